"""What a point file holds besides its coordinates, as every format's reader describes it: the
per-point attributes (:class:`Dimension`), a header's summary (:class:`Summary`), a LAS file's
variable-length records (:class:`RawVlr`) and a chunk of records (:data:`Chunk`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError

CHUNK_POINTS = 1_000_000
"""Default points per chunk (about 100 MB of records and coordinates for LAS format 7)."""

CRS_USER_ID = "LASF_Projection"
CRS_RECORD_IDS = (2111, 2112, 34735, 34736, 34737)
"""VLR record ids of the coordinate system: WKT math transform and coordinate system, GeoTIFF
key directory, double and ASCII parameters."""

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


def is_crs(vlr: RawVlr) -> bool:
    """True for the coordinate-system records (user id ``LASF_Projection``)."""
    return vlr.user_id == CRS_USER_ID and vlr.record_id in CRS_RECORD_IDS


def require_xyz(names: tuple[str, ...] | list[str], path: Path) -> None:
    """Raise unless the record field ``names`` include x, y and z."""
    if not {"x", "y", "z"} <= set(names):
        raise InputError(f"no x, y, z fields (found: {', '.join(names) or 'none'})", path)
