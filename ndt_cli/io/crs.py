"""A coordinate reference system the user names: an EPSG code (``EPSG:25832``), any text
pyproj understands, or a file holding WKT. Kept as WKT: what LAS files and the outputs carry."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ndt_cli.errors import ConfigError, read_user_text
from ndt_cli.io.records import RawVlr

if TYPE_CHECKING:
    from pyproj import CRS


def crs_wkt(value: str) -> str:
    """The WKT (2019) of the coordinate system ``value`` names; a one-line error naming
    ``--crs`` when pyproj cannot read it."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    text = value
    if "\n" not in value and Path(value).is_file():
        text = read_user_text(value, "coordinate system", ConfigError)
    try:
        return CRS.from_user_input(text.strip()).to_wkt()
    except CRSError:
        shown = value if len(value) <= 60 else value[:57] + "..."
        raise ConfigError(f"--crs {shown!r} is not a coordinate system pyproj knows") from None


def crs_name(wkt: str) -> str:
    """A short name of a coordinate system, e.g. 'ETRS89 / UTM zone 32N (EPSG:25832)'."""
    from pyproj import CRS

    crs = CRS.from_wkt(wkt)
    epsg = crs.to_epsg()
    return f"{crs.name} (EPSG:{epsg})" if epsg else crs.name


def wkt_records(wkt: str) -> tuple[RawVlr, ...]:
    """The LAS record holding ``wkt`` (``LASF_Projection`` 2112, null-terminated), as a
    LAS 1.4 file with the WKT bit carries its coordinate system."""
    return (RawVlr("LASF_Projection", 2112, "OGC coordinate system WKT", wkt.encode() + b"\0"),)


EARTH_RADIUS_M = 6_371_000.0  # mean radius: the height reduction's, good to 1e-6 of a distance


def _horizontal(wkt: str) -> CRS:
    """The horizontal part of a coordinate system (of a compound one, its first)."""
    from pyproj import CRS

    crs = CRS.from_wkt(wkt)
    return crs.sub_crs_list[0] if crs.is_compound else crs


def check_system(wkt: str, value: str) -> None:
    """A one-line error naming ``--crs`` unless it can hold the control: a projected (or local)
    system in metres, its z the height. Not geographic (degrees), not geocentric (z the
    earth's axis, not the vertical), not heights alone, not feet."""
    horizontal = _horizontal(wkt)
    if horizontal.is_geographic:
        raise ConfigError(
            f"--crs {value!r} is geographic (degrees): give control in a projected system (m)"
        )
    if horizontal.is_geocentric:
        raise ConfigError(
            f"--crs {value!r} is geocentric (x, y, z from the earth's centre: z is not the "
            "vertical): give control in a projected system, e.g. the UTM zone's"
        )
    if horizontal.is_vertical:
        raise ConfigError(
            f"--crs {value!r} holds heights only: give the projected system of x, y, or a "
            "compound one (e.g. EPSG:25832+7837)"
        )
    units = {a.unit_name.lower() for a in horizontal.axis_info}
    if units - {"metre", "meter", "m"}:
        raise ConfigError(f"--crs {value!r} has axes in {', '.join(sorted(units))}, not metres")


AREA_MARGIN_DEG = 5.0  # how far outside its area of use a system's coordinates are accepted


@dataclass(frozen=True)
class Area:
    """Where a coordinate system is meant to be used: degrees of longitude and latitude."""

    name: str
    west: float
    south: float
    east: float
    north: float

    def holds(self, lon: float, lat: float) -> bool:
        """Whether (``lon``, ``lat``), degrees, lies within the area widened by
        :data:`AREA_MARGIN_DEG` (a zone is often used a little beyond its edge)."""
        m = AREA_MARGIN_DEG
        east = self.east if self.east >= self.west else self.east + 360.0  # across 180 deg
        lon = lon + 360.0 if lon < self.west - m else lon
        return self.west - m <= lon <= east + m and self.south - m <= lat <= self.north + m

    def __str__(self) -> str:
        d = Area.degrees
        return (
            f"{d(self.west, 'EW')}-{d(self.east, 'EW')} {d(self.south, 'NS')}-{d(self.north, 'NS')}"
        )

    @staticmethod
    def degrees(value: float, sides: str) -> str:
        """``12.01°E``: an angle (degrees) and its side, ``sides`` "EW" or "NS"."""
        return f"{abs(value):.2f}°{sides[0] if value >= 0 else sides[1]}"


def area_of_use(wkt: str) -> Area | None:
    """The area of use of the horizontal part of a coordinate system (None when it names
    none: a local system, a PROJ string)."""
    horizontal = _horizontal(wkt)
    area = horizontal.area_of_use
    if area is None or not horizontal.is_projected:
        return None
    return Area(crs_name(horizontal.to_wkt()), area.west, area.south, area.east, area.north)


def geographic(wkt: str, x: float, y: float) -> tuple[float, float]:
    """Longitude and latitude (degrees) of easting ``x`` and northing ``y`` (m) of a projected
    system; not finite where the projection cannot place them."""
    from pyproj import Transformer

    horizontal = _horizontal(wkt)
    to_geographic = Transformer.from_crs(horizontal, horizontal.geodetic_crs, always_xy=True)
    with np.errstate(all="ignore"):
        lon, lat = to_geographic.transform(float(x), float(y), errcheck=False)
    return float(lon), float(lat)


def grid_scale(wkt: str, xyz: np.ndarray) -> float:
    """Grid distance over ground distance at ``xyz`` (the system's coordinates, m): the map
    projection's point scale (UTM: 0.9996 on the central meridian, up to about 1.0004 at a
    zone's edge) times the height reduction R / (R + h). 1 for a system that is not a map
    projection (a local one is at ground scale); NaN where the projection cannot place
    ``xyz``."""
    from pyproj import Proj

    horizontal = _horizontal(wkt)
    if not horizontal.is_projected:
        return 1.0
    lon, lat = geographic(wkt, float(xyz[0]), float(xyz[1]))
    if not np.isfinite([lon, lat]).all():
        return float("nan")
    with np.errstate(all="ignore"):
        point = float(np.sqrt(Proj(horizontal).get_factors(lon, lat).areal_scale))
    return point * EARTH_RADIUS_M / (EARTH_RADIUS_M + float(xyz[2]))
