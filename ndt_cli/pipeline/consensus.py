"""Which control stations agree with the network before the adjustment weighs them: the largest
group of stations that one placement of the network fits (a turn about the vertical and a
shift), found from every pair of stations; and, when none agree, the likely cause.

The network is levelled already, so two stations give its placement: the turn that takes the
line between their scanners in the network onto the line between their coordinates. A
station agrees with a placement when its coordinates lie within three standard deviations
(its own and those of the pair, carried over the distance by the turn) plus the network's
own error (:data:`NET_XY_M` + :data:`NET_XY_PER_M` of the distance; heights likewise) of where
the placement puts its scanner. These bounds catch a wrong point number, swapped stations or a
fix metres off; what is finer is left to the adjustment's chi-square test.

The largest group wins when it is a majority of the stations; a group as large that shares
fewer than two stations with it places the network elsewhere, and which of the two is right
cannot be told (two stations against two). Three stations of which two have swapped numbers
look like two right ones and a blunder (a turn by 180 degrees about the two); with four, two
against two are refused; with five, the three right ones win.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

NET_XY_M, NET_XY_PER_M = 0.1, 0.005  # the network's own horizontal error: 10 cm + 0.5 %
NET_Z_M, NET_Z_PER_M = 0.1, 0.002  # and in height
MIN_BASE_M = 0.1  # two stations closer than this give no heading
MIN_SCALE_BASE_M = 5.0  # pairs that say how the control's distances compare with the network's
SCALE_TOLERANCE = 0.002  # a ratio of distances this close to 1 is the network's own error


@dataclass(frozen=True)
class Group:
    """The largest group of stations that agree (their indices), and a rival group as large
    that places the network elsewhere (empty: none)."""

    members: tuple[int, ...]
    rivals: tuple[int, ...] = ()


def _members(
    i: int, j: int, p: np.ndarray, q: np.ndarray, s_xy: np.ndarray, s_z: np.ndarray
) -> tuple[int, ...]:
    """The stations that agree with the placement stations ``i`` and ``j`` give (none when
    the two disagree with each other). ``p``: (n, 3) scanners in the network (m); ``q``:
    (n, 3) the stations' coordinates (m); ``s_xy``, ``s_z``: (n,) their sigmas (m)."""
    a, b = p[j, :2] - p[i, :2], q[j, :2] - q[i, :2]
    base = float(np.linalg.norm(a))
    pair_xy = 3.0 * np.hypot(s_xy[i], s_xy[j])
    if base < MIN_BASE_M or abs(base - np.linalg.norm(b)) > pair_xy + _net_xy(base):
        return ()
    dz = q[[i, j], 2] - p[[i, j], 2]
    if abs(dz[0] - dz[1]) > 3.0 * np.hypot(s_z[i], s_z[j]) + NET_Z_M + NET_Z_PER_M * base:
        return ()
    yaw = np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)
    R = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    pm, qm = (p[i, :2] + p[j, :2]) / 2, (q[i, :2] + q[j, :2]) / 2
    reach = np.linalg.norm(p[:, :2] - pm, axis=1)
    off_xy = np.linalg.norm(q[:, :2] - (qm + (p[:, :2] - pm) @ R.T), axis=1)
    off_z = np.abs(q[:, 2] - p[:, 2] - dz.mean())
    tol_xy = 3.0 * s_xy + pair_xy * (0.5 + reach / base) + _net_xy(reach)
    tol_z = 3.0 * s_z + 3.0 * max(s_z[i], s_z[j]) + NET_Z_M + NET_Z_PER_M * reach
    agree = (off_xy <= tol_xy) & (off_z <= tol_z)
    agree[[i, j]] = True
    return tuple(int(k) for k in np.flatnonzero(agree))


def _net_xy(distance: float | np.ndarray) -> float | np.ndarray:
    return NET_XY_M + NET_XY_PER_M * distance


def largest_group(p: np.ndarray, q: np.ndarray, s_xy: np.ndarray, s_z: np.ndarray) -> Group:
    """The largest group of stations that agree with one placement of the network (see the
    module docstring; arguments as :func:`_members`); no members when no two agree."""
    n = len(p)
    groups: list[tuple[int, ...]] = []
    majority: set[int] = set()
    for i, j in combinations(range(n), 2):
        if i in majority and j in majority:
            continue  # a pair of a majority group gives that group again
        found = _members(i, j, p, q, s_xy, s_z)
        if found and found not in groups:
            groups.append(found)
            if 2 * len(found) > n:
                majority |= set(found)
    if not groups:
        return Group(())
    best = max(groups, key=len)
    rivals = [g for g in groups if len(g) == len(best) and len(set(g) & set(best)) < 2]
    return Group(best, rivals[0] if rivals else ())


def likely_cause(
    p: np.ndarray, q: np.ndarray, s_xy: np.ndarray, s_z: np.ndarray, agree: int
) -> str:
    """Why the stations do not place the network, when the geometry tells (arguments as
    :func:`_members`; ``agree``: how many of them agree as they are): more of them fit it
    mirrored (x and y swapped), or with their distances a constant factor off the network's
    (feet, or a map projection's grid without its scale); else ''."""
    better = max(3, agree + 1)
    if len(p) < better:
        return ""
    mirrored = len(largest_group(p, q * [-1.0, 1.0, 1.0], s_xy, s_z).members)
    if mirrored >= better:
        return f"{mirrored} fit it mirrored: are x and y (easting, northing) swapped?"
    ratios = [
        np.linalg.norm(q[j, :2] - q[i, :2]) / d
        for i, j in combinations(range(len(p)), 2)
        if (d := np.linalg.norm(p[j, :2] - p[i, :2])) > MIN_SCALE_BASE_M
    ]
    r = float(np.median(ratios)) if ratios else 1.0
    if not 1e-3 < r < 1e3 or abs(r - 1.0) <= SCALE_TOLERANCE:
        return ""
    centre = q.mean(axis=0)
    scaled = len(largest_group(p, centre + (q - centre) / r, s_xy, s_z).members)
    if scaled >= better:
        return (
            f"{scaled} fit it with distances {r:.4f} times the network's: coordinates in feet "
            "(0.3048 m), or on a map projection's grid without --crs?"
        )
    return ""
