"""The LAS/LAZ output of :mod:`ndt_cli.io.export`: one point format for all scans, the union of
their extra bytes, ``scan_index``, the anchor's CRS, millimetre scales.

Point format (always LAS 1.4, which holds every format, extra bytes and 64-bit counts):

- 6 / 7 / 8 (the LAS 1.4 family) when any input has point format >= 6 or a ``nir`` dimension:
  8 with NIR, 7 with RGB, else 6;
- else the legacy family: 0, 1 (GPS time), 2 (RGB), 3 (GPS time and RGB);
- waveform packets (formats 4, 5, 9, 10) are not copied (their formats become 1, 3, 6, 8).

Dimensions are copied by name. Legacy ``scan_angle_rank`` (degrees) becomes ``scan_angle``
(0.006 degree units) and back; a scan without a dimension gets zeros there. Attributes of other
formats (PLY, PCD, E57) fill the standard dimension of the same name when there is one: 8-bit
colours are scaled to 16 bits (x 257), float intensities are mapped linearly from their range
(E57 intensity limits, else the file's min..max) onto 0..65535, other values are rounded and
clipped to the dimension's range. Every other attribute becomes an extra-bytes dimension of its
own name and type. Extra bytes of the same name must have the same number of elements and the
same scales/offsets; different types are promoted when that loses nothing (int16 and int32 ->
int32, float32 and float64 -> float64, an integer and a float -> float64 only if the integer is
at most 32 bits); otherwise :class:`OutputError`.

``scan_index`` (uint16 extra bytes) holds :attr:`ExportScan.index` of each point's scan;
``point_source_id`` is kept as the input had it. The CRS records (``LASF_Projection``) and the
WKT bit of the anchor scan are copied byte for byte (a scan whose CRS records differ is logged as
a warning), unless the export is given the records of the world frame (a WKT of ``--crs``).
Scales are 1 mm, offsets the centre of the world bounding box (whole metres), so that
coordinates of millions of metres keep millimetres in the int32 range.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

import laspy
import numpy as np

from ndt_cli.errors import InputError, OutputError
from ndt_cli.io.records import Chunk, Dimension, RawVlr, Summary

if TYPE_CHECKING:
    from ndt_cli.io.export_inputs import ExportScan, ScanInput

log = logging.getLogger(__name__)

LAS_SCALE = 0.001
"""Coordinate resolution of the written LAS/LAZ, metres."""

SCAN_INDEX = "scan_index"
_SCAN_INDEX_DIM = Dimension(
    SCAN_INDEX, np.dtype(np.uint16), "extra", description="ndt-cli scan number"
)
_EXTRA_TYPES = {np.dtype(t) for t in ("u1", "i1", "u2", "i2", "u4", "i4", "u8", "i8", "f4", "f8")}
_SCAN_ANGLE_UNIT = 0.006  # degrees per unit of LAS 1.4 scan_angle
_ALIASES = {"scan_angle": "scan_angle_rank", "scan_angle_rank": "scan_angle"}
_WAVEFORM = {4: 1, 5: 3, 9: 6, 10: 8}


def _names(summaries: Sequence[Summary]) -> set[str]:
    return {d.name for s in summaries for d in s.dimensions}


def choose_point_format(summaries: Sequence[Summary]) -> int:
    """The LAS point format holding the dimensions of every input (see the module docstring)."""
    names = _names(summaries)
    formats = [
        _WAVEFORM.get(s.point_format, s.point_format)
        for s in summaries
        if s.point_format is not None
    ]
    rgb = bool({"red", "green", "blue"} & names)
    if "nir" in names or any(f >= 6 for f in formats):
        return 8 if "nir" in names else 7 if rgb else 6
    return {(False, False): 0, (True, False): 1, (False, True): 2, (True, True): 3}[
        ("gps_time" in names, rgb)
    ]


def _standard_names(point_format: int) -> set[str]:
    return set(laspy.PointFormat(point_format).dimension_names) - {"X", "Y", "Z"}


def _goes_standard(d: Dimension, standard: set[str]) -> bool:
    """Whether an input dimension is written into a standard dimension of the output."""
    return d.name in standard or (d.name in _ALIASES and _ALIASES[d.name] in standard)


def _promote(a: np.dtype, b: np.dtype) -> np.dtype | None:
    """The type holding both without loss, or None."""
    r = np.promote_types(a, b)
    ints = [t for t in (a, b) if t.kind in "iu"]
    if r.kind == "f" and ints and max(t.itemsize for t in ints) > 4:
        return None
    return r if r in _EXTRA_TYPES else None


def _merge_extra(a: Dimension, b: Dimension, path: Path) -> Dimension:
    """One extra-bytes dimension for two inputs' dimensions of the same name."""
    if a.dtype == b.dtype and a.scales == b.scales and a.offsets == b.offsets:
        return a
    problem = None
    if a.dtype.shape != b.dtype.shape:
        problem = f"{a.dtype.shape or 1} and {b.dtype.shape or 1} elements"
    elif (a.scales, a.offsets) != (b.scales, b.offsets):
        problem = f"scales/offsets {a.scales}/{a.offsets} and {b.scales}/{b.offsets}"
    elif (base := _promote(a.dtype.base, b.dtype.base)) is None:
        problem = f"types {a.dtype.base} and {b.dtype.base}"
    if problem is not None:
        raise OutputError(
            f"extra-bytes dimension {a.name!r} has {problem} in different scans; "
            "convert one of them",
            path,
        )
    dtype = np.dtype((base, a.dtype.shape)) if a.dtype.shape else base
    return Dimension(a.name, dtype, "extra", a.scales, a.offsets, a.description)


