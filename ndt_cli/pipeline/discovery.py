"""Where a new scan is: predictions from coarse matches with placed scans, and the consensus.

Placed scans belong to groups (scans that ok links connect), each with a frame of its own;
``T_group_scan`` places a scan in its group's frame. A coarse match of a new scan with a
placed scan (:func:`ndt_cli.ndt.overlap.coarse_match`) predicts where the new scan is in that
placed scan's group. The best-scoring match is most often with a scan that truly overlaps
the new one; matches with others land anywhere (a street shifted along itself fits its
facades too). The new scan is registered fully to the scans of the best prediction and those
that agree with it (:func:`consensus`), or to the placed scans nearest to it
(:func:`nearest`).

The campaign's order is a hint: the scans next to the new one in that order (:data:`HINTS`)
are matched first; only when registering those gives no ok link is every placed scan
matched. Known positions (control stations, down to a scanner's own GNSS of metres) name
candidates too (:func:`near_by_position`): whatever the coarse match says, scans near each
other by position are registered.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ndt_cli.core.transforms import yaw_of
from ndt_cli.ndt.overlap import CoarseMatch

HINTS = (-1, -2, 1, 2)  # places in campaign order matched first
HINT_TRIALS = 6  # scans with an order hint placed before the order is judged
AGREE_M = 3.0  # m: two predictions of a scan's position this close agree ...
AGREE_DEG = 6.0  # ... if their headings are this close too
Match = Callable[[int, int], CoarseMatch]  # (placed, new) -> T_placed_new and its score


@dataclass(frozen=True)
class Placed:
    """A placed scan: its group and ``T_group_scan`` (4x4, m)."""

    group: int
    T_group_scan: np.ndarray


@dataclass(frozen=True)
class Prediction:
    """Where a coarse match with the placed scan ``via`` puts a new scan in ``group``."""

    via: int
    group: int
    T_group_scan: np.ndarray
    score: float


def agree(A: np.ndarray, B: np.ndarray, metres: float = AGREE_M, deg: float = AGREE_DEG) -> bool:
    """Two poses (4x4) within ``metres`` in position (x, y) and ``deg`` in heading."""
    turn = np.degrees(abs(np.angle(np.exp(1j * (yaw_of(A) - yaw_of(B))))))
    return bool(np.hypot(*(A[:2, 3] - B[:2, 3])) <= metres and turn <= deg)


def predict(
    scan: int, candidates: Iterable[int], where: Mapping[int, Placed], match: Match
) -> list[Prediction]:
    """The prediction of each placed candidate's coarse match with ``scan``."""
    out = []
    for c in candidates:
        if c == scan or c not in where:
            continue
        m = match(c, scan)
        if m.score > 0:
            T = where[c].T_group_scan @ m.T_target_source
            out.append(Prediction(c, where[c].group, T, m.score))
    return out


def order_is_a_hint(outcomes: Sequence[bool]) -> bool:
    """Whether the campaign order is still worth following, from whether it placed each scan
    that had a hint so far: yes for the first :data:`HINT_TRIALS`, then while it placed at
    least half of them. In a walk it places nearly every scan; in a shuffled order a scan's
    neighbours in the order are rarely its neighbours on the street."""
    return len(outcomes) < HINT_TRIALS or 2 * sum(outcomes) >= len(outcomes)


def consensus(predictions: list[Prediction]) -> list[Prediction]:
    """The largest set of predictions that agree with one of them (same group, within
    :data:`AGREE_M` / :data:`AGREE_DEG`), by summed score, best first; ties: the lower scan."""
    best: list[Prediction] = []
    best_key = (0.0, 0)
    for p in sorted(predictions, key=lambda q: q.via):
        mates = [
            q for q in predictions if q.group == p.group and agree(q.T_group_scan, p.T_group_scan)
        ]
        key = (sum(q.score for q in mates), len(mates))
        if key > best_key:
            best, best_key = mates, key
    return sorted(best, key=lambda q: (-q.score, q.via))


def nearest(
    where: Mapping[int, Placed], group: int, xy: np.ndarray, k: int, radius: float
) -> list[int]:
    """The ``k`` placed scans of ``group`` nearest to ``xy`` (m), at most ``radius`` m away."""
    mine = sorted(s for s, p in where.items() if p.group == group)
    d = [float(np.hypot(*(where[s].T_group_scan[:2, 3] - xy))) for s in mine]
    order = sorted(range(len(mine)), key=lambda n: (d[n], mine[n]))
    return [mine[n] for n in order if d[n] <= radius][:k]


def near_by_position(
    scan: int,
    positions: Mapping[int, tuple[np.ndarray, float]],
    candidates: Iterable[int],
    radius: float,
    k: int,
) -> list[int]:
    """The ``k`` candidates nearest to ``scan`` by their known positions (control stations,
    however coarse: a scanner's own GNSS of metres), each at most ``radius`` m plus three
    standard deviations of the distance away. ``positions``: (x, y) m in the control's frame
    and the horizontal standard deviation (m), per scan that has one; none for ``scan``:
    none."""
    if scan not in positions:
        return []
    xy, sigma = positions[scan]
    found = []
    for other in candidates:
        if other == scan or other not in positions:
            continue
        d = float(np.hypot(*(positions[other][0] - xy)))
        if d <= radius + 3.0 * float(np.hypot(sigma, positions[other][1])):
            found.append((d, other))
    return [other for _, other in sorted(found)[:k]]
