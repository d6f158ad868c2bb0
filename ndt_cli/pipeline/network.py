"""Which scan pairs a campaign registers: the network of links, planned from where scans are.

Once scans are placed (each group of connected scans in a frame of its own), the network links
each scan to its ``neighbours`` nearest scans of its group within a radius, plus the shortest
links that keep the group connected (a minimum spanning tree over the scanner positions, pairs
known not to register left out), plus the user's pairs. The plan depends on where the scans
are, not on the order they came in: a campaign given in any order, or one scan at a time, ends
with the same links. Redundant links are what lets the adjustment check one against another.

With one neighbour the campaign is the classic chain instead: each scan against the one before
it in the order given (:func:`classic_chain`).

Scans are indices into the campaign's list here (0, 1, ... in campaign order).
"""

from __future__ import annotations

import csv
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.errors import InputError

RADIUS_FACTOR = 2.2  # default radius: this times the median distance of a scan to its nearest
Pair = tuple[int, int]  # an unordered pair of scans, lower index first


class LinkKind(StrEnum):
    """Why a pair of scans is registered."""

    ADJACENT = "adjacent"  # consecutive in the campaign's order (the walk, when there is one)
    PAST = "past"  # neighbours along the walk past one scan that tied in nothing (a room)
    FOUND = "found"  # found by where the scans are, whatever their order
    USER = "user"  # listed by the user (--pairs)

    @property
    def walked(self) -> bool:
        """Whether the pair are neighbours along the walk (adjacent, or past a scan)."""
        return self in (LinkKind.ADJACENT, LinkKind.PAST)


class Bridges(StrEnum):
    """Which links on no cycle (bridges of the network) may tie a scan in on their own
    gate's word."""

    ALL = "all"  # every one its gate passed (a walk outdoors)
    WALK = "walk"  # those between neighbours along the walk (:attr:`LinkKind.ADJACENT`)
    NONE = "none"  # none: every ok scan lies on a cycle of links that agree

    @classmethod
    def of(cls, trust_bridges: bool, trust_walk_bridges: bool, walked: bool) -> Bridges:
        """The bridges trusted by ``quality.trust_bridges`` and ``quality.trust_walk_bridges``
        in a campaign that ``walked`` (its order proved a hint); out of order, none."""
        if not walked:
            return cls.NONE
        return cls.ALL if trust_bridges else cls.WALK if trust_walk_bridges else cls.NONE


@dataclass(frozen=True)
class PlannedLink:
    """A pair to register: ``source`` onto ``target`` (scan indices), why, a guess of
    ``T_target_source`` (a :class:`~ndt_cli.ndt.register.Guess`; None: the search alone), and
    whether the search may look deeper (False: a probe of a pair that may not overlap, see
    :func:`~ndt_cli.ndt.register.register_prepared`)."""

    target: int
    source: int
    kind: LinkKind
    guess: Any = field(default=None, compare=False)
    deep: bool = field(default=True, compare=False)

    @property
    def pair(self) -> Pair:
        return pair_of(self.target, self.source)


def pair_of(a: int, b: int) -> Pair:
    return (min(a, b), max(a, b))


def kind_of(pair: Pair, user: Collection[Pair], walk: Mapping[Pair, LinkKind]) -> LinkKind:
    """How a link came to be: given by the user, between neighbours along the walk (``walk``:
    their pairs and kinds, :func:`~ndt_cli.pipeline.members.walk_pairs`), or found."""
    if pair in user:
        return LinkKind.USER
    return walk.get(pair, LinkKind.FOUND)


def classic_chain(n_scans: int, unreadable: Iterable[int] = ()) -> list[PlannedLink]:
    """Each scan against the last readable scan before it (a scan that cannot be read gets one
    failing link from the scan before it, so that the outputs say why it has no pose)."""
    bad = set(unreadable)
    links = []
    for j in range(1, n_scans):
        readable = [i for i in range(j - 1, -1, -1) if i not in bad]
        links.append(PlannedLink(readable[0] if readable else j - 1, j, LinkKind.ADJACENT))
    return links


def default_radius(
    groups: Sequence[Mapping[int, np.ndarray]], factor: float = RADIUS_FACTOR
) -> float:
    """``factor`` times the median distance (m) from a placed scan to the nearest other scan
    of its group; NaN when no group has two scans."""
    nearest = []
    for group in groups:
        xy = np.array(list(group.values())).reshape(-1, 2)
        if len(xy) > 1:
            d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
            np.fill_diagonal(d, np.inf)
            nearest.append(d.min(axis=1))
    if not nearest:
        return float("nan")
    return factor * float(np.median(np.concatenate(nearest)))


def plan_near(
    groups: Sequence[Mapping[int, np.ndarray]],
    neighbours: int,
    radius: float,
    failed: set[Pair] = frozenset(),  # type: ignore[assignment]
) -> set[Pair]:
    """The pairs to register in each group of placed scans (scan -> (x, y) m, one frame per
    group): each scan's ``neighbours`` nearest within ``radius`` m, and the minimum spanning
    tree of the group's positions over the pairs not ``failed``."""
    pairs: set[Pair] = set()
    for group in groups:
        ids = sorted(group)
        if len(ids) < 2:
            continue
        xy = np.array([group[i] for i in ids])
        d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        pairs |= _nearest(ids, d, neighbours, radius)
        pairs |= _spanning_tree(ids, d, failed)
    return pairs


