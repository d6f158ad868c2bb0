"""Where the placed scans of a campaign are, from their links: groups, joins and placing again.

Placed scans belong to groups (scans that ok links connect), each with a frame of its own;
``where[scan]`` is a :class:`~ndt_cli.pipeline.discovery.Placed` (its group and
``T_group_scan``, 4x4, m). Links are keyed by their pair of campaign indices. Every function
here is plain: it reads the links and reads or updates ``where``, and registers nothing (the
campaign, :mod:`ndt_cli.pipeline.campaign`, decides what to register).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.linalg import inv

from ndt_cli.ndt.overlap import COARSE_WINDOW
from ndt_cli.pipeline.discovery import Placed, agree
from ndt_cli.pipeline.link_use import usable
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.network import Pair, default_radius, pair_of

BRIDGE_MEMBERS = 8  # scans of a group whose coarse matches with other groups are ranked

Where = dict[int, Placed]
Links = Mapping[Pair, Link]


def T_other_scan(link: Link, other: int) -> np.ndarray:
    """``T_other_scan`` of a link between ``other`` and a scan (4x4, scan frames)."""
    return link.T_target_source if link.target == other else inv(link.T_target_source)


def groups(where: Where) -> list[list[int]]:
    """The placed scans by group, the largest first (ties: the lowest scan)."""
    by_group: dict[int, list[int]] = {}
    for s, p in sorted(where.items()):
        by_group.setdefault(p.group, []).append(s)
    return sorted(by_group.values(), key=lambda g: (-len(g), g[0]))


def placed_groups(where: Where) -> list[dict[int, np.ndarray]]:
    """Where the scans were placed, (x, y) m per scan, one dict per group of several scans."""
    by_group: dict[int, dict[int, np.ndarray]] = {}
    for s, p in sorted(where.items()):
        by_group.setdefault(p.group, {})[s] = p.T_group_scan[:2, 3]
    return [g for g in by_group.values() if len(g) > 1]


def alone(scan: int, where: Where) -> bool:
    """Whether ``scan`` is placed in no group with another scan (or not placed)."""
    group = where[scan].group if scan in where else None
    return group is None or all(p.group != group for s, p in where.items() if s != scan)


def placing_radius(where: Where, radius: float | None) -> float:
    """The radius while placing (m): the option ``radius``, or the default of the scans placed
    so far (the coarse match's window while there are too few)."""
    if radius is not None:
        return radius
    by_group: dict[int, dict[int, np.ndarray]] = {}
    for s, p in where.items():
        by_group.setdefault(p.group, {})[s] = p.T_group_scan[:2, 3]
    default = default_radius(list(by_group.values()))
    return default if np.isfinite(default) else COARSE_WINDOW


def edge(group: list[int], links: Links) -> list[int]:
    """The :data:`BRIDGE_MEMBERS` scans of a group most likely at its edge, where another
    group may continue it: those with the fewest ok links within it (the ends of a street),
    ties by campaign order; so that bridging costs coarse matches in proportion to the
    campaign, not to the product of two groups' sizes."""
    if len(group) <= BRIDGE_MEMBERS:
        return group
    mine = set(group)
    degree = dict.fromkeys(group, 0)
    for (a, b), link in links.items():
        if link.ok and a in mine and b in mine:
            degree[a] += 1
            degree[b] += 1
    return sorted(group, key=lambda s: (degree[s], s))[:BRIDGE_MEMBERS]


def merge(where: Where, old: int, new: int, T_new_old: np.ndarray) -> None:
    """Move every scan of group ``old`` into group ``new`` (``T_new_old``: 4x4, m)."""
    for s, p in list(where.items()):
        if p.group == old:
            where[s] = Placed(new, T_new_old @ p.T_group_scan)


def settle(scan: int, links: Links, where: Where) -> bool:
    """Place the scan by its ok links to placed scans (:func:`_fit`); the groups its other
    ok links reach join that one. False when it has no ok link to a placed scan."""
    mine = [(o, k) for o in where if (k := links.get(pair_of(scan, o)))]
    fit = _fit(scan, [(o, k) for o, k in mine if k.ok], where)
    if fit is None:
        return False
    _, other, T = fit
    group = where[other].group
    where[scan] = Placed(group, T)
    for o, link in mine:
        if link.ok and where[o].group != group:
            T_new_old = T @ inv(where[o].T_group_scan @ T_other_scan(link, o))
            merge(where, where[o].group, group, T_new_old)
    return True


def join(pair: Pair, links: Links, where: Where) -> bool:
    """Join the groups of a link's scans (the smaller into the larger) when it fits: an
    ok link, or one that another link between the two groups agrees with."""
    link = links.get(pair)
    a, b = pair
    if link is None or not usable(link):
        return False
    if where[a].group == where[b].group:
        return False
    big, small = (a, b) if _size(a, where) >= _size(b, where) else (b, a)
    g_big, g_small = where[big].group, where[small].group
    implied = []  # where each link between the two groups puts the small group's frame
    for p, k in links.items():
        ends = {where[e].group if e in where else None for e in p}
        if ends == {g_big, g_small} and usable(k):
            x, y = p if where[p[0]].group == g_big else p[::-1]
            T = where[x].T_group_scan @ T_other_scan(k, x) @ inv(where[y].T_group_scan)
            implied.append((k, x, T))
    fit = _best_fit(implied, lambda o: g_big)
    if fit is None:
        return False
    merge(where, g_small, g_big, fit[1])
    return True


def _size(scan: int, where: Where) -> int:
    return sum(p.group == where[scan].group for p in where.values())


def _best_fit(
    implied: list[tuple[Link, int, np.ndarray]], group_of: Callable[[int], int]
) -> tuple[int, np.ndarray] | None:
    """The pose that links put a scan at, ``(other, T)``: among the poses ``T`` that each
    link (with the placed scan ``other``) implies, the one the most links agree with, ok
    links first, then by score per point; it must have an ok link or two that agree (a scan
    shifted along a street may fit one scan well enough to pass, rarely several). None when
    no pose has that."""
    best, best_key = None, None
    for link, other, T in implied:
        mates = [k for k, o, U in implied if group_of(o) == group_of(other) and agree(U, T)]
        ok = sum(k.ok for k in mates)
        if not ok and len(mates) < 2:
            continue
        key = (-ok, -len(mates), -link.result.score_per_point, other)
        if best_key is None or key < best_key:
            best, best_key = (other, T), key
    return best


def replace_all(scans: Sequence[int], links: Links) -> Where:
    """Every scan placed again from scratch by the links: from the lowest scan, the unplaced
    scan whose links to placed scans agree best (:func:`_fit_key`) is placed next, until
    none fits; then a new group from the lowest scan left. The result depends on the links,
    not on the order the scans came in (a scan that one wrong link would put elsewhere is
    placed where two right ones agree)."""
    by_scan: dict[int, list[tuple[int, Link]]] = {s: [] for s in scans}
    for (a, b), link in links.items():
        if usable(link) and a in by_scan and b in by_scan:
            by_scan[a].append((b, link))
            by_scan[b].append((a, link))
    where: Where = {}
    left = set(scans)
    while left:
        seed = min(left)
        where[seed] = Placed(seed, np.eye(4))
        left.discard(seed)
        while True:
            fits = [(f, u) for u in sorted(left) if (f := _fit(u, by_scan[u], where, ok=True))]
            fits = fits or [(f, u) for u in sorted(left) if (f := _fit(u, by_scan[u], where))]
            if not fits:
                break
            (_, other, T), u = min(fits, key=lambda f: (f[0][0], f[1]))
            where[u] = Placed(where[other].group, T)
            left.discard(u)
    return where


def _fit(
    scan: int, mine: list[tuple[int, Link]], where: Where, ok: bool = False
) -> tuple[tuple, int, np.ndarray] | None:
    """The best pose the scan's links to placed scans imply (``ok``: its ok links only):
    (its key, the other scan, T)."""
    implied = [
        (k, o, where[o].T_group_scan @ T_other_scan(k, o))
        for o, k in mine
        if o in where and k.ok >= ok
    ]
    best = None
    for link, other, T in implied:
        key = _fit_key(link, other, T, implied, where)
        if key is not None and (best is None or key < best[0]):
            best = (key, other, T)
    return best


def _fit_key(link: Link, other: int, T: np.ndarray, implied: list, where: Where) -> tuple | None:
    """How well links agree on pose ``T``: the most agreeing ok links, then links, then the
    score per point; None unless an ok link or two links agree on it."""
    g = where[other].group
    mates = [k for k, o, U in implied if where[o].group == g and agree(U, T)]
    ok = sum(k.ok for k in mates)
    if not ok and len(mates) < 2:
        return None
    return (-ok, -len(mates), -link.result.score_per_point, other)
