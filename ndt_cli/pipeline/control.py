"""Control: known coordinates of scanner stations (GNSS on the scanner, a station set up over a
surveyed point, a total-station measurement), read from a CSV file.

One row per station, ``scan,x,y,z,sigma_xy,sigma_z``: the scan (named as the outputs name it,
or by its file name), the coordinates of its scanner's origin in the coordinate system of the
control (metres: easting, northing, height), and their standard deviations (metres; blank:
:data:`DEFAULT_SIGMA_XY` and :data:`DEFAULT_SIGMA_Z`, a GNSS RTK fix). A first row of column
names (``scan,x,y,z`` and optionally ``sigma_xy,sigma_z``) is a header, and every row then has
as many fields; ``#`` starts a comment; a UTF-8 byte-order mark (Excel's "CSV UTF-8") is
skipped. Every problem (an unknown or ambiguous scan, a row of the wrong length, a number that
is not finite, a coordinate no place on the earth has, a standard deviation out of range, a
station given twice, coordinates outside the area of their coordinate system) is an error
naming the line, found before any scan is read.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np

from ndt_cli.errors import ConfigError, InputError, read_user_text
from ndt_cli.io.crs import Area, area_of_use, check_system, crs_name, geographic, grid_scale

COLUMNS = ("scan", "x", "y", "z", "sigma_xy", "sigma_z")
DEFAULT_SIGMA_XY = 0.02  # m: a GNSS RTK fix, horizontally (1 sigma)
DEFAULT_SIGMA_Z = 0.03  # m: and in height
SIGMA_RANGE_M = (1e-4, 1e3)  # a standard deviation a station can have: 0.1 mm to 1 km
MAX_COORDINATE_M = 1e8  # easting or northing (zone-prefixed eastings reach 6.1e7)
MAX_HEIGHT_M = 1e4  # no ground lies 10 km above or below the sea
MAX_GRID_DISTORTION = 0.01  # a surveying projection keeps distances within 1 %


@dataclass(frozen=True)
class Control:
    """A station's known position: scan ``scan`` (its index in the campaign, its ``name``),
    the coordinates of its scanner's origin (m, the control's coordinate system) and their
    standard deviations (m)."""

    scan: int
    name: str
    xyz: np.ndarray
    sigma_xy: float = DEFAULT_SIGMA_XY
    sigma_z: float = DEFAULT_SIGMA_Z

    @property
    def sigmas(self) -> np.ndarray:
        """(3,) standard deviations of x, y, z (m)."""
        return np.array([self.sigma_xy, self.sigma_xy, self.sigma_z])


@dataclass(frozen=True)
class Station:
    """A row of a control file before its scan is known: the name it gives, its line."""

    name: str
    line: int
    xyz: np.ndarray
    sigma_xy: float
    sigma_z: float


def _number(cell: str, what: str, default: float | None = None) -> float:
    if cell == "" and default is not None:
        return default
    try:
        value = float(cell)
    except ValueError:
        raise ValueError(f"{what} {cell!r} is not a number") from None
    if not np.isfinite(value):
        raise ValueError(f"{what} is not finite ({cell})")
    return value


def _coordinates(cells: list[str]) -> np.ndarray:
    """x, y, z of a row, each a coordinate some place on the earth can have."""
    xyz = np.array([_number(c, w) for c, w in zip(cells[1:4], "xyz", strict=True)])
    for value, what in zip(xyz[:2], "xy", strict=True):
        if abs(value) > MAX_COORDINATE_M:
            raise ValueError(f"column {what}: {value:g} m is no coordinate on the earth")
    if abs(xyz[2]) > MAX_HEIGHT_M:
        raise ValueError(
            f"column z: {xyz[2]:,.3f} m is no height (no ground is {MAX_HEIGHT_M / 1000:g} km "
            "above or below the sea): are the columns scan,x,y,z (easting, northing, height)?"
        )
    return xyz


def _row(cells: list[str], number: int) -> Station:
    """One station from its cells (ValueError with the problem)."""
    if not cells[0]:
        raise ValueError("no scan named (the first field is empty)")
    xyz = _coordinates(cells)
    sig = [
        _number(c, w, d)
        for c, w, d in zip(
            [*cells, "", ""][4:6],
            ("sigma_xy", "sigma_z"),
            (DEFAULT_SIGMA_XY, DEFAULT_SIGMA_Z),
            strict=True,
        )
    ]
    if min(sig) <= 0:
        raise ValueError("standard deviations must be positive")
    low, high = SIGMA_RANGE_M
    for value, what in zip(sig, ("sigma_xy", "sigma_z"), strict=True):
        if not low <= value <= high:
            raise ValueError(f"{what} {value:g} m is out of range ({low:g} to {high:g} m)")
    return Station(cells[0], number, xyz, sig[0], sig[1])


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _header(cells: list[str]) -> tuple[str, ...] | None:
    """The column names of a header row (a ValueError unless they are the columns, in order);
    None when the row holds a station (a coordinate of it is a number)."""
    if len(cells) < 4 or any(_is_number(c) for c in cells[1:4]):
        return None
    names = tuple(c.lower() for c in cells)
    if names not in (COLUMNS[:4], COLUMNS[:5], COLUMNS):
        raise ValueError(f"a header must read {','.join(COLUMNS)} (or its first four names)")
    return names


def _length(cells: list[str], header: tuple[str, ...] | None) -> None:
    """A ValueError unless the row has as many fields as the header (without one: 4 to 6),
    with the likely cause: decimal commas, semicolons."""
    for sep, what in ((";", "semicolons"), ("\t", "tabs")):
        first = cells[0].split(sep)
        if len(first) > 1 and _is_number(first[1].replace(",", ".")):
            raise ValueError(f"fields separated by {what}: separate them with commas")
    if tuple(c.lower() for c in cells[:4]) == COLUMNS[:4]:
        raise ValueError("a header again (two files joined?): a header is the first row only")
    allowed = (len(header),) if header else (4, 5, 6)
    if len(cells) in allowed:
        return
    expected = (
        f" where the header has {len(header)}"
        if header
        else "; expected 'scan,x,y,z' and optionally 'sigma_xy,sigma_z'"
    )
    hint = ""
    if len(cells) > allowed[-1]:
        pairs = pairwise(cells[1:])
        comma = next(
            (f"{a}.{b}" for a, b in pairs if re.fullmatch(r"[-+]?\d+", a) and b.isdigit()), None
        )
        hint = f" (a decimal comma? write {comma})" if comma else ""
    fields = "1 field" if len(cells) == 1 else f"{len(cells)} fields"
    raise ValueError(f"{fields}{expected}{hint}")


def read_stations(path: str | Path) -> tuple[Station, ...]:
    """The rows of a control file, checked but not yet matched to scans (field mode reads the
    file before the scans land)."""
    p = Path(path)
    text = read_user_text(p, "control").removeprefix("\ufeff")
    out: list[Station] = []
    seen: set[str] = set()
    header: tuple[str, ...] | None = None
    for number, raw in enumerate(text.splitlines(), 1):
        cells = [c.strip() for c in next(csv.reader([raw]), [])]
        if not any(cells) or cells[0].startswith("#"):
            continue
        try:
            if not out and header is None and (header := _header(cells)) is not None:
                continue
            _length(cells, header)
            station = _row(cells, number)
        except ValueError as exc:
            raise InputError(f"line {number}: {exc}", p) from None
        if station.name in seen:
            raise InputError(f"line {number}: scan {station.name!r} is given twice", p)
        seen.add(station.name)
        out.append(station)
    if not out:
        raise InputError("no station in the control file", p)
    return tuple(out)


Lookup = tuple[dict[str, int], dict[str, list[int]]]


def _lookup(names: Sequence[str]) -> Lookup:
    """The scans by the names the outputs give them, and by their files' names."""
    by_file: dict[str, list[int]] = {}
    for k, n in enumerate(names):
        by_file.setdefault(Path(n.split("#")[0]).name, []).append(k)
    return {n: k for k, n in enumerate(names)}, by_file


