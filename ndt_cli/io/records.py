"""Point records with every attribute: chunked readers and header summaries of all formats.

Where :mod:`ndt_cli.io.points` reads x, y, z only, this module keeps every per-point attribute a
file holds, for writing the registered cloud (:mod:`ndt_cli.io.export`):

- :func:`summary` describes a file from its header without reading the points: the point count,
  the bounding box (LAS/LAZ), the LAS point format and version, the CRS records (VLRs under
  ``LASF_Projection``: WKT 2112, GeoTIFF keys 34735/34736/34737) and the name and storage type of
  each attribute (:class:`Dimension`).
- :func:`iter_records` yields chunks of at most ``chunk_points`` points as ``dict`` of arrays:
  ``"x"``, ``"y"``, ``"z"`` (float64, the file's own coordinates, before any ``input.scale`` or
  ``input.axes``) plus one array per :class:`Dimension`, in its storage type (LAS extra bytes
  with a scale stay raw integers; ``Dimension.scales`` / ``offsets`` give their meaning).

Per format: LAS/LAZ every standard dimension (bit fields as uint8) and every extra-bytes
dimension, streamed with laspy's ``chunk_iterator``; PLY every scalar ``vertex`` property
(binary files are memory-mapped and sliced); PCD every field (a packed ``rgb``/``rgba`` field
becomes ``red``, ``green``, ``blue``); E57 (``FILE.e57#K`` names scan K, see
:mod:`ndt_cli.io.e57`) ``intensity``, ``red``/``green``/``blue``, ``row_index``/``column_index``
and ``time_stamp`` when present, streamed, points flagged invalid dropped, spherical coordinates
turned cartesian; PTX (``FILE.ptx#K``, see :mod:`ndt_cli.io.ptx`) ``intensity`` and
``red``/``green``/``blue`` when present; text files x, y, z only. No point is dropped here
otherwise.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import laspy
import numpy as np

from ndt_cli.errors import InputError
from ndt_cli.io.multiscan import split_spec
from ndt_cli.io.points import file_errors

CHUNK_POINTS = 1_000_000
"""Default points per chunk (about 100 MB of records and coordinates for LAS format 7)."""

CRS_USER_ID = "LASF_Projection"
CRS_RECORD_IDS = (2111, 2112, 34735, 34736, 34737)
"""VLR record ids of the coordinate system: WKT math transform and coordinate system, GeoTIFF
key directory, double and ASCII parameters."""

FORMATS = {
    ".las": "las",
    ".laz": "laz",
    ".ply": "ply",
    ".pcd": "pcd",
    ".e57": "e57",
    ".ptx": "ptx",
    ".xyz": "text",
    ".txt": "text",
    ".csv": "text",
    ".3d": "text",
}

Chunk = dict[str, np.ndarray]
"""Arrays of equal length: x, y, z (float64, file frame) and one per :class:`Dimension`."""


@dataclass(frozen=True)
class Dimension:
    """One per-point attribute besides x, y, z.

    ``dtype`` is the storage type of one value (a sub-array type such as ``(uint8, 3)`` for a
    multi-element LAS extra-bytes dimension). ``kind``: ``"las"`` a standard LAS dimension (bit
    fields as uint8), ``"extra"`` a LAS extra-bytes dimension, ``"field"`` an attribute of
    another format. LAS extra bytes with ``scales``: real value = raw * scale + offset.
    """

    name: str
    dtype: np.dtype
    kind: str = "field"
    scales: tuple[float, ...] | None = None
    offsets: tuple[float, ...] | None = None
    description: str = ""


@dataclass(frozen=True)
class RawVlr:
    """A LAS (extended) variable-length record exactly as stored: payload bytes untouched."""

    user_id: str
    record_id: int
    description: str
    data: bytes
    extended: bool = False

    def key(self) -> tuple[str, int, bytes]:
        """What makes two records the same CRS information (the description is free text)."""
        return self.user_id, self.record_id, self.data


@dataclass(frozen=True)
class Summary:
    """What a file's header says, without reading its points.

    ``bounds`` is (lo, hi), each (3,) float64 in the file's own coordinates, when the header
    holds a usable bounding box (LAS/LAZ), else None. ``count`` is None for text files.
    ``point_format`` / ``version`` / ``scales`` / ``offsets`` / ``crs`` / ``wkt`` (the global
    encoding WKT bit) / ``gps_standard`` (bit 0: adjusted standard GPS time) describe LAS/LAZ;
    ``intensity_limits`` and ``pose`` (4x4 scan-to-file pose of the header) describe E57 scans.
    """

    path: Path
    format: str
    count: int | None
    bounds: tuple[np.ndarray, np.ndarray] | None
    dimensions: tuple[Dimension, ...]
    point_format: int | None = None
    version: str | None = None
    scales: np.ndarray | None = None
    offsets: np.ndarray | None = None
    crs: tuple[RawVlr, ...] = ()
    wkt: bool = False
    gps_standard: bool = False
    intensity_limits: tuple[float, float] | None = None
    pose: np.ndarray | None = None

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the attributes besides x, y, z, in file order."""
        return tuple(d.name for d in self.dimensions)

    def dimension(self, name: str) -> Dimension | None:
        """The attribute called ``name``, or None."""
        return next((d for d in self.dimensions if d.name == name), None)


