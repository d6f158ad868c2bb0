"""One reader per point-file format, all behind the same interface, for registration (x, y, z)
and export (every attribute) alike; :data:`ndt_cli.io.points.READERS` is their one table.
Adding a format is a reader class here (or in a module of its own) and its entry there.

Every reader tells the point count its header announces (``None`` when the format has no
header count), and yields the raw coordinates in chunks of at most ``chunk_size`` points:
LAS/LAZ and E57 stream from the file, the other formats come as one chunk. Coordinates are the
file's own (metres unless the file says otherwise), float64, before any filtering; as
:class:`~ndt_cli.io.blocks.Block` a LAS/LAZ file's chunks keep their integers (12 bytes a
point instead of 24).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import laspy
import numpy as np
import plyfile

from ndt_cli.core.records import record_bytes, xyz_integers
from ndt_cli.errors import InputError
from ndt_cli.io import records_formats as record_io
from ndt_cli.io.blocks import Block
from ndt_cli.io.record_types import Chunk, Summary, require_xyz

logger = logging.getLogger(__name__)

LAS_CHUNK_SIZE = 2_000_000
"""Points per chunk when reading LAS/LAZ (bounds the memory used by laspy's point records)."""


class PointReader:
    """Reads the raw coordinates of one file format (see the module docstring)."""

    suffixes: tuple[str, ...] = ()
    name: str = ""  # the format's name in summaries (``format_name``)

    def format_name(self, path: Path) -> str:
        """The format's name (``Summary.format``)."""
        return self.name

    def summary(self, path: Path) -> Summary:
        """What the header says, without reading the points (:class:`Summary`)."""
        raise NotImplementedError

    def records(self, path: Path, chunk_points: int) -> Iterator[Chunk]:
        """Chunks of at most ``chunk_points`` points with every attribute, in file order."""
        raise NotImplementedError

    def scan_count(self, path: Path) -> int:
        """Scans the file holds (formats of many scans: their suffix is in
        :data:`ndt_cli.io.multiscan.MULTI_SCAN`)."""
        return 1

    def header_pose(self, spec: Path) -> np.ndarray | None:
        """The 4x4 pose a scan's header stores (scan frame to the file's frame), or None."""
        return None

    def count(self, path: Path) -> int | None:
        """Points the header announces, or None for formats without a header count."""
        return None

    def acquired(self, spec: Path) -> float | None:
        """When the scan was taken (GPS seconds as the file stores them), or None: the format
        or the file keeps no time (:func:`ndt_cli.io.points.acquired`)."""
        return None

    def check(self, path: Path) -> None:
        """Read what a quick look needs (the header) and raise if the file cannot be used."""
        self.count(path)

    def record_count(self, path: Path) -> int | None:
        """Point records the header announces, invalid ones included (LAS/LAZ, E57), or None:
        an upper bound on the points, to budget memory before reading."""
        return self.count(path)

    def iter_xyz(self, path: Path, chunk_size: int | None = None) -> Iterator[np.ndarray]:
        """Raw (m,3) float64 chunks in file order (one chunk unless the format streams)."""
        yield np.asarray(self.read_xyz(path), dtype=np.float64).reshape(-1, 3)

    def iter_blocks(self, path: Path, chunk_size: int | None = None) -> Iterator[Block]:
        """The chunks of :meth:`iter_xyz` as blocks (float64 unless the format stores
        integers)."""
        for xyz in self.iter_xyz(path, chunk_size):
            yield Block(xyz)

    def read_xyz(self, path: Path) -> np.ndarray:
        """All points of ``path`` as raw (N,3) float64, before any filtering."""
        raise NotImplementedError


class PlyReader(PointReader):
    """PLY (ascii, binary little or big endian): ``vertex`` element, x/y/z of any numeric type."""

    suffixes = (".ply",)
    name = "ply"

    def summary(self, path: Path) -> Summary:
        return record_io.ply_summary(path)

    def check(self, path: Path) -> None:
        record_io.ply_summary(path)  # the header: magic line, vertex element, x, y, z

    def records(self, path: Path, chunk_points: int) -> Iterator[Chunk]:
        return record_io.ply_chunks(path, chunk_points)

    def read_xyz(self, path: Path) -> np.ndarray:
        ply = plyfile.PlyData.read(str(path))
        names = [element.name for element in ply.elements]
        if "vertex" not in names:
            raise InputError(f"PLY file has no 'vertex' element (elements: {names})", path)
        vertex = ply["vertex"].data
        require_xyz(vertex.dtype.names or (), path)
        return stack_xyz(vertex)


class LasReader(PointReader):
    """LAS/LAZ via laspy (lazrs for LAZ): scaled x/y/z, streamed ``chunk_size`` points at a time.

    laspy parses the header; an uncompressed file's point records are then mapped from the
    file with the record type laspy gives (``header.point_format.dtype()``) and scaled block by
    block, as laspy scales them (``X * scale + offset``, float64): the same coordinates, without
    the zero-filled copy of every record that a read through laspy makes (for a 2 M-point scan,
    40 MB filled, read into and dropped). LAZ files are decompressed by laspy, chunk by chunk."""

    suffixes = (".las", ".laz")
    name = "las"

    def format_name(self, path: Path) -> str:
        return path.suffix.lower().lstrip(".")

    def summary(self, path: Path) -> Summary:
        return record_io.las_summary(path)

    def records(self, path: Path, chunk_points: int) -> Iterator[Chunk]:
        return record_io.las_chunks(path, chunk_points)

    def acquired(self, spec: Path) -> float | None:
        """The first point record's ``gps_time`` (point formats 1 and 3-10; a scanner writes
        its records in the order it measured them)."""
        with laspy.open(spec) as reader:
            if "gps_time" not in reader.header.point_format.dimension_names:
                return None
            first = reader.read_points(1)
        return float(first.gps_time[0]) if len(first) else None

    def count(self, path: Path) -> int:
        with laspy.open(path) as reader:
            _check_las_coordinates(reader.header, path)
            _check_las_size(reader.header, path)
            _warn_extra_records(reader.header, path)
            return int(reader.header.point_count)

    def record_count(self, path: Path) -> int:
        with laspy.open(path) as reader:
            return int(reader.header.point_count)

    def iter_xyz(self, path: Path, chunk_size: int | None = None) -> Iterator[np.ndarray]:
        for block in self.iter_blocks(path, chunk_size):
            yield block.xyz()

    def iter_blocks(self, path: Path, chunk_size: int | None = None) -> Iterator[Block]:
        """The X, Y, Z integers with the header's scales and offsets, ``chunk_size`` points at
        a time: an uncompressed file mapped chunk by chunk, a LAZ file decompressed once, on
        every core, and only its x, y and z (where its point format allows)."""
        size = chunk_size or LAS_CHUNK_SIZE
        with laspy.open(path, laz_backend=LAZ_BACKEND, decompression_selection=XYZ) as reader:
            header = reader.header
            _check_las_coordinates(header, path)
            scale = np.array(header.scales, np.float64)
            offset = np.array(header.offsets, np.float64)
            if not header.are_points_compressed:
                _check_las_size(header, path)
                n = int(header.point_count)
                for start in range(0, n, size):  # a mapping per chunk: memory stays bounded
                    records = _records(path, header, start, min(size, n - start))
                    yield Block(_integers(records), scale, offset)
                return
            for chunk in _las_chunks(reader, path, size):
                yield Block(_integers(chunk.array), scale, offset)

    def read_xyz(self, path: Path) -> np.ndarray:
        with laspy.open(path, laz_backend=LAZ_BACKEND, decompression_selection=XYZ) as reader:
            header = reader.header
            _check_las_coordinates(header, path)
            if header.are_points_compressed:  # a LAZ file's size does not vouch for its count
                chunks = _las_chunks(reader, path, LAS_CHUNK_SIZE)
                parts = [_scaled_xyz(c, np.empty((len(c), 3))) for c in chunks]
                return np.concatenate(parts) if parts else np.empty((0, 3))
            _check_las_size(header, path)  # before mapping what the header announces
            n = int(header.point_count)
            return _scaled_records(_records(path, header, 0, n), header, np.empty((n, 3)))


LAZ_BACKEND = laspy.LazBackend.LazrsParallel  # lazrs decompresses a file's chunks on every core
XYZ = laspy.DecompressionSelection.xy_returns_channel() | laspy.DecompressionSelection.Z
"""The layers a LAZ file of point format 6 to 10 decompresses for the registration: x and y
(stored with the returns and the channel), and z; the other formats store points whole."""


def _integers(records: np.ndarray) -> np.ndarray:
    """(m,3) int32 X, Y, Z of LAS point records (mapped or decompressed), read in one pass
    over the records (:func:`ndt_cli.core.records.xyz_integers`)."""
    return xyz_integers(record_bytes(records))


SCALE_BLOCK = 65_536  # records scaled at a time: the block's columns stay in the CPU's cache


def _records(path: Path, header: laspy.LasHeader, start: int, count: int) -> np.ndarray:
    """Point records ``start .. start+count-1`` of an uncompressed LAS file, mapped read-only
    from the file (the caller has checked that the file holds them)."""
    dtype = header.point_format.dtype()
    if count == 0:
        return np.empty(0, dtype)
    offset = header.offset_to_point_data + start * dtype.itemsize
    return np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=(count,))