def extra_dimensions(summaries: Sequence[Summary], point_format: int) -> tuple[Dimension, ...]:
    """The union of the inputs' extra dimensions (by name, first-seen order), then scan_index."""
    standard = _standard_names(point_format)
    known = standard | {n for f in range(11) for n in laspy.PointFormat(f).dimension_names}
    out: dict[str, Dimension] = {}
    for s in summaries:
        for d in s.dimensions:
            if d.kind == "las" or (d.kind == "field" and _goes_standard(d, standard)):
                continue
            if d.name == SCAN_INDEX or d.name in known or len(d.name.encode()) > 32:
                why = "is reserved" if d.name == SCAN_INDEX or d.name in known else "is too long"
                raise OutputError(f"attribute name {d.name!r} {why} for LAS extra bytes", s.path)
            if d.dtype.base not in _EXTRA_TYPES:
                raise OutputError(
                    f"attribute {d.name!r} of type {d.dtype} cannot go into LAS", s.path
                )
            kind_d = Dimension(d.name, d.dtype, "extra", d.scales, d.offsets, d.description)
            out[d.name] = _merge_extra(out[d.name], kind_d, s.path) if d.name in out else kind_d
    return (*out.values(), _SCAN_INDEX_DIM)


def las_offsets(lo: np.ndarray, hi: np.ndarray, target: Path) -> np.ndarray:
    """Offsets (whole metres, centre of the world box) that keep ``lo..hi`` in int32 at 1 mm."""
    offsets = np.round(0.5 * (np.asarray(lo) + np.asarray(hi)))
    half = np.maximum(np.abs(hi - offsets), np.abs(lo - offsets)).max()
    if not np.isfinite(half) or half / LAS_SCALE >= 2**31 - 1:
        raise OutputError(f"extent too large for LAS at {LAS_SCALE} m resolution", target)
    return offsets


def anchor_crs(inputs: Sequence[ScanInput], anchor: ExportScan) -> tuple[tuple[RawVlr, ...], bool]:
    """The anchor's CRS records and WKT bit; a warning for every scan whose CRS differs."""
    first = next((i for i in inputs if i.scan is anchor), None)
    if first is None:  # a per-scan file: the anchor is another scan
        from ndt_cli.io.records import summary

        anchor_summary = summary(anchor.path)
    else:
        anchor_summary = first.summary
    crs = anchor_summary.crs
    keys = [v.key() for v in crs]
    for item in inputs:
        other = [v.key() for v in item.summary.crs]
        if other and other != keys:
            log.warning(
                "%s: its CRS differs from the anchor scan's (%s); the output carries the anchor's",
                item.scan.path,
                anchor.path,
            )
    return crs, anchor_summary.wkt or any(v.record_id == 2112 for v in crs)


def make_header(
    point_format: int,
    extras: Sequence[Dimension],
    offsets: np.ndarray,
    crs: Sequence[RawVlr],
    wkt: bool,
    gps_standard: bool,
) -> laspy.LasHeader:
    """A LAS 1.4 header: 1 mm scales, ``offsets`` (m), the extra bytes and the CRS records."""
    header = laspy.LasHeader(version="1.4", point_format=point_format)
    header.scales = np.full(3, LAS_SCALE)
    header.offsets = offsets
    for d in extras:
        scaled = d.scales is not None
        header.add_extra_dim(
            laspy.ExtraBytesParams(
                d.name,
                d.dtype,
                d.description[:32],
                offsets=np.array(d.offsets) if scaled else None,
                scales=np.array(d.scales) if scaled else None,
            )
        )
    for v in crs:
        if len(v.data) > 65535:
            raise OutputError(f"CRS record {v.record_id} of {len(v.data)} bytes does not fit a VLR")
        header.vlrs.append(laspy.VLR(v.user_id, v.record_id, v.description, v.data))
    header.global_encoding.wkt = bool(wkt)
    if gps_standard:
        header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    header.generating_software = "ndt-cli export"
    header.system_identifier = "MERGE"
    return header


def _int_range(point_format: laspy.PointFormat, name: str) -> tuple[float, float] | None:
    """(min, max) a standard integer dimension holds, None for floats."""
    info = point_format.dimension_by_name(name)
    if info.kind == laspy.DimensionKind.BitField:
        return 0, 2**info.num_bits - 1
    if info.dtype.kind == "f":
        return None
    limits = np.iinfo(info.dtype)
    return limits.min, limits.max