def _nearest(ids: list[int], d: np.ndarray, k: int, radius: float) -> set[Pair]:
    out = set()
    for a in range(len(ids)):
        order = np.lexsort((np.arange(len(ids)), d[a]))  # ties: the lower index
        near = [b for b in order if b != a and d[a, b] <= radius][:k]
        out |= {pair_of(ids[a], ids[b]) for b in near}
    return out


def _spanning_tree(ids: list[int], d: np.ndarray, failed: set[Pair]) -> set[Pair]:
    """Prim's minimum spanning tree over the pairs not ``failed`` (a forest where those cut
    the group); ties go to the lower indices."""
    n = len(ids)
    w = d.copy()
    for a in range(n):
        for b in range(n):
            if a == b or pair_of(ids[a], ids[b]) in failed:
                w[a, b] = np.inf
    out: set[Pair] = set()
    seen = np.zeros(n, dtype=bool)
    for root in range(n):
        if seen[root]:
            continue
        seen[root] = True
        best, via = w[root].copy(), np.full(n, root)
        while True:
            best[seen] = np.inf
            nxt = int(np.argmin(best))
            if not np.isfinite(best[nxt]):
                break
            seen[nxt] = True
            out.add(pair_of(ids[via[nxt]], ids[nxt]))
            closer = w[nxt] < best
            best[closer], via[closer] = w[nxt][closer], nxt
    return out


def read_pairs(
    path: Path, names: Sequence[str], sigma: tuple[float, float] = (1.0, 5.0)
) -> list[PlannedLink]:
    """User pairs from a CSV of ``target,source`` rows (scan names as the outputs show them,
    file names, or 0-based indices; a header row, a UTF-8 byte order mark and ``#`` comments
    are allowed), one link per unordered pair (the first row wins). A row may add a guess of
    ``T_target_source``: ``x,y,z,yaw_deg`` or the name of a 4x4 file, within ``sigma`` (m,
    degrees). The file is streamed: memory grows with the distinct pairs, not with the rows."""
    lookup = {name: k for k, name in enumerate(names)}
    lookup.update({Path(name).name: k for k, name in enumerate(names)})
    links: dict[tuple[int, int], PlannedLink] = {}
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            for number, row in enumerate(csv.reader(fh), 1):
                cells = [c.strip() for c in row]
                link = _pair_row(number, cells, lookup, len(names), path, sigma)
                if link is not None:
                    links.setdefault(
                        (min(link.target, link.source), max(link.target, link.source)), link
                    )
    except FileNotFoundError:
        raise InputError("pairs file not found", path) from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        reason = getattr(exc, "strerror", None) or " ".join(str(exc).split())
        raise InputError(f"cannot read pairs ({reason})", path) from None
    return list(links.values())


def _pair_row(
    number: int,
    cells: list[str],
    lookup: dict[str, int],
    n: int,
    path: Path,
    sigma: tuple[float, float],
) -> PlannedLink | None:
    """The link of one row of a pairs file; None for an empty row, a comment or a header (a
    first row of which no cell names or looks like a scan)."""
    if not cells or not cells[0] or cells[0].startswith("#"):
        return None
    if len(cells) < 2:
        raise InputError(f"line {number}: expected 'target,source'", path)
    ends = [_scan_index(c, lookup, n) for c in cells[:2]]
    if None in ends:
        scan_like = any(
            e is not None or _looks_like_scan(c) for e, c in zip(ends, cells, strict=False)
        )
        if number == 1 and not scan_like:
            return None  # a header
        bad = cells[ends.index(None)]
        what = (
            f"no scan with index {bad} (0..{n - 1})" if _digits(bad) else f"no scan named {bad!r}"
        )
        raise InputError(f"line {number}: {what}", path)
    if ends[0] == ends[1]:
        raise InputError(f"line {number}: a scan cannot be registered onto itself", path)
    return PlannedLink(ends[0], ends[1], LinkKind.USER, _row_guess(number, cells, path, sigma))


def _row_guess(number: int, cells: list[str], path: Path, sigma: tuple[float, float]) -> Any:
    """The row's guess after its two scans (None without one)."""
    from ndt_cli.ndt.register import Guess
    from ndt_cli.pipeline.guesses import pair_pose

    try:
        T = pair_pose(cells[2:], path.parent)
    except ValueError as exc:
        raise InputError(f"line {number}: {exc}", path) from None
    return None if T is None else Guess(T, *sigma)


def _digits(cell: str) -> bool:
    """0-9 only (``str.isdigit`` is true for superscripts, which ``int`` refuses)."""
    return cell.isascii() and cell.isdigit()


def _looks_like_scan(cell: str) -> bool:
    """An index, or a name with an extension or a folder: a typo, never a header's word."""
    return _digits(cell) or any(c in cell for c in "./\\#")


def _scan_index(cell: str, lookup: dict[str, int], n: int) -> int | None:
    if cell in lookup:
        return lookup[cell]
    return int(cell) if _digits(cell) and int(cell) < n else None


def merge(links: Iterable[PlannedLink]) -> list[PlannedLink]:
    """One link per unordered pair (the first planned wins), in a stable order."""
    seen: set[Pair] = set()
    out = []
    for link in links:
        if link.pair not in seen:
            seen.add(link.pair)
            out.append(link)
    return out