def _scaled_records(records: np.ndarray, header: laspy.LasHeader, out: np.ndarray) -> np.ndarray:
    """The scaled x, y, z of LAS point records written into ``out`` (m,3): for each axis
    ``X * scale + offset`` in float64, as laspy computes them."""
    scales, offsets = header.scales, header.offsets
    for start in range(0, len(records), SCALE_BLOCK):
        block, rows = records[start : start + SCALE_BLOCK], out[start : start + SCALE_BLOCK]
        for k, name in enumerate("XYZ"):
            np.multiply(block[name], scales[k], out=rows[:, k])
            np.add(rows[:, k], offsets[k], out=rows[:, k])
    return out


def _scaled_xyz(chunk: laspy.ScaleAwarePointRecord, out: np.ndarray) -> np.ndarray:
    """The scaled x, y, z of a chunk of point records written into ``out`` (m,3)."""
    out[:, 0], out[:, 1], out[:, 2] = chunk.x, chunk.y, chunk.z
    return out


def _las_chunks(reader: laspy.LasReader, path: Path, chunk_size: int) -> Iterator:
    """The point records of an open LAS/LAZ file, ``chunk_size`` at a time; an InputError when
    the file holds more or fewer points than its header announces."""
    n = int(reader.header.point_count)
    _check_las_size(reader.header, path)
    filled = 0
    for chunk in reader.chunk_iterator(chunk_size):
        if filled + len(chunk) > n:
            raise InputError(f"file holds more points than its header's {n}", path)
        filled += len(chunk)
        yield chunk
    if filled != n:
        raise InputError(f"truncated file: header announces {n} points, found {filled}", path)