def format_of(path: str | Path) -> str:
    """Format name of a path by its extension (``FILE.e57#K`` is e57); InputError if unknown."""
    f = split_spec(path)[0]
    fmt = FORMATS.get(f.suffix.lower())
    if fmt is None:
        known = " ".join(sorted(FORMATS))
        raise InputError(f"unknown extension {f.suffix or '(none)'!r}; supported: {known}", path)
    return fmt


def _checked(path: str | Path) -> tuple[Path, str]:
    """The path and its format, after checking that its file exists and is not empty."""
    p = Path(path)
    f = split_spec(p)[0]
    fmt = format_of(p)
    if not f.exists():
        raise InputError("file not found", p)
    if f.is_dir():
        raise InputError("is a directory, not a point file", p)
    if f.stat().st_size == 0:
        raise InputError("file is empty", p)
    return p, fmt


def summary(path: str | Path) -> Summary:
    """Header summary of a point file (see :class:`Summary`); InputError if unreadable."""
    from ndt_cli.io import records_formats as other

    p, fmt = _checked(path)
    readers = {"las": _las_summary, "laz": _las_summary, "ply": other.ply_summary}
    readers |= {"pcd": other.pcd_summary, "e57": other.e57_summary, "text": other.text_summary}
    readers |= {"ptx": other.ptx_summary}
    with file_errors(p):
        return readers[fmt](p)


def iter_records(path: str | Path, chunk_points: int = CHUNK_POINTS) -> Iterator[Chunk]:
    """Chunks of at most ``chunk_points`` points, in file order, with every attribute (see the
    module docstring). A file that ends before its header's count is an InputError."""
    from ndt_cli.io import records_formats as other

    p, fmt = _checked(path)
    readers = {"las": _las_chunks, "laz": _las_chunks, "ply": other.ply_chunks}
    readers |= {"pcd": other.pcd_chunks, "e57": other.e57_chunks, "text": other.text_chunks}
    readers |= {"ptx": other.ptx_chunks}
    with file_errors(p):
        yield from readers[fmt](p, max(1, int(chunk_points)))


# --- LAS / LAZ -------------------------------------------------------------------------------


def _las_dimensions(point_format: laspy.PointFormat) -> tuple[Dimension, ...]:
    """Every dimension of a LAS point format but X, Y, Z (bit fields as uint8)."""
    out = []
    for d in point_format.dimensions:
        if d.name in ("X", "Y", "Z"):
            continue
        if d.is_standard:
            out.append(Dimension(d.name, d.dtype or np.dtype(np.uint8), "las"))
            continue
        dtype = d.dtype if d.num_elements == 1 else np.dtype((d.dtype.base, d.num_elements))
        scaled = d.scales is not None and d.offsets is not None
        out.append(
            Dimension(
                d.name,
                np.dtype(dtype),
                "extra",
                tuple(map(float, np.atleast_1d(d.scales))) if scaled else None,
                tuple(map(float, np.atleast_1d(d.offsets))) if scaled else None,
                d.description,
            )
        )
    return tuple(out)