def _scan_of(name: str, names: Sequence[str], lookup: Lookup) -> int | str:
    """The index of the scan a station names (as the outputs name it, or by its file's name),
    or why none: no scan has that name, or several have (a file of several scans, files of one
    name in several folders)."""
    exact, by_file = lookup
    if name in exact:
        return exact[name]
    hits = by_file.get(name, [])
    if len(hits) == 1:
        return hits[0]
    if not hits:
        return f"no scan named {name!r}"
    if all("#" in names[k] for k in hits) and len({names[k].split("#")[0] for k in hits}) == 1:
        return f"{name!r} holds {len(hits)} scans: name one as {names[hits[0]]}"
    shown = ", ".join(names[k] for k in hits[:3]) + (", ..." if len(hits) > 3 else "")
    return f"{name!r} names {len(hits)} scans ({shown}): name one as the outputs do"


def matched(
    stations: Sequence[Station], names: Sequence[str], path: Path | None = None
) -> tuple[Control, ...]:
    """The stations whose scan is one of ``names`` (the campaign's, as the outputs show them;
    a scan's file name counts too when no other scan has it). With ``path``, a station naming
    no scan, or several, is an error naming its line; without, it waits (field mode: its scan
    has not landed yet; :func:`unmatched` says why)."""
    out: dict[int, Control] = {}
    lookup = _lookup(names)
    for s in stations:
        k = _scan_of(s.name, names, lookup)
        if isinstance(k, str):
            if path is not None:
                raise InputError(f"line {s.line}: {k}", path)
            continue
        if k in out:
            raise InputError(f"line {s.line}: scan {s.name!r} is given twice", path)
        out[k] = Control(k, names[k], s.xyz, s.sigma_xy, s.sigma_z)
    return tuple(out.values())