FARTHEST = 1e15  # m: no coordinate of a real scan lies farther (float64 keeps 0.1 m there)


def _check_las_coordinates(header: laspy.LasHeader, path: Path) -> None:
    """The header's scales and offsets must give real coordinates: finite, positive scales,
    finite offsets, and no stored integer mapped beyond :data:`FARTHEST` metres."""
    scales = np.asarray(header.scales, np.float64)
    offsets = np.asarray(header.offsets, np.float64)
    if not (np.isfinite(scales).all() and (scales > 0).all() and np.isfinite(offsets).all()):
        raise InputError(
            f"the header's scales {scales.tolist()} or offsets {offsets.tolist()} are not "
            "usable (a damaged header?)",
            path,
        )
    reach = float(np.max(np.abs(offsets) + scales * 2.0**31))
    if reach > FARTHEST:
        raise InputError(
            f"the header's scales {scales.tolist()} and offsets {offsets.tolist()} put "
            f"coordinates up to {reach:.3g} m, beyond any real scan (a damaged header?)",
            path,
        )


def _check_las_size(header: laspy.LasHeader, path: Path) -> None:
    """An uncompressed LAS file must hold the bytes of every point its header announces; a
    LAZ file, its chunk table (which a LAZ writer puts after the points)."""
    if header.are_points_compressed:
        _check_laz_size(header, path)
        return
    n = int(header.point_count)
    record = header.point_format.size
    needed = header.offset_to_point_data + n * record
    size = path.stat().st_size
    if size < needed:
        raise InputError(
            f"truncated LAS file: header announces {n} points ({needed} bytes), "
            f"file has {size} bytes",
            path,
        )


def _check_laz_size(header: laspy.LasHeader, path: Path) -> None:
    """A LAZ file cut short (an aborted copy) ends before the chunk table whose offset the
    first 8 bytes of its point data give (-1: written without one; not checked). Only
    chunked LAZ (every LAZ writer of today: compressor 2 or 3 in its LASzip record) has one."""
    zip_vlr = next((v for v in header.vlrs if getattr(v, "record_id", None) == 22204), None)
    data = getattr(zip_vlr, "record_data", None) or b""
    if int.from_bytes(bytes(data[:2]), "little") not in (2, 3):
        return
    size = path.stat().st_size
    with open(path, "rb") as fh:
        fh.seek(header.offset_to_point_data)
        raw = fh.read(8)
    table = int.from_bytes(raw, "little", signed=True) if len(raw) == 8 else 0
    if len(raw) < 8 or table + 8 > size:
        raise InputError(
            f"truncated LAZ file: it ends at byte {size}, before its chunk table"
            + (f" (at byte {table})" if len(raw) == 8 else ""),
            path,
        )


def _warn_extra_records(header: laspy.LasHeader, path: Path) -> None:
    """Report point records beyond the header's count (a header that undercounts its file)."""
    if header.are_points_compressed:
        return
    n, record = int(header.point_count), header.point_format.size
    needed = header.offset_to_point_data + n * record
    evlr = int(getattr(header, "start_of_first_evlr", 0) or 0)
    end = evlr if evlr >= needed else path.stat().st_size
    if end - needed >= record:
        logger.warning(
            "%s: the file holds %d more point records than its header's %d; only those are read",
            path,
            (end - needed) // record,
            n,
        )


