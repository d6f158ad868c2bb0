"""The PLY and E57 outputs of :mod:`ndt_cli.io.export`.

PLY: binary little endian, one ``vertex`` element: x, y, z (float64, world frame, m), every
attribute of the inputs (union by name, types promoted; LAS extra bytes with a scale as their
float64 values, multi-element ones as ``name_0``, ``name_1``, ...; 64-bit integers as float64,
PLY has no 64-bit integers) and ``scan_index`` (uint16). A scan without an attribute gets zeros.
The vertex count is patched into the header at the end (a padded comment line keeps the header
length), so points are streamed.

E57: one scan per station (``data3D`` child named after the scan), its points in its own
scanner frame (raw file coordinates times ``S_scan_file``, metres, float64) and its pose
``T_world_scan`` in the scan header (unit quaternion w, x, y, z and translation, m). Kept when
present: ``intensity`` (float32; ``intensityLimits`` from the source E57, 0..65535 for LAS,
else the values' range), colours (8 bits: LAS 16-bit colours are shifted right by 8 when any
colour value of the scan is above 255, known from a first pass over the scan, else taken as
8-bit values), ``rowIndex`` /
``columnIndex`` and ``timeStamp`` (from an E57 ``time_stamp`` or a LAS ``gps_time``). The file's
``coordinateMetadata`` is the WKT of the world frame's coordinate system (``--crs``) when the
export is given one, else the anchor's WKT when it has one.
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.errors import OutputError
from ndt_cli.io.records import Chunk, Dimension, RawVlr, Summary

if TYPE_CHECKING:
    from ndt_cli.io.export_inputs import ExportScan, ScanInput

log = logging.getLogger(__name__)

SCAN_INDEX = "scan_index"
_PLY_TYPES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort"}
_PLY_TYPES |= {"i4": "int", "u4": "uint", "f4": "float", "f8": "double"}
_PAD = 24  # spare header bytes for the vertex count


@dataclass(frozen=True)
class PlyColumn:
    """One vertex property: its name, type, and where it comes from (input attribute, and the
    element of a multi-element one)."""

    name: str
    dtype: np.dtype
    source: str
    element: int | None = None


def _ply_type(d: Dimension) -> np.dtype:
    base = d.dtype.base
    if d.scales is not None or base.str[1:] not in _PLY_TYPES:
        return np.dtype("<f8")
    return base.newbyteorder("<")


def ply_columns(summaries: Sequence[Summary]) -> list[PlyColumn]:
    """x, y, z, the union of the attributes (first-seen order, types promoted), scan_index."""
    cols: dict[str, PlyColumn] = {a: PlyColumn(a, np.dtype("<f8"), a) for a in "xyz"}
    for s in summaries:
        for d in s.dimensions:
            n = d.dtype.shape[0] if d.dtype.shape else None
            for k in range(n) if n else [None]:
                name = d.name if k is None else f"{d.name}_{k}"
                if name == SCAN_INDEX or name in "xyz":
                    raise OutputError(
                        f"attribute name {name!r} is reserved in the PLY output", s.path
                    )
                dtype = _ply_type(d)
                if name in cols:
                    dtype = np.promote_types(cols[name].dtype, dtype).newbyteorder("<")
                    dtype = dtype if dtype.str[1:] in _PLY_TYPES else np.dtype("<f8")
                cols[name] = PlyColumn(name, dtype, d.name, k)
    cols[SCAN_INDEX] = PlyColumn(SCAN_INDEX, np.dtype("<u2"), SCAN_INDEX)
    return list(cols.values())


def _ply_header(columns: Sequence[PlyColumn], count: int, size: int | None = None) -> bytes:
    """The PLY header; with ``size``, the comment line is padded to make it ``size`` bytes."""
    props = "".join(f"property {_PLY_TYPES[c.dtype.str[1:]]} {c.name}\n" for c in columns)
    tail = f"\nelement vertex {count}\n{props}end_header\n"
    head = "ply\nformat binary_little_endian 1.0\ncomment ndt-cli export"
    pad = _PAD if size is None else size - len(head) - len(tail)
    return (head + " " * pad + tail).encode("ascii")


class PlySink:
    """A PLY file being written (see the module docstring)."""

    def __init__(self, tmp: Path, inputs: Sequence[ScanInput]) -> None:
        self.columns = ply_columns([i.summary for i in inputs])
        self.dtype = np.dtype([(c.name, c.dtype) for c in self.columns])
        self._header_size = len(_ply_header(self.columns, 0))
        self._fh: BinaryIO = open(tmp, "wb")  # noqa: SIM115 - closed by close() / abort()
        self._fh.write(_ply_header(self.columns, 0))
        self._count = 0
        self._item: ScanInput | None = None

    def begin(self, item: ScanInput) -> None:
        self._item = item

    def _values(self, c: PlyColumn, chunk: Chunk) -> np.ndarray | None:
        assert self._item is not None
        if c.source not in chunk:
            return None
        v = chunk[c.source] if c.element is None else chunk[c.source][:, c.element]
        d = self._item.summary.dimension(c.source)
        if d is not None and d.scales is not None and d.offsets is not None:  # LAS extra bytes
            k = c.element or 0
            return v * d.scales[k] + d.offsets[k]
        return v

    def write(self, chunk: Chunk, world: np.ndarray) -> None:
        assert self._item is not None
        rows = np.zeros(len(world), dtype=self.dtype)
        for k, a in enumerate("xyz"):
            rows[a] = world[:, k]
        for c in self.columns[3:-1]:
            values = self._values(c, chunk)
            if values is not None:
                rows[c.name] = values
        rows[SCAN_INDEX] = self._item.scan.index
        self._fh.write(rows.tobytes())
        self._count += len(rows)

    def end(self) -> None:
        self._item = None

    def close(self) -> None:
        self._fh.seek(0)
        self._fh.write(_ply_header(self.columns, self._count, self._header_size))
        self._fh.close()

    def abort(self) -> None:
        self._fh.close()


# --- E57 -------------------------------------------------------------------------------------


def _wkt(inputs: Sequence[ScanInput], anchor: ExportScan, crs: tuple[RawVlr, ...] | None) -> str:
    """The WKT (LAS record 2112) of ``crs``, else of the anchor scan, or ''."""
    from ndt_cli.io.records import summary

    if crs is None:
        item = next((i for i in inputs if i.scan is anchor), None)
        crs = item.summary.crs if item is not None else summary(anchor.path).crs
    wkt = next((v.data for v in crs if v.record_id == 2112), b"")
    return wkt.split(b"\0", 1)[0].decode("utf-8", errors="replace")


def _pose(scan: ExportScan) -> tuple[np.ndarray, np.ndarray]:
    """Unit quaternion (w, x, y, z) and translation (m) of ``T_world_scan``."""
    from ndt_cli.core.transforms import rotation_to_quaternion

    T = scan.T_world_scan
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise OutputError(
            "T_world_scan is not a rotation: give the scan's scale/axes in S_scan_file", scan.path
        )
    return rotation_to_quaternion(R), T[:3, 3].copy()


def _libe57() -> Any:
    try:
        from pye57 import libe57
    except ImportError:
        raise OutputError("writing E57 needs pye57: pip install 'ndt-cli[e57]'") from None
    return libe57


def _e57_root(imf: Any, e: Any, wkt: str) -> None:
    """The root of a new E57 file (as pye57 writes it), with ``coordinateMetadata`` = ``wkt``."""
    imf.extensionsAdd("", e.E57_V1_0_URI)
    root = imf.root()
    root.set("formatName", e.StringNode(imf, "ASTM E57 3D Imaging Data File"))
    root.set("guid", e.StringNode(imf, f"{{{uuid.uuid4()}}}"))
    root.set("versionMajor", e.IntegerNode(imf, e.E57_FORMAT_MAJOR))
    root.set("versionMinor", e.IntegerNode(imf, e.E57_FORMAT_MINOR))
    root.set("e57LibraryVersion", e.StringNode(imf, e.E57_LIBRARY_ID))
    root.set("coordinateMetadata", e.StringNode(imf, wkt))
    created = e.StructureNode(imf)
    created.set("dateTimeValue", e.FloatNode(imf, 0.0))
    created.set("isAtomicClockReferenced", e.IntegerNode(imf, 0))
    root.set("creationDateTime", created)
    root.set("data3D", e.VectorNode(imf, True))
    root.set("images2D", e.VectorNode(imf, True))


def _e57_fields(summary: Summary, imf: Any, e: Any) -> list[tuple[str, str, str, Any]]:
    """(E57 field, source attribute, buffer type, prototype node) of the attributes kept."""
    names = set(summary.names)
    out = [(f"cartesian{a}", a.lower(), "f8", e.FloatNode(imf, 0.0, e.E57_DOUBLE)) for a in "XYZ"]
    if "intensity" in names:
        out.append(("intensity", "intensity", "f4", e.FloatNode(imf, 0.0, e.E57_SINGLE)))
    if {"red", "green", "blue"} <= names:
        for c in ("Red", "Green", "Blue"):
            out.append((f"color{c}", c.lower(), "u1", e.IntegerNode(imf, 0, 0, 255)))
    if {"row_index", "column_index"} <= names:
        for field, source in (("rowIndex", "row_index"), ("columnIndex", "column_index")):
            out.append((field, source, "q", e.IntegerNode(imf, 0, 0, 2**31 - 1)))
    time = next((n for n in ("time_stamp", "gps_time") if n in names), None)
    if time is not None:
        out.append(("timeStamp", time, "f8", e.FloatNode(imf, 0.0, e.E57_DOUBLE)))
    return out


def _limits_node(imf: Any, e: Any, prefix: str, lo: float, hi: float, integer: bool) -> Any:
    node = e.StructureNode(imf)
    make = (lambda v: e.IntegerNode(imf, int(v))) if integer else (lambda v: e.FloatNode(imf, v))
    node.set(f"{prefix}Minimum", make(lo))
    node.set(f"{prefix}Maximum", make(hi))
    return node


class E57Sink:
    """An E57 file being written, one scan per station (see the module docstring)."""

    def __init__(
        self,
        tmp: Path,
        inputs: Sequence[ScanInput],
        anchor: ExportScan,
        capacity: int,
        crs: tuple[RawVlr, ...] | None = None,
    ) -> None:
        self._e = _libe57()
        tmp.unlink()  # libE57 creates the file itself
        self._imf = self._e.ImageFile(str(tmp), "w")
        _e57_root(self._imf, self._e, _wkt(inputs, anchor, crs))
        self._capacity = max(1, capacity)
        self._item: ScanInput | None = None
        self._warned = False

    def begin(self, item: ScanInput) -> None:
        e, imf = self._e, self._imf
        self._rotation, self._translation = _pose(item.scan)
        self._scan = e.StructureNode(imf)
        self._scan.set("guid", e.StringNode(imf, f"{{{uuid.uuid4()}}}"))
        self._scan.set("name", e.StringNode(imf, item.scan.name))
        self._scan.set("description", e.StringNode(imf, "ndt-cli export"))
        self._fields = _e57_fields(item.summary, imf, e)
        prototype = e.StructureNode(imf)
        for field, _, _, node in self._fields:
            prototype.set(field, node)
        points = e.CompressedVectorNode(imf, prototype, e.VectorNode(imf, True))
        self._scan.set("points", points)
        imf.root()["data3D"].append(self._scan)
        self._arrays = {f: np.empty(self._capacity, t) for f, _, t, _ in self._fields}
        buffers = e.VectorSourceDestBuffer()
        for field, array in self._arrays.items():
            buffers.append(e.SourceDestBuffer(imf, field, array, self._capacity, True, True))
        self._writer = points.writer(buffers)
        top = max(item.ranges.get(c, (0, 0))[1] for c in ("red", "green", "blue"))
        self._item, self._shift = item, 8 if top > 255 else 0
        self._lo, self._hi = np.full(4, np.inf), np.full(4, -np.inf)  # x, y, z, intensity

    def _colour(self, values: np.ndarray) -> np.ndarray:
        """8-bit colour values (LAS 16-bit colours shifted, see the module docstring)."""
        if values.dtype == np.uint8:
            return values
        out = values >> self._shift
        if out.max(initial=0) > 255:
            if not self._warned:
                log.warning("%s: colour values above 255 clipped", self._item.scan.path)
                self._warned = True
            out = np.minimum(out, 255)
        return out

    def write(self, chunk: Chunk, world: np.ndarray) -> None:
        S = self._item.scan.S_scan_file
        xyz = np.column_stack([chunk["x"], chunk["y"], chunk["z"]]) @ S[:3, :3].T + S[:3, 3]
        columns = {"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}
        for field, source, _, _ in self._fields[3:]:
            v = chunk[source]
            columns[source] = self._colour(v) if field.startswith("color") else v
        low, high = column_bounds(xyz)
        self._lo[:3] = np.minimum(self._lo[:3], low)
        self._hi[:3] = np.maximum(self._hi[:3], high)
        if "intensity" in columns:
            self._lo[3] = min(self._lo[3], float(columns["intensity"].min()))
            self._hi[3] = max(self._hi[3], float(columns["intensity"].max()))
        for start in range(0, len(xyz), self._capacity):
            n = min(self._capacity, len(xyz) - start)
            for field, source, _, _ in self._fields:
                self._arrays[field][:n] = columns[source][start : start + n]
            self._writer.write(n)

    def end(self) -> None:
        e, imf, scan = self._e, self._imf, self._scan
        self._writer.close()
        if np.isfinite(self._lo[:3]).all():
            bounds = e.StructureNode(imf)
            for k, a in enumerate("xyz"):
                bounds.set(f"{a}Minimum", e.FloatNode(imf, float(self._lo[k])))
                bounds.set(f"{a}Maximum", e.FloatNode(imf, float(self._hi[k])))
            scan.set("cartesianBounds", bounds)
        if "intensity" in self._arrays:
            lo, hi = self._intensity_limits()
            if lo <= hi:
                scan.set("intensityLimits", _limits_node(imf, e, "intensity", lo, hi, False))
        if "colorRed" in self._arrays:
            limits = e.StructureNode(imf)
            for c in ("Red", "Green", "Blue"):
                limits.set(f"color{c}Minimum", e.IntegerNode(imf, 0))
                limits.set(f"color{c}Maximum", e.IntegerNode(imf, 255))
            scan.set("colorLimits", limits)
        scan.set("pose", self._pose_node())
        self._item = None

    def _intensity_limits(self) -> tuple[float, float]:
        """The source E57's limits, the uint16 range for LAS, else the values' range."""
        s = self._item.summary
        if s.intensity_limits is not None:
            return s.intensity_limits
        d = s.dimension("intensity")
        if d is not None and d.kind == "las":
            return 0.0, 65535.0
        return float(self._lo[3]), float(self._hi[3])

    def _pose_node(self) -> Any:
        e, imf = self._e, self._imf
        pose, rotation, translation = (e.StructureNode(imf) for _ in range(3))
        for name, value in zip("wxyz", self._rotation, strict=True):
            rotation.set(name, e.FloatNode(imf, float(value)))
        for name, value in zip("xyz", self._translation, strict=True):
            translation.set(name, e.FloatNode(imf, float(value)))
        pose.set("rotation", rotation)
        pose.set("translation", translation)
        return pose

    def close(self) -> None:
        self._imf.close()

    def abort(self) -> None:
        try:
            self._imf.cancel()
        except Exception:  # the file is discarded anyway
            log.debug("closing the E57 file after a failure failed", exc_info=True)