def _las_bounds(header: laspy.LasHeader) -> tuple[np.ndarray, np.ndarray] | None:
    """The header's bounding box, or None when it is missing (all zeros) or inconsistent."""
    lo, hi = np.asarray(header.mins, float), np.asarray(header.maxs, float)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()) or (lo > hi).any():
        return None
    if not lo.any() and not hi.any() and header.point_count > 1:
        return None
    return lo, hi


def _las_summary(p: Path) -> Summary:
    with laspy.open(p) as reader:
        h = reader.header
        return Summary(
            path=p,
            format=format_of(p),
            count=int(h.point_count),
            bounds=_las_bounds(h),
            dimensions=_las_dimensions(h.point_format),
            point_format=int(h.point_format.id),
            version=str(h.version),
            scales=np.array(h.scales, float),
            offsets=np.array(h.offsets, float),
            crs=tuple(v for v in raw_vlrs(p) if is_crs(v)),
            wkt=bool(h.global_encoding.wkt),
            gps_standard=bool(h.global_encoding.gps_time_type.value),
        )


def _las_chunks(p: Path, chunk_points: int) -> Iterator[Chunk]:
    with laspy.open(p) as reader:
        n = int(reader.header.point_count)
        dims = _las_dimensions(reader.header.point_format)
        seen = 0
        for rec in reader.chunk_iterator(chunk_points):
            seen += len(rec)
            if seen > n:
                raise InputError(f"file holds more points than its header's {n}", p)
            out = {a: np.asarray(getattr(rec, a), dtype=np.float64) for a in "xyz"}
            for d in dims:
                out[d.name] = np.asarray(rec.array[d.name] if d.kind == "extra" else rec[d.name])
            yield out
    if seen != n:
        raise InputError(f"truncated file: header announces {n} points, found {seen}", p)


def is_crs(vlr: RawVlr) -> bool:
    """True for the coordinate-system records (user id ``LASF_Projection``)."""
    return vlr.user_id == CRS_USER_ID and vlr.record_id in CRS_RECORD_IDS


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", errors="replace")


def raw_vlrs(path: str | Path) -> list[RawVlr]:
    """Every VLR and EVLR of a LAS/LAZ file with its payload bytes exactly as stored.

    Read from the file's bytes (LAS 1.0-1.4 header layout), not re-encoded by laspy, so that a
    CRS can be copied byte for byte.
    """
    out: list[RawVlr] = []
    with open(split_spec(path)[0], "rb") as fh:
        head = fh.read(375)
        if head[:4] != b"LASF" or len(head) < 227:
            raise InputError("not a LAS file (no LASF signature)", path)
        header_size, _, n_vlrs = struct.unpack_from("<HII", head, 94)
        minor = head[25]
        fh.seek(header_size)
        for _ in range(n_vlrs):
            rec = fh.read(54)
            if len(rec) < 54:
                raise InputError("truncated VLR in the header", path)
            _, user, rid, length, desc = struct.unpack("<H16sHH32s", rec)
            out.append(RawVlr(_text(user), rid, _text(desc), fh.read(length)))
        if minor >= 4 and len(head) >= 375:
            start, n_evlrs = struct.unpack_from("<QI", head, 235)
            if n_evlrs:
                fh.seek(start)
            for _ in range(n_evlrs if start else 0):
                rec = fh.read(60)
                if len(rec) < 60:
                    break
                _, user, rid, length, desc = struct.unpack("<H16sHQ32s", rec)
                out.append(RawVlr(_text(user), rid, _text(desc), fh.read(length), True))
    return out
