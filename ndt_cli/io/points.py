"""Reading point clouds: the format is chosen by extension, failures become one-line errors.

Coordinates are kept exactly as the file stores them (the file's own frame, metres unless the
file says otherwise), as float64. Non-finite points and exact (0,0,0) points ("no return" points
of spinning LiDARs) are dropped, and every failure is an :class:`~ndt_cli.errors.InputError`
naming the file.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError, NdtError, one_line
from ndt_cli.io.blocks import Block, unusable_integers
from ndt_cli.io.formats import (
    E57Reader,
    LasReader,
    PcdReader,
    PlyReader,
    PointReader,
    PtxReader,
)
from ndt_cli.io.text import TextReader

logger = logging.getLogger(__name__)

READERS: tuple[PointReader, ...] = (
    PlyReader(),
    LasReader(),
    PcdReader(),
    TextReader(),
    E57Reader(),
    PtxReader(),
)
SUPPORTED_SUFFIXES: tuple[str, ...] = tuple(s for r in READERS for s in r.suffixes)


@dataclass(frozen=True)
class PointCloud:
    """Points read from one file, after dropping unusable points.

    ``points`` is (N,3) float64, finite, without exact (0,0,0) rows, in the file's own
    coordinates (metres unless the file says otherwise). ``n_read`` counts the points in the file;
    ``n_nonfinite`` (NaN/inf in any coordinate) and ``n_zero`` (exactly (0,0,0)) were dropped.
    """

    points: np.ndarray
    path: Path | None
    n_read: int
    n_nonfinite: int
    n_zero: int


def unusable(raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the (N,3) rows that are not finite, and of those that are exactly (0,0,0).

    One pass over the rows finds the candidates, whose squared length is not a positive finite
    number; only those are tested exactly (a tiny or huge coordinate can square to 0 or inf).
    A usable row is in neither mask.
    """
    r2 = np.einsum("ij,ij->i", raw, raw)
    odd = np.flatnonzero(~(r2 > 0.0) | ~np.isfinite(r2))
    nonfinite, zero = np.zeros(len(raw), bool), np.zeros(len(raw), bool)
    rows = raw[odd]
    nonfinite[odd] = ~np.isfinite(rows).all(axis=1)
    zero[odd] = (rows == 0.0).all(axis=1)
    return nonfinite, zero


def as_points(array: object) -> np.ndarray:
    """An array the user passed as points, as (N,3) float64; anything else is an InputError
    that says what is expected."""
    expected = "an (N,3) array of real x, y, z coordinates in metres"
    a = np.asarray(array) if not isinstance(array, np.ndarray) else array
    if a.dtype.names is not None or a.dtype == object:
        raise InputError(f"expected {expected}, got an array of {a.dtype}")
    if a.dtype.kind not in "iuf":
        raise InputError(f"expected {expected}, got {a.dtype} values")
    if a.ndim != 2 or a.shape[1] != 3:
        hint = " (transpose it: points are rows)" if a.ndim == 2 and a.shape[0] == 3 else ""
        raise InputError(f"expected {expected}, got shape {a.shape}{hint}")
    return np.ascontiguousarray(a, dtype=np.float64)


def reader_for(path: Path) -> PointReader:
    """The reader of a file's extension."""
    suffix = path.suffix.lower()
    for reader in READERS:
        if suffix in reader.suffixes:
            return reader
    raise InputError(
        f"unknown extension {path.suffix or '(none)'!r}; supported: {' '.join(SUPPORTED_SUFFIXES)}",
        path,
    )


def checked_reader(path: str | Path) -> tuple[Path, PointReader]:
    """The path and its reader, after the checks every format shares: the file exists, is a
    regular file (not a folder, FIFO or device), can be read and is not empty."""
    from ndt_cli.io.multiscan import split_spec

    p = Path(path)
    f = split_spec(p)[0]  # 'scans.e57#3' names scan 3 of scans.e57
    try:
        if not f.exists():
            raise InputError(_not_found(f), p)
        if f.is_dir():
            raise InputError("is a directory, not a point file", p)
        if not f.is_file():
            raise InputError("is not a regular file (a FIFO, socket or device?)", p)
        reader = reader_for(f)
        with open(f, "rb") as fh:
            empty = not fh.read(1)
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or one_line(exc)})", p) from None
    if empty:
        raise InputError("file is empty", p)
    return p, reader


def _not_found(f: Path) -> str:
    """Why ``f`` is not found: a file that is there with a ``#...`` tail that names no scan
    (``FILE.e57#K`` needs a number K; a file of one scan takes none), or no file at all."""
    from ndt_cli.io.multiscan import MULTI_SCAN

    text = str(f)
    cuts = [k for k, c in enumerate(text) if c == "#"]
    base = next((Path(text[:k]) for k in reversed(cuts) if Path(text[:k]).is_file()), None)
    if base is None:
        return "file not found"
    tail = text[len(str(base)) :]
    if base.suffix.lower() in MULTI_SCAN:
        return f"{tail!r} names no scan: {base.name}#K takes a scan number K = 0, 1, ..."
    kind = f"a {base.suffix} file" if base.suffix else "this file"
    return f"{kind} holds one scan: name it without {tail!r}"


def check_readable(path: str | Path) -> None:
    """Raise the file's one-line :class:`InputError` now if it cannot be opened as a point
    file (missing, unreadable, unknown format, empty, a broken header), before any heavy work."""
    p, reader = checked_reader(path)
    with file_errors(p):
        reader.check(p)


TYPICAL_SPREAD = 250.0  # m: half a terrestrial scan's points lie nearer to its centre


