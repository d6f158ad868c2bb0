"""Write the registered point cloud of many scans, every point attribute and the CRS kept.

:func:`export` streams each scan's points through :mod:`ndt_cli.io.records`, maps them to the
world frame with the scan's ``T_world_file`` and writes, by the extension of ``out``:

- ``.las`` / ``.laz``: one merged file (:mod:`ndt_cli.io.export_las`: the point format holding
  every input's dimensions, the union of extra bytes, an extra-bytes ``scan_index`` (uint16) per
  point, the anchor scan's CRS records copied byte for byte, 1 mm scales, offsets at the centre
  of the world bounding box);
- ``.ply``: binary little-endian, x/y/z float64 plus every attribute and ``scan_index``;
- ``.e57``: one scan per station, points in the scanner frame (``S_scan_file`` applied), the
  pose ``T_world_scan`` in the scan header (:mod:`ndt_cli.io.export_other`).

With ``per_scan_dir``, one file per scan is written there instead (in ``out``'s format), named
after the scan and listed in the folder's manifest (``.ndt-cli-outputs``): a later per-scan
export into the folder replaces them and removes those it does not write again, and never
replaces a file that no export wrote there (nor a scan it reads). ``voxel`` thins to one point
per cube of the world frame (the first point met: scans in the given order, points in file
order). Points that are not finite or exactly (0,0,0) in the file (no-return points) are
dropped, as everywhere in ndt-cli.

Memory stays bounded: one chunk of ``chunk_points`` points at a time (a process peaks at about
0.3-0.4 GB with the default 1 M, whatever the number of points), plus, with ``voxel``, 8 bytes
per occupied voxel (16 while a chunk's new voxels are merged in). Every file is written to a
temporary file beside its target and renamed when complete: a failure leaves nothing behind.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from ndt_cli.errors import InputError, NdtError, OutputError, one_line
from ndt_cli.io.atomic import atomic_path
from ndt_cli.io.export_inputs import ExportScan, ScanInput, scan_inputs, union_bounds, usable
from ndt_cli.io.names import per_scan_file_names
from ndt_cli.io.outdir import check_shared_folder, record_shared_folder
from ndt_cli.io.records import CHUNK_POINTS, Chunk, RawVlr, iter_records

log = logging.getLogger(__name__)

EXPORT_SUFFIXES = (".las", ".laz", ".ply", ".e57")
SCAN_INDEX = "scan_index"
"""Name of the per-point scan number (uint16, :attr:`ExportScan.index`) in every output."""

Progress = Callable[[int, int], None]
"""``progress(points_done, points_total)``: points read so far and in all inputs."""


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export` wrote. Counts are points; ``points_read`` includes dropped ones."""

    paths: tuple[Path, ...]
    points_read: int
    points_written: int
    points_dropped: int  # not finite, or exactly (0,0,0) in the file
    points_thinned: int  # removed by the voxel filter
    written_per_scan: tuple[int, ...]
    point_format: int | None = None  # LAS point format written (LAS/LAZ only)


class Sink(Protocol):
    """A file being written: scans arrive one after the other, in chunks."""

    def begin(self, item: ScanInput) -> None: ...

    def write(self, chunk: Chunk, world: np.ndarray) -> None:
        """Points of the current scan: ``chunk`` as read (file frame), ``world`` (m,3) in the
        world frame (m)."""

    def end(self) -> None: ...

    def close(self) -> None:
        """Finish the file (after the last scan)."""

    def abort(self) -> None:
        """Release the file after a failure (the caller removes it)."""


class FirstPointThinner:
    """One point per ``voxel`` metre cube of the world frame: the first one met.

    Voxel indices are taken relative to ``lo`` (with a margin) and packed into one int64 key;
    only the sorted keys of the occupied voxels are kept (8 bytes per voxel).
    """

    def __init__(self, voxel: float, lo: np.ndarray, hi: np.ndarray) -> None:
        if not voxel > 0:
            raise ValueError(f"voxel must be > 0 m, got {voxel}")
        margin = 1.0 + 0.01 * float(np.max(hi - lo))
        self.voxel = float(voxel)
        self.origin = np.floor((lo - margin) / voxel)
        self.size = np.floor((hi + margin) / voxel) - self.origin + 1
        bits = np.ceil(np.log2(self.size + 1)).astype(np.int64)
        if bits.sum() > 62:
            raise OutputError(
                f"voxel {voxel} m is too small for an extent of {np.max(hi - lo):.0f} m"
            )
        self.shifts = (int(bits[1] + bits[2]), int(bits[2]), 0)
        self.occupied = np.empty(0, dtype=np.int64)

    def keep(self, world: np.ndarray) -> np.ndarray:
        """Boolean mask of the (m,3) world points (m) that open a new voxel."""
        ijk = np.floor(world / self.voxel) - self.origin
        if len(ijk) and ((ijk < 0).any() or (ijk >= self.size).any()):
            raise InputError("points lie outside the bounding box the header announces")
        ijk = ijk.astype(np.int64)
        keys = (ijk[:, 0] << self.shifts[0]) | (ijk[:, 1] << self.shifts[1]) | ijk[:, 2]
        uniq, first = np.unique(keys, return_index=True)
        pos = np.searchsorted(self.occupied, uniq)
        seen = np.zeros(len(uniq), dtype=bool)
        inside = pos < len(self.occupied)
        seen[inside] = self.occupied[pos[inside]] == uniq[inside]
        self.occupied = np.insert(self.occupied, pos[~seen], uniq[~seen])
        mask = np.zeros(len(keys), dtype=bool)
        mask[first[~seen]] = True
        return mask


