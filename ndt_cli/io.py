"""Point-cloud files: read PLY, LAS/LAZ, PCD and xyz/txt/csv text; write the same formats.

Coordinates are kept exactly as the file stores them (the file's own frame, metres unless the
file says otherwise), as float64. :func:`read` drops non-finite points and exact (0,0,0) points
("no return" points of spinning LiDARs) and turns every failure into an
:class:`~ndt_cli.errors.InputError` naming the file.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

import laspy
import numpy as np
import plyfile
import pypcd4

from ndt_cli.atomic import atomic_path
from ndt_cli.errors import InputError, NdtError, OutputError

logger = logging.getLogger(__name__)

LAS_CHUNK_SIZE = 2_000_000
"""Points per chunk when reading LAS/LAZ (bounds the memory used by laspy's point records)."""

LAS_SCALE = 0.001
"""Coordinate resolution of written LAS/LAZ files, metres."""


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


@runtime_checkable
class PointReader(Protocol):
    """Reads the raw coordinates of one file format."""

    suffixes: tuple[str, ...]

    def read_xyz(self, path: Path) -> np.ndarray:
        """Return all points of ``path`` as raw (N,3) float64, before any filtering."""
        ...


class PlyReader:
    """PLY (ascii, binary little or big endian): ``vertex`` element, x/y/z of any numeric type."""

    suffixes = (".ply",)

    def read_xyz(self, path: Path) -> np.ndarray:
        ply = plyfile.PlyData.read(str(path))
        names = [element.name for element in ply.elements]
        if "vertex" not in names:
            raise InputError(f"PLY file has no 'vertex' element (elements: {names})", path)
        vertex = ply["vertex"].data
        _require_xyz(vertex.dtype.names or (), path)
        return _stack_xyz(vertex)


class LasReader:
    """LAS/LAZ via laspy (lazrs for LAZ): scaled x/y/z, read in chunks of ``chunk_size`` points."""

    suffixes = (".las", ".laz")

    def __init__(self, chunk_size: int | None = None) -> None:
        self.chunk_size = chunk_size  # None: LAS_CHUNK_SIZE at read time

    def count(self, path: Path) -> int:
        """Points announced by the header (the file is not read further)."""
        with laspy.open(path) as reader:
            return int(reader.header.point_count)

    def iter_xyz(self, path: Path, chunk_size: int | None = None) -> Iterator[np.ndarray]:
        """Raw (m,3) float64 chunks of at most ``chunk_size`` points, in file order."""
        with laspy.open(path) as reader:
            header = reader.header
            n = int(header.point_count)
            if not header.are_points_compressed:
                needed = header.offset_to_point_data + n * header.point_format.size
                size = path.stat().st_size
                if size < needed:
                    raise InputError(
                        f"truncated LAS file: header announces {n} points ({needed} bytes), "
                        f"file has {size} bytes",
                        path,
                    )
            filled = 0
            for chunk in reader.chunk_iterator(chunk_size or self.chunk_size or LAS_CHUNK_SIZE):
                m = len(chunk)
                if filled + m > n:
                    raise InputError(f"file holds more points than its header's {n}", path)
                out = np.empty((m, 3), dtype=np.float64)
                out[:, 0], out[:, 1], out[:, 2] = chunk.x, chunk.y, chunk.z
                filled += m
                yield out
        if filled != n:
            raise InputError(f"truncated file: header announces {n} points, found {filled}", path)

    def read_xyz(self, path: Path) -> np.ndarray:
        chunks = list(self.iter_xyz(path))
        return np.concatenate(chunks) if chunks else np.empty((0, 3))


class PcdReader:
    """PCD (ascii, binary, binary_compressed) via pypcd4: fields x, y, z."""

    suffixes = (".pcd",)

    def read_xyz(self, path: Path) -> np.ndarray:
        with path.open("rb") as fh:
            head = fh.read(16384)
        if b"FIELDS" not in head or b"DATA" not in head:
            raise InputError("not a PCD file (no FIELDS/DATA header)", path)
        cloud = pypcd4.PointCloud.from_path(path)
        _require_xyz(cloud.fields, path)
        data = np.atleast_1d(cloud.pc_data)
        if len(data) != cloud.metadata.points:
            raise InputError(
                f"truncated file: header announces {cloud.metadata.points} points, "
                f"found {len(data)}",
                path,
            )
        return _stack_xyz(data)


_SPLIT = re.compile(r"[\s,;]+")


def _parse_row(line: str) -> tuple[float, float, float] | None:
    """First three numbers of a text row, or None if it does not start with three numbers."""
    tokens = [t for t in _SPLIT.split(line.strip(), maxsplit=3)[:3] if t]
    if len(tokens) < 3:
        return None
    try:
        return float(tokens[0]), float(tokens[1]), float(tokens[2])
    except ValueError:
        return None


def _strip_comment(line: str) -> str:
    return line.split("#", 1)[0].split("//", 1)[0].strip()


class TextReader:
    """xyz/txt/csv: first three numeric columns, separated by whitespace, comma or semicolon.

    Leading lines that are not a row of numbers (headers, ``#`` or ``//`` comments) are skipped;
    after the first data row, blank and comment lines are allowed but any other row is an error.
    """

    suffixes = (".xyz", ".txt", ".csv", ".3d")  # .3d: 3DTK's plain "x y z" lines

    def read_xyz(self, path: Path) -> np.ndarray:
        try:
            with path.open(encoding="utf-8-sig") as fh:
                n_header, delimiter = 0, None
                for line in fh:
                    content = _strip_comment(line)
                    if content and _parse_row(content) is not None:
                        delimiter = "," if "," in content else ";" if ";" in content else None
                        break
                    n_header += 1
                else:
                    return np.empty((0, 3))
            try:  # fast path: numpy's C parser
                return np.loadtxt(
                    path,
                    dtype=np.float64,
                    delimiter=delimiter,
                    comments=("#", "//"),
                    skiprows=n_header,
                    usecols=(0, 1, 2),
                    ndmin=2,
                    encoding="utf-8-sig",
                )
            except ValueError:
                return self._read_slow(path, n_header)
        except UnicodeDecodeError as exc:
            raise InputError(
                f"not a UTF-8 text file ({exc.reason} at byte {exc.start})", path
            ) from exc

    @staticmethod
    def _read_slow(path: Path, n_header: int) -> np.ndarray:
        """Row-by-row parse (mixed separators, ragged rows); reports the first bad line."""
        rows = []
        with path.open(encoding="utf-8-sig") as fh:
            for number, line in enumerate(fh, start=1):
                content = _strip_comment(line)
                if number <= n_header or not content:
                    continue
                row = _parse_row(content)
                if row is None:
                    shown = content if len(content) <= 40 else content[:37] + "..."
                    raise InputError(f"line {number}: expected three numbers, got {shown!r}", path)
                rows.append(row)
        return np.array(rows, dtype=np.float64).reshape(-1, 3)


class E57Reader:
    """E57 scans (optional pye57); ``FILE.e57#K`` names scan K, see :mod:`ndt_cli.e57`."""

    suffixes = (".e57",)

    def read_xyz(self, path: Path) -> np.ndarray:
        from ndt_cli import e57

        return e57.read_xyz(path)


READERS: tuple[PointReader, ...] = (
    PlyReader(), LasReader(), PcdReader(), TextReader(), E57Reader()
)  # fmt: skip
SUPPORTED_SUFFIXES: tuple[str, ...] = tuple(s for r in READERS for s in r.suffixes)
WRITE_SUFFIXES: tuple[str, ...] = (".ply", ".las", ".laz", ".pcd", ".xyz", ".txt", ".csv")


def _require_xyz(names: tuple[str, ...] | list[str], path: Path) -> None:
    if not {"x", "y", "z"} <= set(names):
        raise InputError(f"no x, y, z fields (found: {', '.join(names) or 'none'})", path)


def _stack_xyz(data: np.ndarray) -> np.ndarray:
    out = np.empty((len(data), 3), dtype=np.float64)
    for i, name in enumerate("xyz"):
        out[:, i] = data[name]
    return out


def _one_line(exc: BaseException, limit: int = 160) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _reader_for(path: Path) -> PointReader:
    suffix = path.suffix.lower()
    for reader in READERS:
        if suffix in reader.suffixes:
            return reader
    raise InputError(_unknown_suffix(path), path)


def _unknown_suffix(path: Path) -> str:
    return (
        f"unknown extension {path.suffix or '(none)'!r}; supported: {' '.join(SUPPORTED_SUFFIXES)}"
    )


def _open(path: str | Path) -> tuple[Path, PointReader]:
    """The path and its reader, after the checks every format shares."""
    from ndt_cli.e57 import split_spec

    p = Path(path)
    f = split_spec(p)[0]  # 'scans.e57#3' names scan 3 of scans.e57
    if not f.exists():
        raise InputError("file not found", p)
    if f.is_dir():
        raise InputError("is a directory, not a point file", p)
    reader = _reader_for(f)
    try:
        empty = f.stat().st_size == 0
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or _one_line(exc)})", p) from exc
    if empty:
        raise InputError("file is empty", p)
    return p, reader


