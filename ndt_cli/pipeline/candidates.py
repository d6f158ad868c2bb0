"""Which scans may overlap a scan, ranked without matching the pair: the shapes their
landmarks make (:mod:`ndt_cli.ndt.landmarks`).

A scan placed out of order was matched coarsely with every other scan, quadratic in the scans.
:class:`LandmarkIndex` ranks the others by the triangles of landmarks they share with it (a
side may differ by one :data:`~ndt_cli.ndt.landmarks.KEY_STEP`), so that only the best few
are matched. It is a ranking for the cost's sake: the coarse matches, the registrations and
the network decide. A scan its first candidates do not place is matched with the next ones
by rank (:data:`WIDER`), and one the index finds nothing for with every scan.
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

CANDIDATES = 16  # scans per scan matched coarsely (out of order, without a position)
# the next tiers by rank, for a scan its first candidates leave alone: on a long uniform street
# a neighbour may rank below the first 16, and every scan cost a thousand coarse matches
WIDER = (4 * CANDIDATES, 16 * CANDIDATES)
MIN_KEYS = 20  # triangles a scan needs for its ranking to mean anything
_NEAR = np.array(list(itertools.product((-1, 0, 1), repeat=3)), dtype=np.int64)


def _packed(keys: np.ndarray) -> np.ndarray:
    """One int64 per key (3 sides, each below 2**20 steps)."""
    k = keys + 1  # a side of step 0 is looked up at -1 too
    return (k[:, 0] << 42) | (k[:, 1] << 21) | k[:, 2]


class LandmarkIndex:
    """Each scan's triangle keys ((m, 3) int64, :func:`~ndt_cli.ndt.landmarks.triangle_keys`)
    and, per key and its 26 neighbours (one step off on any side), the scans holding it."""

    def __init__(self, keys: Mapping[int, np.ndarray] | None = None) -> None:
        self.keys: dict[int, np.ndarray] = {}
        self.holders: dict[int, set[int]] = defaultdict(set)
        self.update(keys or {})

    def update(self, keys: Mapping[int, np.ndarray]) -> None:
        """:meth:`add` each scan of ``keys``."""
        for scan, k in keys.items():
            self.add(scan, k)

    def add(self, scan: int, keys: np.ndarray) -> None:
        """Index ``scan`` by its triangle ``keys`` ((m, 3) int64); a scan already in: kept."""
        if scan in self.keys:
            return
        k = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
        self.keys[scan] = np.unique(_packed(k))
        for key in np.unique(_packed((k[:, None, :] + _NEAR[None]).reshape(-1, 3))).tolist():
            self.holders[key].add(scan)

    def knows(self, scan: int) -> bool:
        """Whether ``scan`` has enough triangles (:data:`MIN_KEYS`) to be ranked by them."""
        return len(self.keys.get(scan, ())) >= MIN_KEYS

    def ranked(self, scan: int, others: Iterable[int], k: int = CANDIDATES) -> list[int]:
        """The ``k`` of ``others`` sharing most triangles with ``scan``, per the geometric
        mean of the two scans' counts (a scan full of landmarks shares some with any);
        ties: the lowest index. Only those sharing one or more."""
        shared: dict[int, int] = defaultdict(int)
        for key in self.keys.get(scan, np.zeros(0, np.int64)).tolist():
            for other in self.holders.get(key, ()):
                shared[other] += 1
        mine = len(self.keys.get(scan, ())) + 1
        score = {
            o: shared[o] / np.sqrt(mine * (len(self.keys.get(o, ())) + 1))
            for o in others
            if o != scan and shared.get(o)
        }
        return sorted(score, key=lambda o: (-score[o], o))[:k]


def shortlists(
    index: LandmarkIndex, scans: Iterable[int], every: Sequence[int], k: int = CANDIDATES
) -> dict[int, list[int]]:
    """Per scan of ``scans``, the scans of ``every`` to match it with coarsely: its ``k``
    best by the index when the index knows it (:meth:`LandmarkIndex.knows`), all of them
    otherwise."""
    out = {}
    for scan in scans:
        others = [o for o in every if o != scan]
        out[scan] = index.ranked(scan, others, k) if index.knows(scan) else others
    return out


def next_tier(
    index: LandmarkIndex,
    scans: Iterable[int],
    every: Sequence[int],
    tried: Mapping[int, Iterable[int]],
) -> dict[int, list[int]]:
    """Per scan of ``scans``, the scans of ``every`` to match it with next, leaving out those
    it was ``tried`` with: the first tier by rank (:data:`CANDIDATES`, then :data:`WIDER`)
    that holds one not tried, else every scan not tried; a scan with none left: not listed.
    A scan the index does not know (:meth:`LandmarkIndex.knows`): every scan at once."""
    out = {}
    for scan in scans:
        done = set(tried.get(scan, ()))
        others = [o for o in every if o != scan and o not in done]
        for k in (CANDIDATES, *WIDER) if index.knows(scan) else ():
            ranked = [o for o in index.ranked(scan, every, k) if o not in done]
            if ranked:
                others = ranked
                break
        if others:
            out[scan] = others
    return out
