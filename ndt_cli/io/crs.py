"""A coordinate reference system the user names: an EPSG code (``EPSG:25832``), any text
pyproj understands, or a file holding WKT. Kept as WKT: what LAS files and the outputs carry."""

from __future__ import annotations

from pathlib import Path

from ndt_cli.errors import ConfigError, read_user_text
from ndt_cli.io.records import RawVlr


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