class PcdReader(PointReader):
    """PCD (ascii, binary, binary_compressed) via pypcd4: fields x, y, z."""

    suffixes = (".pcd",)
    name = "pcd"

    def summary(self, path: Path) -> Summary:
        return record_io.pcd_summary(path)

    def check(self, path: Path) -> None:
        record_io.pcd_summary(path)  # the header: FIELDS (x, y, z among them) ... DATA

    def records(self, path: Path, chunk_points: int) -> Iterator[Chunk]:
        return record_io.pcd_chunks(path, chunk_points)

    def read_xyz(self, path: Path) -> np.ndarray:
        if not _pcd_header(path):
            raise InputError("not a PCD file (no FIELDS/DATA header)", path)
        import pypcd4  # here: with pydantic it takes ~0.1 s no other format needs

        cloud = pypcd4.PointCloud.from_path(path)
        require_xyz(cloud.fields, path)
        data = np.atleast_1d(cloud.pc_data)
        if len(data) != cloud.metadata.points:
            raise InputError(
                f"truncated file: header announces {cloud.metadata.points} points, "
                f"found {len(data)}",
                path,
            )
        return stack_xyz(data)


def _pcd_header(path: Path, max_lines: int = 100_000) -> bool:
    """Whether the file starts with a PCD header (comments of any length, then FIELDS ... DATA)."""
    fields = False
    with path.open("rb") as fh:
        for _, line in zip(range(max_lines), fh, strict=False):
            word = line.split(maxsplit=1)[0].upper() if line.split() else b""
            if word.startswith(b"#") or not word:
                continue
            fields |= word == b"FIELDS"
            if word == b"DATA":
                return fields
    return False


class E57Reader(PointReader):
    """E57 scans (optional pye57); ``FILE.e57#K`` names scan K, see :mod:`ndt_cli.io.e57`."""

    suffixes = (".e57",)
    name = "e57"

    def scan_count(self, path: Path) -> int:
        from ndt_cli.io import e57

        return e57.scan_count(path)

    def header_pose(self, spec: Path) -> np.ndarray | None:
        from ndt_cli.io import e57

        return e57.header_pose(spec)

    def acquired(self, spec: Path) -> float | None:
        from ndt_cli.io import e57

        return e57.acquisition_start(spec)

    def summary(self, path: Path) -> Summary:
        return record_io.e57_summary(path)

    def records(self, path: Path, chunk_points: int) -> Iterator[Chunk]:
        return record_io.e57_chunks(path, chunk_points)

    def check(self, path: Path) -> None:
        from ndt_cli.io import e57

        e57.check_scan(path)

    def record_count(self, path: Path) -> int:
        from ndt_cli.io import e57

        return e57.record_count(path)

    def iter_xyz(self, path: Path, chunk_size: int | None = None) -> Iterator[np.ndarray]:
        from ndt_cli.io import e57

        yield from e57.iter_xyz(path, chunk_size or LAS_CHUNK_SIZE)

    def iter_blocks(self, path: Path, chunk_size: int | None = None) -> Iterator[Block]:
        from ndt_cli.io import e57

        yield from e57.iter_blocks(path, chunk_size or LAS_CHUNK_SIZE)

    def read_xyz(self, path: Path) -> np.ndarray:
        from ndt_cli.io import e57

        return e57.read_xyz(path)


class PtxReader(PointReader):
    """PTX (Leica Cyclone text); ``FILE.ptx#K`` names scan K, see :mod:`ndt_cli.io.ptx`."""

    suffixes = (".ptx",)
    name = "ptx"

    def scan_count(self, path: Path) -> int:
        from ndt_cli.io import ptx

        return ptx.scan_count(path)

    def header_pose(self, spec: Path) -> np.ndarray | None:
        from ndt_cli.io import ptx

        return ptx.header_pose(spec)

    def summary(self, path: Path) -> Summary:
        return record_io.ptx_summary(path)

    def records(self, path: Path, chunk_points: int) -> Iterator[Chunk]:
        return record_io.ptx_chunks(path, chunk_points)

    def count(self, path: Path) -> int:
        from ndt_cli.io import ptx

        return ptx.scan_of(path).count

    def read_xyz(self, path: Path) -> np.ndarray:
        from ndt_cli.io import ptx

        return ptx.read_xyz(path)


def stack_xyz(data: np.ndarray) -> np.ndarray:
    """(N,3) float64 of the x, y, z fields of a structured array."""
    out = np.empty((len(data), 3), dtype=np.float64)
    for i, name in enumerate("xyz"):
        out[:, i] = data[name]
    return out