@contextmanager
def _file_errors(p: Path) -> Iterator[None]:
    """Turn any library failure while reading ``p`` into a one-line :class:`InputError`."""
    try:
        yield
    except NdtError:
        raise
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or _one_line(exc)})", p) from exc
    except Exception as exc:  # any library failure is a problem with the file
        raise InputError(f"not a valid or complete {p.suffix} file: {_one_line(exc)}", p) from exc


def _usable(raw: np.ndarray) -> np.ndarray:
    """Rows that are finite and not exactly (0,0,0) (column-wise: fast on (N,3) arrays)."""
    finite = np.isfinite(raw[:, 0] + raw[:, 1] + raw[:, 2])
    return finite & ~((raw[:, 0] == 0.0) & (raw[:, 1] == 0.0) & (raw[:, 2] == 0.0))


def count(path: str | Path) -> int | None:
    """Points a file announces in its header (LAS/LAZ), or None for formats without a count."""
    p, reader = _open(path)
    if not isinstance(reader, LasReader):
        return None
    with _file_errors(p):
        return reader.count(p)


def read_chunks(path: str | Path, chunk_size: int | None = None) -> Iterator[np.ndarray]:
    """The usable points of a file as (m,3) float64 chunks in file order: LAS/LAZ are streamed
    ``chunk_size`` points at a time (memory stays bounded), other formats come as one chunk.
    Non-finite and (0,0,0) points are dropped; errors as in :func:`read`."""
    p, reader = _open(path)
    n_read = n_kept = 0
    with _file_errors(p):
        raws = (
            reader.iter_xyz(p, chunk_size)
            if isinstance(reader, LasReader)
            else iter([np.asarray(reader.read_xyz(p), dtype=np.float64).reshape(-1, 3)])
        )
        for raw in raws:
            keep = _usable(raw)
            n_read += len(raw)
            n_kept += int(keep.sum())
            if keep.any():
                yield raw if keep.all() else raw[keep]
    if n_read == 0:
        raise InputError("no points in file", p)
    if n_kept == 0:
        raise InputError(f"no usable points: all {n_read} are NaN/inf or (0,0,0)", p)