def _check(scans: Sequence[ExportScan], out: Path) -> str:
    """The output suffix, after checking the scans (unique names and indices, one anchor)."""
    suffix = out.suffix.lower()
    if suffix not in EXPORT_SUFFIXES:
        known = " ".join(EXPORT_SUFFIXES)
        shown = suffix or "(no extension)"
        raise OutputError(f"cannot export to {shown!r}; supported: {known}", out)
    if not scans:
        raise ValueError("no scans to export")
    for what in ("name", "index"):
        values = [getattr(s, what) for s in scans]
        if len(set(values)) != len(values):
            raise ValueError(f"scan {what}s must be unique, got {values}")
    if sum(s.anchor for s in scans) > 1:
        raise ValueError("at most one scan can be the anchor")
    return suffix


def anchor_of(scans: Sequence[ExportScan]) -> ExportScan:
    """The scan marked ``anchor``, or the first scan."""
    return next((s for s in scans if s.anchor), scans[0])


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


def refuse_inputs(targets: Sequence[Path], inputs: Sequence[str | Path]) -> None:
    """Raise :class:`OutputError` when a file to write is one of the ``inputs`` (point files;
    ``FILE.e57#K`` is the file): an export never replaces what it reads."""
    from ndt_cli.io.multiscan import split_spec

    files = [split_spec(p)[0] for p in inputs]
    for target in targets:
        hit = next((f for f in files if _same_file(target, f)), None)
        if hit is not None:
            raise OutputError(
                f"is the scan file {hit}: an export never overwrites its input", target
            )


def _make_sink(
    suffix: str,
    tmp: Path,
    inputs: list[ScanInput],
    anchor: ExportScan,
    target: Path,
    chunk_points: int,
    crs: tuple[RawVlr, ...] | None,
) -> Sink:
    if suffix in (".las", ".laz"):
        from ndt_cli.io.export_las import LasSink

        return LasSink(tmp, inputs, union_bounds(inputs), anchor, target, crs)
    from ndt_cli.io.export_other import E57Sink, PlySink

    if suffix == ".ply":
        return PlySink(tmp, inputs)
    return E57Sink(tmp, inputs, anchor, chunk_points, crs)


@dataclass
class _Tally:
    """Running point counts of one export."""

    total: int
    read: int = 0
    dropped: int = 0
    thinned: int = 0
    written: dict[int, int] = field(default_factory=dict)


def _scan_chunks(
    item: ScanInput, thinner: FirstPointThinner | None, tally: _Tally, chunk_points: int
) -> Iterator[tuple[Chunk, np.ndarray]]:
    """The usable (and, with ``thinner``, kept) points of one scan: (chunk, world (m,3))."""
    T = item.scan.T_world_file
    for chunk in iter_records(item.scan.path, chunk_points):
        m = len(chunk["x"])
        tally.read += m
        ok = usable(chunk)
        if not ok.all():
            tally.dropped += m - int(ok.sum())
            chunk = {k: v[ok] for k, v in chunk.items()}
        xyz = np.column_stack([chunk["x"], chunk["y"], chunk["z"]])
        world = xyz @ T[:3, :3].T + T[:3, 3]
        if thinner is not None:
            try:
                keep = thinner.keep(world)
            except InputError as exc:
                raise InputError(exc.message, item.scan.path) from None
            tally.thinned += len(keep) - int(keep.sum())
            chunk, world = {k: v[keep] for k, v in chunk.items()}, world[keep]
        yield chunk, world


def _write(
    sink: Sink,
    group: Sequence[ScanInput],
    thinner: FirstPointThinner | None,
    tally: _Tally,
    chunk_points: int,
    progress: Progress | None,
) -> None:
    """Feed the scans of ``group`` to ``sink``, chunk by chunk, and finish the file."""
    try:
        for item in group:
            sink.begin(item)
            written = 0
            for chunk, world in _scan_chunks(item, thinner, tally, chunk_points):
                if len(world):
                    sink.write(chunk, world)
                written += len(world)
                if progress is not None:
                    progress(tally.read, tally.total)
            sink.end()
            tally.written[item.scan.index] = written
    except BaseException:
        sink.abort()
        raise
    sink.close()


@contextlib.contextmanager
def _removed_on_failure(folder: Path | None) -> Iterator[None]:
    """Remove ``folder`` again if the block fails and the folder did not exist before (empty)."""
    created = folder is not None and not folder.exists()
    try:
        yield
    except BaseException:
        if created and folder is not None:
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise


def _write_files(
    suffix: str,
    targets: Sequence[Path],
    groups: Sequence[list[ScanInput]],
    anchor: ExportScan,
    thinner: FirstPointThinner | None,
    tally: _Tally,
    chunk_points: int,
    progress: Progress | None,
    crs: tuple[RawVlr, ...] | None,
) -> list[int | None]:
    """Write ``groups[k]`` into ``targets[k]``: temporary files, renamed once all are complete
    (none is left on failure). Returns the LAS point format of each file (None: not LAS)."""
    formats = []
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(atomic_path(t)) for t in targets]
        for tmp, group, t in zip(tmps, groups, targets, strict=True):
            with _writing(t):
                sink = _make_sink(suffix, tmp, group, anchor, t, chunk_points, crs)
                _write(sink, group, thinner, tally, chunk_points, progress)
            formats.append(getattr(sink, "point_format", None))
    return formats


@contextlib.contextmanager
def _writing(target: Path) -> Iterator[None]:
    """A failure of the writing library (a full disk, a file-size limit: lazrs and libE57 raise
    their own errors) as one line naming ``target``; user errors and bugs pass unchanged."""
    try:
        yield
    except NdtError:
        raise
    except OSError as exc:
        raise OutputError(f"cannot write ({exc.strerror or one_line(exc)})", target) from exc
    except _library_errors() as exc:
        raise OutputError(f"cannot write ({one_line(exc)}; is the disk full?)", target) from exc


def _library_errors() -> tuple[type[Exception], ...]:
    """What the writing libraries raise: lazrs.LazrsError (a RuntimeError), laspy's errors and
    libE57's E57Exception (when pye57 is installed)."""
    from laspy.errors import LaspyException

    errors: tuple[type[Exception], ...] = (RuntimeError, LaspyException)
    try:
        from pye57.libe57 import E57Exception
    except ImportError:
        return errors
    return (*errors, E57Exception)


def export(
    scans: Sequence[ExportScan],
    out: str | Path,
    *,
    voxel: float | None = None,
    per_scan_dir: str | Path | None = None,
    chunk_points: int = CHUNK_POINTS,
    progress: Progress | None = None,
    protect: Sequence[str | Path] = (),
    crs: tuple[RawVlr, ...] | None = None,
) -> ExportResult:
    """Write the registered cloud of ``scans`` (see the module docstring) and say what was written.

    ``out``: the merged file; its extension chooses the format (.las, .laz, .ply, .e57). With
    ``per_scan_dir``, one file per scan is written into that folder instead, in ``out``'s
    format (``out`` itself is not written). ``voxel``: thinning cube edge in metres (None: keep
    every point). ``chunk_points``: points read and written at a time. ``progress``: called
    after every chunk with (points read so far, points in all inputs). ``protect``: more files
    that must not be written (the scans' own files never are). ``crs``: the CRS records the
    outputs carry (LAS ``LASF_Projection`` records; E57 takes the WKT of record 2112), ``()``
    for none; None: the anchor scan's, copied.

    Raises :class:`OutputError` (unwritable target, unsupported extension, incompatible extra
    bytes, extent too large) and :class:`InputError` (unreadable input), each one line naming the
    file; ValueError for a wrong ``scans`` list (duplicate names or indices, two anchors).
    """
    target = Path(out)
    suffix = _check(scans, target)
    if voxel is not None and not voxel > 0:
        raise ValueError(f"voxel must be > 0 m, got {voxel}")
    if per_scan_dir is None:
        targets = [target]
    else:
        names = per_scan_file_names([s.name for s in scans], suffix)
        targets = [Path(per_scan_dir) / n for n in names]
    refuse_inputs(targets, [*(s.path for s in scans), *protect])
    if per_scan_dir is not None:
        check_shared_folder(Path(per_scan_dir), [t.name for t in targets])
    need_bounds = suffix in (".las", ".laz") or voxel is not None
    inputs = scan_inputs(scans, need_bounds, chunk_points, need_colours=suffix == ".e57")
    thinner = None if voxel is None else FirstPointThinner(voxel, *union_bounds(inputs))
    groups = [inputs] if per_scan_dir is None else [[i] for i in inputs]
    tally = _Tally(total=sum(i.count for i in inputs))
    with _removed_on_failure(None if per_scan_dir is None else Path(per_scan_dir)):
        formats = _write_files(
            suffix, targets, groups, anchor_of(scans), thinner, tally, chunk_points, progress, crs
        )
        if per_scan_dir is not None:
            record_shared_folder(Path(per_scan_dir), [t.name for t in targets])
    result = ExportResult(
        paths=tuple(targets),
        points_read=tally.read,
        points_written=sum(tally.written.values()),
        points_dropped=tally.dropped,
        points_thinned=tally.thinned,
        written_per_scan=tuple(tally.written.get(s.index, 0) for s in scans),
        point_format=formats[0] if per_scan_dir is None else None,
    )
    log.info(
        "exported %d of %d points (%d dropped, %d thinned) to %s",
        result.points_written,
        result.points_read,
        result.points_dropped,
        result.points_thinned,
        target if per_scan_dir is None else per_scan_dir,
    )
    return result