def unmatched(stations: Sequence[Station], names: Sequence[str]) -> tuple[tuple[Station, str], ...]:
    """The stations naming no scan of ``names`` (or several), each with why."""
    lookup = _lookup(names)
    found = ((s, _scan_of(s.name, names, lookup)) for s in stations)
    return tuple((s, k) for s, k in found if isinstance(k, str))


def read_control(path: str | Path, names: Sequence[str]) -> tuple[Control, ...]:
    """The stations of a control file (see the module docstring) matched to the campaign's
    scans, ``names`` as the outputs show them; every station must name one."""
    return matched(read_stations(path), names, Path(path))


def _outside(s: Station, wkt: str, area: Area) -> str:
    """Why station ``s`` lies outside the ``area`` of use of ``wkt`` ('' when it does not):
    with x and y swapped, or without a zone number before its easting, it would lie inside."""
    x, y = float(s.xyz[0]), float(s.xyz[1])
    lon, lat = geographic(wkt, x, y)
    if area.holds(lon, lat):
        return ""
    where = f"line {s.line}: x, y ({x:.3f}, {y:.3f}) lie outside the area of {area.name}"
    if area.holds(*geographic(wkt, y, x)):
        return (
            f"{where}, and inside it with columns x and y swapped: give the easting first, "
            "then the northing"
        )
    if x > 1e6 and area.holds(*geographic(wkt, x % 1e6, y)):
        return (
            f"{where}, and inside it as {x % 1e6:.3f}: the easting carries a zone number "
            f"({x // 1e6:.0f})? give it without"
        )
    if abs(x) <= 180 and abs(y) <= 90:
        return f"{where}: degrees of longitude and latitude? give the system's eastings, northings"
    d = Area.degrees
    at = f"at {d(lon, 'EW')} {d(lat, 'NS')}, " if np.isfinite([lon, lat]).all() else ""
    return f"{where}: {at}not in {area}; coordinates of another system?"


def check_in_system(stations: Sequence[Station], wkt: str, value: str, path: Path) -> float:
    """The stations checked against their coordinate system ``wkt`` (``--crs`` ``value``; the
    control file ``path``): the system holds control (:func:`~ndt_cli.io.crs.check_system`),
    every station lies in its area of use (or an error naming the line, and the columns when
    x and y swapped would put it there), and its grid scale keeps distances within 1 %.
    Returns the grid scale at the stations' mean (grid distance over ground distance)."""
    check_system(wkt, value)
    area = area_of_use(wkt)
    for s in stations if area is not None else ():
        if problem := _outside(s, wkt, area):
            raise InputError(problem, path)
    scale = grid_scale(wkt, np.mean([s.xyz for s in stations], axis=0))
    if not abs(scale - 1.0) <= MAX_GRID_DISTORTION:
        raise ConfigError(
            f"--crs {value!r}: its grid scale at the stations is {scale:.4g}, distances "
            f"distorted by more than {MAX_GRID_DISTORTION:.0%}: give control in a surveying "
            f"projection ({crs_name(wkt)} is not one here)"
        )
    return scale
