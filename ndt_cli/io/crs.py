"""A coordinate reference system the user names: an EPSG code (``EPSG:25832``), any text
pyproj understands, or a file holding WKT. Kept as WKT: what LAS files and the outputs carry."""

from __future__ import annotations

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


def check_metres(wkt: str, value: str) -> None:
    """A one-line error naming ``--crs`` unless its coordinates are metres (the control's and
    the network's unit): not degrees, not feet."""
    horizontal = _horizontal(wkt)
    if horizontal.is_geographic:
        raise ConfigError(
            f"--crs {value!r} is geographic (degrees): give control in a projected system (m)"
        )
    units = {a.unit_name.lower() for a in horizontal.axis_info}
    if units - {"metre", "meter", "m"}:
        raise ConfigError(f"--crs {value!r} has axes in {', '.join(sorted(units))}, not metres")


def grid_scale(wkt: str, xyz: np.ndarray) -> float:
    """Grid distance over ground distance at ``xyz`` (the system's coordinates, m): the map
    projection's point scale (UTM: 0.9996 on the central meridian, up to about 1.0004 at a
    zone's edge) times the height reduction R / (R + h). 1 for a system that is not a map
    projection (a local one is at ground scale)."""
    from pyproj import Proj, Transformer

    horizontal = _horizontal(wkt)
    if not horizontal.is_projected:
        return 1.0
    to_geographic = Transformer.from_crs(horizontal, horizontal.geodetic_crs, always_xy=True)
    lon, lat = to_geographic.transform(float(xyz[0]), float(xyz[1]))
    point = float(np.sqrt(Proj(horizontal).get_factors(lon, lat).areal_scale))
    return point * EARTH_RADIUS_M / (EARTH_RADIUS_M + float(xyz[2]))