def read(path: str | Path) -> PointCloud:
    """Read a point file (format chosen by extension) and drop non-finite and (0,0,0) points.

    Raises :class:`InputError` (one line, naming the file) for anything wrong with the file.
    """
    p, reader = _open(path)
    with _file_errors(p):
        raw = np.asarray(reader.read_xyz(p), dtype=np.float64).reshape(-1, 3)
    n_read = len(raw)
    if n_read == 0:
        raise InputError("no points in file", p)
    finite = np.isfinite(raw[:, 0] + raw[:, 1] + raw[:, 2])  # NaN or inf anywhere: not finite
    zero = (raw[:, 0] == 0.0) & (raw[:, 1] == 0.0) & (raw[:, 2] == 0.0)
    keep = finite & ~zero
    n_nonfinite, n_zero = int(n_read - finite.sum()), int(zero.sum())
    logger.log(
        logging.INFO if n_nonfinite or n_zero else logging.DEBUG,
        "%s: read %d points, dropped %d non-finite and %d (0,0,0) points",
        p,
        n_read,
        n_nonfinite,
        n_zero,
    )
    if not keep.any():
        raise InputError(
            f"no usable points: of {n_read}, {n_nonfinite} are NaN/inf and {n_zero} are (0,0,0)", p
        )
    points = raw if keep.all() else raw[keep]
    return PointCloud(np.ascontiguousarray(points), p, n_read, n_nonfinite, n_zero)


