"""Control places a scan: a scan with a station that no link put in the group of most
stations (:func:`home_group`) is registered from where its station says it is.

The group's own stations (two at least) give the control frame in the group's frame: a
horizontal rotation and shift fitted to their placed positions (:func:`frame_of`). The lone
scan's station is carried into the group's frame; the placed scans nearest to it are its
targets, each link registered from that guess with the heading unknown (searched all round,
:class:`~ndt_cli.ndt.register.Guess` of 180 degrees) and from the search, the better kept
(:func:`~ndt_cli.pipeline.guesses.better`). The gate judges the link as always: a station
only says where to look.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.ndt.register import Guess
from ndt_cli.pipeline.discovery import Placed
from ndt_cli.pipeline.network import LinkKind, PlannedLink

MAX_FRAME_MISFIT = 0.5  # m: stations that fit the group's placement worse say nothing here
SIGMA_M = 1.0  # m: the station's scanner found within a cell of 2 m


def home_group(
    groups: Sequence[Sequence[int]], stations: Mapping[int, object], anchor: int
) -> list[int]:
    """The placed group with the most scans that have a station (the anchor's on a tie; empty
    without one): the group the others are brought to."""
    if not groups:
        return []
    best = max(groups, key=lambda g: (sum(s in stations for s in g), anchor in g))
    return list(best)


def frame_of(
    stations: Mapping[int, np.ndarray], where: Mapping[int, Placed]
) -> tuple[np.ndarray, np.ndarray] | None:
    """(R 2x2, t) with ``R @ xy_control + t`` = xy in the group's frame, fitted to the scans
    that have both a station (``stations``: x, y, z per scan, control frame) and a place;
    None with fewer than two, or when one misfits by more than :data:`MAX_FRAME_MISFIT`."""
    both = [s for s in stations if s in where]
    if len(both) < 2:
        return None
    P = np.array([stations[s][:2] for s in both])
    Q = np.array([where[s].T_group_scan[:2, 3] for s in both])
    pc, qc = P.mean(axis=0), Q.mean(axis=0)
    a, b = P - pc, Q - qc  # the turn that best carries one onto the other (no mirror)
    turn = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b))
    R = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    t = qc - R @ pc
    misfit = np.linalg.norm(P @ R.T + t - Q, axis=1)
    return (R, t) if float(misfit.max()) <= MAX_FRAME_MISFIT else None


def station_links(
    lone: int,
    xyz: np.ndarray,
    frame: tuple[np.ndarray, np.ndarray],
    where: Mapping[int, Placed],
    members: Sequence[int],
    probes: int,
) -> list[PlannedLink]:
    """The links that register scan ``lone`` (its station at ``xyz``, control frame) to the
    ``probes`` members of the group placed nearest to where its station puts it, each with
    the guess of its ``T_target_source`` (heading unknown)."""
    R, t = frame
    xy = R @ np.asarray(xyz, float)[:2] + t
    near = sorted(members, key=lambda m: float(np.hypot(*(where[m].T_group_scan[:2, 3] - xy))))
    T_group_lone = pose2d_matrix(xy[0], xy[1], 0.0)
    out = []
    for target in near[:probes]:
        T = np.linalg.inv(where[target].T_group_scan) @ T_group_lone
        T[2, 3] = 0.0  # the heights come from the scans' ground
        out.append(PlannedLink(target, lone, LinkKind.FOUND, Guess(T, SIGMA_M, 180.0)))
    return out