def _field_converter(
    name: str, src: Dimension, item: ScanInput, limits: tuple[float, float] | None
) -> Callable[[np.ndarray], np.ndarray]:
    """How an attribute of a non-LAS file becomes the standard dimension ``name``."""
    if name in ("red", "green", "blue", "nir") and src.dtype == np.uint8:
        return lambda v: v.astype(np.uint16) * np.uint16(257)
    if name == "intensity" and src.dtype.kind == "f":
        lo, hi = item.summary.intensity_limits or item.ranges.get("intensity", (0.0, 1.0))
        span = hi - lo if hi > lo else 1.0
        return lambda v: np.round(np.clip((v - lo) / span, 0.0, 1.0) * 65535.0)
    if limits is None:
        return lambda v: v
    lo, hi = limits
    return lambda v: np.clip(np.round(v) if v.dtype.kind == "f" else v, lo, hi)


def copy_plan(item: ScanInput, point_format: laspy.PointFormat) -> list[tuple[str, str, Callable]]:
    """(output dimension, input dimension, conversion) for every standard dimension the scan
    fills; the rest stays zero."""
    plan: list[tuple[str, str, Callable]] = []
    out_names = set(point_format.dimension_names) - {"X", "Y", "Z"}
    for d in item.summary.dimensions:
        if d.kind == "extra":
            continue
        target = d.name if d.name in out_names else _ALIASES.get(d.name)
        if target not in out_names:
            if d.kind == "las":
                log.debug("%s: dimension %s is not kept (waveform)", item.scan.path, d.name)
            continue
        limits = _int_range(point_format, target)
        if target != d.name:  # scan angle: rank in degrees <-> 0.006 degree units
            factor = 1 / _SCAN_ANGLE_UNIT if target == "scan_angle" else _SCAN_ANGLE_UNIT
            lo, hi = limits
            plan.append(
                (target, d.name, lambda v, f=factor, lo=lo, hi=hi: np.clip(np.round(v * f), lo, hi))
            )
        elif d.kind == "las":
            plan.append((target, d.name, lambda v: v))
        else:
            plan.append((target, d.name, _field_converter(target, d, item, limits)))
    return plan


class LasSink:
    """A LAS/LAZ file being written (see the module docstring); ``point_format`` is its format."""

    def __init__(
        self,
        tmp: Path,
        inputs: Sequence[ScanInput],
        bounds: tuple[np.ndarray, np.ndarray],
        anchor: ExportScan,
        target: Path,
        crs: tuple[RawVlr, ...] | None = None,
    ) -> None:
        summaries = [i.summary for i in inputs]
        self.point_format = choose_point_format(summaries)
        self.extras = extra_dimensions(summaries, self.point_format)
        self.offsets = las_offsets(*bounds, target)
        self.target = target
        if crs is None:
            crs, wkt = anchor_crs(inputs, anchor)
        else:
            wkt = any(v.record_id == 2112 for v in crs)
        gps = {i.summary.gps_standard for i in inputs if "gps_time" in i.summary.names}
        if len(gps) > 1:
            log.warning("%s: the scans mix GPS week time and standard GPS time", target)
        self.header = make_header(
            self.point_format, self.extras, self.offsets, crs, wkt, True in gps
        )
        if len(inputs) == 1:
            self.header.system_identifier = "TRANSFORMATION"
        self._fh: BinaryIO = open(tmp, "wb")  # noqa: SIM115 - closed by close() / abort()
        compress = target.suffix.lower() == ".laz"
        backend = laspy.LazBackend.detect_available() if compress else None
        self._writer = laspy.LasWriter(
            self._fh, self.header, do_compress=compress, laz_backend=backend
        )
        self._item: ScanInput | None = None
        self._plan: list[tuple[str, str, Callable]] = []

    def begin(self, item: ScanInput) -> None:
        self._item = item
        self._plan = copy_plan(item, self.header.point_format)

    def write(self, chunk: Chunk, world: np.ndarray) -> None:
        assert self._item is not None
        rec = laspy.ScaleAwarePointRecord.zeros(len(world), header=self.header)
        ints = np.round((world - self.offsets) / LAS_SCALE)
        if (np.abs(ints) > 2**31 - 1).any():
            raise InputError(
                "points lie outside the bounding box of the header", self._item.scan.path
            )
        for k, axis in enumerate("XYZ"):
            rec.array[axis] = ints[:, k].astype(np.int32)
        for target, source, convert in self._plan:
            values = convert(chunk[source])
            if target in rec.array.dtype.names:
                rec.array[target] = values
            else:  # a bit field
                rec[target] = np.asarray(values).astype(np.uint8)
        for d in self.extras[:-1]:
            if d.name in chunk:
                rec.array[d.name] = chunk[d.name]
        rec.array[SCAN_INDEX] = self._item.scan.index
        self._writer.write_points(rec)

    def end(self) -> None:
        self._item = None

    def close(self) -> None:
        self._writer.close()  # closes the file too

    def abort(self) -> None:
        try:
            self._writer.close()
        except Exception:  # the file is discarded anyway
            self._fh.close()
