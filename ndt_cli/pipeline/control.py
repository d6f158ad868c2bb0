"""Control: known coordinates of scanner stations (GNSS on the scanner, a station set up over a
surveyed point, a total-station measurement), read from a CSV file.

One row per station, ``scan,x,y,z,sigma_xy,sigma_z``: the scan (named as the outputs name it,
or by its file name), the coordinates of its scanner's origin in the coordinate system of the
control (metres), and their standard deviations (metres; blank: :data:`DEFAULT_SIGMA_XY` and
:data:`DEFAULT_SIGMA_Z`, a GNSS RTK fix). A first row of exactly these column names is a
header; ``#`` starts a comment. Every problem (an unknown scan, a number that is not finite, a
standard deviation that is not positive, a station given twice) is an error naming the line,
found before any registration.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError, read_user_text

COLUMNS = ("scan", "x", "y", "z", "sigma_xy", "sigma_z")
DEFAULT_SIGMA_XY = 0.02  # m: a GNSS RTK fix, horizontally (1 sigma)
DEFAULT_SIGMA_Z = 0.03  # m: and in height


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


@dataclass(frozen=True)
class Station:
    """A row of a control file before its scan is known: the name it gives, its line."""

    name: str
    line: int
    xyz: np.ndarray
    sigma_xy: float
    sigma_z: float


def _row(cells: list[str], number: int) -> Station:
    """One station from its cells (ValueError with the problem)."""
    if len(cells) < 4:
        raise ValueError("expected 'scan,x,y,z' and optionally 'sigma_xy,sigma_z'")
    xyz = np.array([_number(c, w) for c, w in zip(cells[1:4], "xyz", strict=True)])
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
    return Station(cells[0], number, xyz, sig[0], sig[1])


def read_stations(path: str | Path) -> tuple[Station, ...]:
    """The rows of a control file, checked but not yet matched to scans (field mode reads the
    file before the scans land)."""
    p = Path(path)
    out: list[Station] = []
    for number, row in enumerate(csv.reader(read_user_text(p, "control").splitlines()), 1):
        cells = [c.strip() for c in row]
        if not cells or not cells[0] or cells[0].startswith("#"):
            continue
        if number == 1 and tuple(c.lower() for c in cells) == COLUMNS[: len(cells)]:
            continue  # the header
        try:
            station = _row(cells, number)
        except ValueError as exc:
            raise InputError(f"line {number}: {exc}", p) from None
        if any(s.name == station.name for s in out):
            raise InputError(f"line {number}: scan {station.name!r} is given twice", p)
        out.append(station)
    if not out:
        raise InputError("no station in the control file", p)
    return tuple(out)


def matched(
    stations: Sequence[Station], names: Sequence[str], path: Path | None = None
) -> tuple[Control, ...]:
    """The stations whose scan is one of ``names`` (the campaign's, as the outputs show them;
    a scan's file name counts too). With ``path``, a station naming no scan is an error naming
    its line; without, it waits (field mode: its scan has not landed yet)."""
    lookup = {name: k for k, name in enumerate(names)}
    lookup.update({Path(name.split("#")[0]).name: k for k, name in enumerate(names)})
    out = []
    for s in stations:
        if s.name not in lookup:
            if path is not None:
                raise InputError(f"line {s.line}: no scan named {s.name!r}", path)
            continue
        k = lookup[s.name]
        if any(c.scan == k for c in out):
            raise InputError(f"line {s.line}: scan {s.name!r} is given twice", path)
        out.append(Control(k, names[k], s.xyz, s.sigma_xy, s.sigma_z))
    return tuple(out)


def read_control(path: str | Path, names: Sequence[str]) -> tuple[Control, ...]:
    """The stations of a control file (see the module docstring) matched to the campaign's
    scans, ``names`` as the outputs show them; every station must name one."""
    return matched(read_stations(path), names, Path(path))