def check_spread(sample: np.ndarray, path: Path | None) -> None:
    """Raise :class:`InputError` when half of a sample of a scan's points (m,3, metres) lie
    farther than :data:`TYPICAL_SPREAD` from their median point: a scanner's points crowd
    around it (tens of metres in a street, a few in a room), so the coordinates are in other
    units or a first column is no coordinate. Registering such a scan would take minutes and
    gigabytes before failing with a misleading message."""
    if len(sample) < 100:
        return
    spread = float(np.median(np.linalg.norm(sample - np.median(sample, axis=0), axis=1)))
    if spread > TYPICAL_SPREAD:
        raise InputError(
            f"half its points lie more than {spread:.0f} m from their centre (a scan's lie "
            "within tens of metres): coordinates in centimetres or millimetres (set "
            "input.scale), or a first column that is not x (an id)?",
            path,
        )


@contextmanager
def file_errors(p: Path) -> Iterator[None]:
    """Turn any library failure while reading ``p`` into a one-line :class:`InputError`."""
    try:
        yield
    except NdtError:
        raise
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or one_line(exc)})", p) from exc
    except Exception as exc:  # any library failure is a problem with the file
        raise InputError(f"not a valid or complete {p.suffix} file: {one_line(exc)}", p) from exc


def count(path: str | Path) -> int | None:
    """Points a file announces in its header (LAS/LAZ), or None for formats without a count."""
    p, reader = checked_reader(path)
    with file_errors(p):
        return reader.count(p)


def acquired(path: str | Path) -> float | None:
    """When a scan was taken: GPS seconds of its first point record (LAS/LAZ ``gps_time``) or
    its E57 header's ``acquisitionStart``; None for formats without times (PLY, PCD, PTX,
    text), for a file that stores none (0 is what writers put when they have none), and for a
    file that cannot be read (reading it fails later, with its reason). Seconds as the file
    stores them: only their order is used (:attr:`ndt_cli.pipeline.campaign.Campaign.walk`)."""
    try:
        p, reader = checked_reader(path)
        with file_errors(p):
            t = reader.acquired(p)
    except NdtError:
        return None
    return t if t is not None and np.isfinite(t) and t > 0 else None


def record_count(path: str | Path) -> int | None:
    """Point records a file's header announces, invalid ones included (LAS/LAZ, E57), or None
    for formats without a count: an upper bound on its points, to budget memory."""
    p, reader = checked_reader(path)
    with file_errors(p):
        return reader.record_count(p)


def _unusable_rows(block: Block) -> tuple[np.ndarray, np.ndarray]:
    """Masks of a block's non-finite and (0,0,0) rows."""
    return unusable_integers(block) if block.scaled else unusable(block.values)


def _log_dropped(p: Path, n_read: int, n_nonfinite: int, n_zero: int) -> None:
    logger.log(
        logging.INFO if n_nonfinite or n_zero else logging.DEBUG,
        "%s: read %d points, dropped %d non-finite and %d (0,0,0) points",
        p,
        n_read,
        n_nonfinite,
        n_zero,
    )


def _no_usable(p: Path, n_read: int, n_nonfinite: int, n_zero: int) -> InputError:
    return InputError(
        f"no usable points: of {n_read}, {n_nonfinite} are NaN/inf and {n_zero} are (0,0,0)", p
    )


def read_blocks(path: str | Path, chunk_size: int | None = None) -> Iterator[Block]:
    """The usable points of a file as :class:`~ndt_cli.io.blocks.Block` in file order: LAS/LAZ
    (their integers) and E57 are streamed ``chunk_size`` points at a time (memory stays
    bounded), other formats come as one chunk. Non-finite and (0,0,0) points are dropped and
    counted in the log; errors as in :func:`read`."""
    p, reader = checked_reader(path)
    n_read = n_nonfinite = n_zero = 0
    with file_errors(p):
        for raw in reader.iter_blocks(p, chunk_size):
            nonfinite, zero = _unusable_rows(raw)
            drop = nonfinite | zero
            n_drop = int(drop.sum())
            n_read += len(raw)
            n_nonfinite += int(nonfinite.sum())
            n_zero += int(zero.sum())
            if n_drop < len(raw):
                yield raw if n_drop == 0 else raw.rows(~drop)
    if n_read == 0:
        raise InputError("no points in file", p)
    if n_nonfinite + n_zero == n_read:
        raise _no_usable(p, n_read, n_nonfinite, n_zero)
    _log_dropped(p, n_read, n_nonfinite, n_zero)


def read_chunks(path: str | Path, chunk_size: int | None = None) -> Iterator[np.ndarray]:
    """The usable points of a file as (m,3) float64 chunks in file order (the blocks of
    :func:`read_blocks` as coordinates)."""
    for block in read_blocks(path, chunk_size):
        yield block.xyz()


def read(path: str | Path) -> PointCloud:
    """Read a point file (format chosen by extension) and drop non-finite and (0,0,0) points.

    Raises :class:`InputError` (one line, naming the file) for anything wrong with the file.
    """
    p, reader = checked_reader(path)
    with file_errors(p):
        raw = np.asarray(reader.read_xyz(p), dtype=np.float64).reshape(-1, 3)
    n_read = len(raw)
    if n_read == 0:
        raise InputError("no points in file", p)
    nonfinite, zero = unusable(raw)
    keep = ~(nonfinite | zero)
    n_nonfinite, n_zero = int(nonfinite.sum()), int(zero.sum())
    if not keep.any():
        raise _no_usable(p, n_read, n_nonfinite, n_zero)
    _log_dropped(p, n_read, n_nonfinite, n_zero)
    points = raw if keep.all() else raw[keep]
    return PointCloud(np.ascontiguousarray(points), p, n_read, n_nonfinite, n_zero)