def _write_ply(path: Path, points: np.ndarray) -> None:
    vertex = np.empty(len(points), dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    vertex["x"], vertex["y"], vertex["z"] = points.T
    element = plyfile.PlyElement.describe(vertex, "vertex")
    plyfile.PlyData([element], text=False, byte_order="<").write(str(path))


def _las_offsets(points: np.ndarray, target: Path) -> np.ndarray:
    """Whole-metre offsets at the data minimum; checks that LAS integers can hold the points."""
    if not np.isfinite(points).all():
        raise OutputError("LAS/LAZ cannot store NaN or infinite coordinates", target)
    if len(points) == 0:
        return np.zeros(3)
    offsets = np.floor(points.min(axis=0))
    if (points.max(axis=0) - offsets).max() / LAS_SCALE >= 2**31 - 1:
        raise OutputError(f"extent too large for LAS at {LAS_SCALE} m resolution", target)
    return offsets


def _write_las(path: Path, points: np.ndarray, offsets: np.ndarray, compress: bool) -> None:
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.full(3, LAS_SCALE)
    header.offsets = offsets
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    las.write(str(path), do_compress=compress)


def _write_pcd(path: Path, points: np.ndarray) -> None:
    cloud = pypcd4.PointCloud.from_points(points, ("x", "y", "z"), (np.float64,) * 3)
    cloud.save(path, encoding=pypcd4.Encoding.BINARY)


def _write_text(path: Path, points: np.ndarray, sep: str) -> None:
    """Shortest round-trip repr of each float64: full precision, no spurious digits."""
    with path.open("w", encoding="utf-8", newline="\n") as fh:
        if sep == ",":
            fh.write("x,y,z\n")
        for start in range(0, len(points), 100_000):
            block = points[start : start + 100_000].tolist()
            fh.write("".join(f"{x!r}{sep}{y!r}{sep}{z!r}\n" for x, y, z in block))


def write(path: str | Path, points: np.ndarray) -> None:
    """Write (N,3) points (metres, any frame) atomically; the format follows the extension.

    .ply: binary little endian float64; .las/.laz: 1 mm scale, offsets from the data minimum;
    .pcd: binary float64; .xyz/.txt: space separated, .csv: comma separated with an x,y,z
    header, full float64 precision. Raises :class:`OutputError` if the file cannot be written.
    """
    target = Path(path)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be an (N,3) array, got shape {pts.shape}")
    suffix = target.suffix.lower()
    if suffix not in WRITE_SUFFIXES:
        raise OutputError(
            f"cannot write {suffix or '(no extension)'!r}; writable: {' '.join(WRITE_SUFFIXES)}",
            target,
        )
    offsets = _las_offsets(pts, target) if suffix in (".las", ".laz") else None
    with atomic_path(target) as tmp:
        if suffix == ".ply":
            _write_ply(tmp, pts)
        elif offsets is not None:
            _write_las(tmp, pts, offsets, compress=suffix == ".laz")
        elif suffix == ".pcd":
            _write_pcd(tmp, pts)
        else:
            _write_text(tmp, pts, "," if suffix == ".csv" else " ")
