"""Every attribute of a point file, per format: LAS/LAZ, PLY, PCD, E57 and PTX (text files have
x, y, z only: :mod:`ndt_cli.io.text`); the readers of :mod:`ndt_cli.io.formats` call them.

Each format has a ``*_summary(path) -> Summary`` (header only) and a
``*_chunks(path, chunk_points) -> Iterator[Chunk]`` (x, y, z float64 in the file's own
coordinates plus every attribute, see :mod:`ndt_cli.io.records`).
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import laspy
import numpy as np

from ndt_cli.errors import InputError
from ndt_cli.io.multiscan import split_spec
from ndt_cli.io.record_types import Chunk, Dimension, RawVlr, Summary, is_crs, require_xyz

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_XYZ = ("x", "y", "z")


def _slices(n: int, chunk_points: int) -> Iterator[slice]:
    for start in range(0, n, chunk_points):
        yield slice(start, min(n, start + chunk_points))


# --- PLY -------------------------------------------------------------------------------------


def _ply_header(p: Path) -> tuple[int, list[tuple[str, str]]]:
    """Vertex count and the vertex element's scalar properties (name, numpy type)."""
    with open(p, "rb") as fh:
        if fh.readline().strip() != b"ply":
            raise InputError("not a PLY file (no 'ply' magic line)", p)
        element, count, props = None, None, []
        for raw in fh:
            words = raw.decode("ascii", errors="replace").split()
            if not words or words[0] in ("comment", "obj_info", "format"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "element":
                element = words[1]
                if element == "vertex":
                    count = int(words[2])
            elif words[0] == "property" and element == "vertex" and words[1] != "list":
                if words[1] not in _PLY_TYPES:
                    raise InputError(f"unknown PLY property type {words[1]!r}", p)
                props.append((words[2], _PLY_TYPES[words[1]]))
        else:
            raise InputError("PLY header has no end_header line", p)
    if count is None:
        raise InputError("PLY file has no 'vertex' element", p)
    require_xyz([name for name, _ in props], p)
    return count, props


def ply_summary(p: Path) -> Summary:
    count, props = _ply_header(p)
    dims = tuple(Dimension(n, np.dtype(t)) for n, t in props if n not in _XYZ)
    return Summary(p, "ply", count, None, dims)


def ply_chunks(p: Path, chunk_points: int) -> Iterator[Chunk]:
    """Binary PLY vertex data is memory-mapped and copied one chunk at a time."""
    import plyfile

    count, props = _ply_header(p)
    vertex = plyfile.PlyData.read(str(p), mmap="r")["vertex"].data
    if len(vertex) != count:
        raise InputError(f"truncated file: header announces {count} points, found {len(vertex)}", p)
    for s in _slices(count, chunk_points):
        part = vertex[s]
        out = {a: np.asarray(part[a], dtype=np.float64) for a in _XYZ}
        for name, t in props:
            if name not in _XYZ:
                out[name] = np.asarray(part[name], dtype=np.dtype(t))
        yield out


# --- PCD -------------------------------------------------------------------------------------


def _pcd_meta(p: Path) -> Any:
    import pypcd4

    lines = []
    with open(p, "rb") as fh:
        for raw in fh:
            line = raw.decode("utf-8", errors="replace").strip()
            if line and not line.startswith("#"):
                lines.append(line)
            if line.startswith("DATA") or len(lines) > 20:
                break
    if (
        not lines
        or not lines[-1].startswith("DATA")
        or not any(x.startswith("FIELDS") for x in lines)
    ):
        raise InputError("not a PCD file (no FIELDS/DATA header)", p)
    meta = pypcd4.MetaData.parse_header(lines)
    require_xyz(meta.fields, p)
    return meta


def _pcd_packed_rgb(dtype: np.dtype) -> str | None:
    """Name of a packed colour field (PCL's float32/uint32 ``rgb`` or ``rgba``), or None."""
    for name in ("rgb", "rgba"):
        if name in (dtype.names or ()) and dtype[name].itemsize == 4:
            return name
    return None


def pcd_summary(p: Path) -> Summary:
    dtype = _pcd_meta(p).build_dtype()
    packed = _pcd_packed_rgb(dtype)
    dims = [Dimension(n, dtype[n]) for n in dtype.names if n not in _XYZ and n != packed]
    if packed:
        dims += [Dimension(c, np.dtype(np.uint8)) for c in ("red", "green", "blue")]
    return Summary(p, "pcd", int(_pcd_meta(p).points), None, tuple(dims))


def pcd_chunks(p: Path, chunk_points: int) -> Iterator[Chunk]:
    import pypcd4

    meta = _pcd_meta(p)
    data = np.atleast_1d(pypcd4.PointCloud.from_path(p).pc_data)
    if len(data) != meta.points:
        raise InputError(
            f"truncated file: header announces {meta.points} points, found {len(data)}", p
        )
    packed = _pcd_packed_rgb(data.dtype)
    for s in _slices(len(data), chunk_points):
        part = data[s]
        out = {a: np.asarray(part[a], dtype=np.float64) for a in _XYZ}
        for name in data.dtype.names:
            if name not in _XYZ and name != packed:
                out[name] = np.ascontiguousarray(part[name])
        if packed:
            v = np.ascontiguousarray(part[packed]).view(np.uint32)
            for shift, c in zip((16, 8, 0), ("red", "green", "blue"), strict=True):
                out[c] = ((v >> shift) & 255).astype(np.uint8)
        yield out


# --- PTX -------------------------------------------------------------------------------------

_PTX_COLOURS = ("red", "green", "blue")


def _ptx_width(p: Path) -> int:
    """Numbers per point line of the scan: 4 (x y z intensity) or 7 (and red green blue)."""
    from ndt_cli.io import ptx

    first = next(ptx.chunks(p, 1), None)
    return 4 if first is None else first.shape[1]


def ptx_summary(p: Path) -> Summary:
    from ndt_cli.io import ptx

    scan = ptx.scan_of(p)
    dims = [Dimension("intensity", np.dtype("f4"))]
    if _ptx_width(p) == 7:
        dims += [Dimension(c, np.dtype("u1")) for c in _PTX_COLOURS]
    return Summary(p, "ptx", scan.count, None, tuple(dims), pose=scan.transform)


def ptx_chunks(p: Path, chunk_points: int) -> Iterator[Chunk]:
    """Point lines as read (missing returns ``0 0 0`` included), scanner frame."""
    from ndt_cli.io import ptx

    for block in ptx.chunks(p, chunk_points):
        out = {a: np.ascontiguousarray(block[:, k]) for k, a in enumerate(_XYZ)}
        out["intensity"] = block[:, 3].astype(np.float32)
        if block.shape[1] == 7:
            for k, c in enumerate(_PTX_COLOURS):
                out[c] = np.clip(block[:, 4 + k], 0, 255).astype(np.uint8)
        yield out


# --- text ------------------------------------------------------------------------------------


# --- E57 -------------------------------------------------------------------------------------

_E57_FIELDS = {  # E57 point field -> (attribute name, buffer type)
    "intensity": ("intensity", "f4"),
    "colorRed": ("red", None),
    "colorGreen": ("green", None),
    "colorBlue": ("blue", None),
    "rowIndex": ("row_index", "q"),  # libE57 buffers: "q" is int64 ("l" is taken as 32-bit)
    "columnIndex": ("column_index", "q"),
    "timeStamp": ("time_stamp", "f8"),
}


def _e57_scan(spec: Path) -> tuple[Any, int]:
    """The open E57 file and the index of the scan ``spec`` names (``FILE.e57#K``)."""
    from ndt_cli.io.e57 import open_file
    from ndt_cli.io.multiscan import which_scan

    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        return e57, which_scan(path, index, int(e57.scan_count), str(spec))
    except BaseException:
        e57.close()
        raise


def _number(node: Any) -> float:
    """The value of an E57 Integer, ScaledInteger or Float node."""
    from pye57 import libe57

    kinds = {
        libe57.E57_INTEGER: lambda n: libe57.IntegerNode(n).value(),
        libe57.E57_SCALED_INTEGER: lambda n: libe57.ScaledIntegerNode(n).scaledValue(),
        libe57.E57_FLOAT: lambda n: libe57.FloatNode(n).value(),
    }
    return float(kinds[node.type()](node))


def _limits(header: Any, node: str, lo: str, hi: str) -> tuple[float, float] | None:
    if node not in header.scan_fields:
        return None
    limits = header[node]
    if not (limits.isDefined(lo) and limits.isDefined(hi)):
        return None
    return _number(limits.get(lo)), _number(limits.get(hi))


def _colour_type(header: Any) -> np.dtype:
    """8 bits, or 16 when the colour field (or the scan's colour limits) goes above 255."""
    from pye57 import libe57

    top = _limits(header, "colorLimits", "colorRedMinimum", "colorRedMaximum")
    field = libe57.StructureNode(header.points.prototype()).get("colorRed")
    if field.type() == libe57.E57_INTEGER:
        top = (0.0, max(top[1] if top else 0.0, float(libe57.IntegerNode(field).maximum())))
    return np.dtype("u1" if top is None or top[1] <= 255 else "u2")


def _e57_layout(header: Any) -> tuple[list[tuple[str, str, np.dtype]], tuple[float, float] | None]:
    """(E57 field, attribute name, dtype) of every kept attribute, and the intensity limits."""
    colour_type = _colour_type(header) if "colorRed" in header.point_fields else np.dtype("u1")
    fields = []
    for field, (name, t) in _E57_FIELDS.items():
        if field in header.point_fields:
            fields.append((field, name, np.dtype(t) if t else colour_type))
    limits = _limits(header, "intensityLimits", "intensityMinimum", "intensityMaximum")
    return fields, limits


def e57_summary(p: Path) -> Summary:
    e57, k = _e57_scan(p)
    try:
        header = e57.get_header(k)
        fields, limits = _e57_layout(header)
        pose = None
        if header.has_pose():
            pose = np.eye(4)
            pose[:3, :3] = np.asarray(header.rotation_matrix, dtype=np.float64)
            pose[:3, 3] = np.asarray(header.translation, dtype=np.float64)
        dims = tuple(Dimension(name, t) for _, name, t in fields)
        return Summary(
            p, "e57", int(header.point_count), None, dims, intensity_limits=limits, pose=pose
        )
    finally:
        e57.close()


def _coordinate_fields(header: Any, p: Path) -> tuple[list[str], str]:
    fields = header.point_fields
    for names, state in (
        (["cartesianX", "cartesianY", "cartesianZ"], "cartesianInvalidState"),
        (["sphericalRange", "sphericalAzimuth", "sphericalElevation"], "sphericalInvalidState"),
    ):
        if set(names) <= set(fields):
            return names + ([state] if state in fields else []), state
    raise InputError("the scan has neither cartesian nor spherical coordinates", p)


def _e57_chunk(
    arrays: dict[str, np.ndarray], n: int, fields: list[tuple[str, str, np.dtype]]
) -> Chunk:
    """One chunk of the first ``n`` buffered records: cartesian x, y, z and the attributes."""
    if "cartesianX" in arrays:
        xyz = [arrays[f"cartesian{a}"][:n].copy() for a in "XYZ"]
    else:
        r, az, el = (arrays[f"spherical{a}"][:n] for a in ("Range", "Azimuth", "Elevation"))
        xyz = [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]
    out = dict(zip(_XYZ, xyz, strict=True))
    for field, name, _ in fields:
        out[name] = arrays[field][:n].copy()
    state = next((arrays[s][:n] for s in arrays if s.endswith("InvalidState")), None)
    if state is not None and state.any():
        keep = state == 0
        out = {k: v[keep] for k, v in out.items()}
    return out


def e57_chunks(p: Path, chunk_points: int) -> Iterator[Chunk]:
    """Streams a scan through libE57 buffers of ``chunk_points`` records (pose not applied)."""
    from pye57 import libe57

    e57, k = _e57_scan(p)
    try:
        header = e57.get_header(k)
        fields, _ = _e57_layout(header)
        coords, _ = _coordinate_fields(header, p)
        cap = int(min(chunk_points, max(1, header.point_count)))
        arrays: dict[str, np.ndarray] = {}
        buffers = libe57.VectorSourceDestBuffer()
        for name in coords:
            arrays[name] = np.empty(cap, np.int8 if name.endswith("State") else np.float64)
        for field, _, t in fields:
            arrays[field] = np.empty(cap, t)
        for name, arr in arrays.items():
            buffers.append(libe57.SourceDestBuffer(e57.image_file, name, arr, cap, True, True))
        reader = header.points.reader(buffers)
        try:
            while n := reader.read():
                yield _e57_chunk(arrays, n, fields)
        finally:
            reader.close()
    finally:
        e57.close()


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


def las_summary(p: Path) -> Summary:
    with laspy.open(p) as reader:
        h = reader.header
        return Summary(
            path=p,
            format=split_spec(p)[0].suffix.lower().lstrip("."),
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


def las_chunks(p: Path, chunk_points: int) -> Iterator[Chunk]:
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
