"""Which of a registration's distinct candidates the data allow, which one wins, and its rivals.

Two kinds of evidence judge a candidate pose. NDT's evidence (:func:`~ndt_cli.ndt.
coarse_to_fine.fit_weighted`) says how much of the slices a pose fits; it is *for* a pose, and
biased: indoors, and wherever scanners see each other's surroundings only at grazing angles,
poses that put the two scanners close together fit the most, since there each scan's dense near
field meets the other's. What the scanners saw (:mod:`ndt_cli.ndt.visibility`) is evidence
*against* a pose: the share of points it puts into space the other scanner saw to be empty.

- A candidate is **refuted** when it puts clearly more points into free space than the cleanest
  candidate: more than ``search.free_space_ratio`` times its share and more than
  ``search.free_space_share`` above it. On simulated streets and interiors the true pose put
  0-1.3 % of the points there, every wrong candidate that was not a near copy of the truth
  0.2-30 %, and in 44 of 44 interior links whose truth was among the candidates the truth had
  the least (docs/trust.md).
- The **winner** is the candidate of most NDT evidence among those not refuted.
- Its **rivals** are the other candidates not refuted, distinct from it, with at least
  ``quality.max_ambiguity`` of its evidence: poses the data cannot tell from the winner (a
  corridor turned by 180 degrees, a pose slid by a room's width); a candidate turned from it by
  90 or 180 degrees (within :data:`TURN_TOLERANCE`) needs only
  ``quality.max_ambiguity_turned``. Right angles repeat: the blocks of a district and the
  rooms of a floor match themselves turned, and two scans that do not overlap at all match
  only such copies, every candidate a turn or a block's shift of another, the first with a
  little more evidence than the rest by chance. A link with a rival is
  ambiguous; the network chooses among the rivals of all links jointly
  (:mod:`ndt_cli.pipeline.hypotheses`).

Without what the scanners saw (a georeferenced file, or the check off) nothing is refuted and
rivals follow from NDT's evidence alone, as before the check existed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ndt_cli.core.transforms import wrap_angle
from ndt_cli.ndt.coarse_to_fine import Ranked

RIVAL_DISTANCE = 0.5  # m: candidates nearer than this (and within RIVAL_YAW) are one pose
RIVAL_YAW = np.radians(3.0)
TURN_TOLERANCE = np.radians(2.0)  # a candidate this near a quarter or half turn is turned
MAX_JUDGED = 16  # candidates, most evidence first, whose free space is always measured


@dataclass(frozen=True)
class Judged:
    """The candidates with the winner first (``ranked``), the free-space share of each (NaN
    where not measured), whether each is refuted, the indices of the winner's rivals, and a
    note when the winner is not the candidate of most evidence ('' when it is)."""

    ranked: Ranked
    shares: np.ndarray
    refuted: np.ndarray
    rivals: tuple[int, ...]
    note: str = ""
    kept_evidence: float = 1.0  # the winner's evidence over the most evidence of any candidate


def refuted(shares: np.ndarray, ratio: float, margin: float) -> np.ndarray:
    """Which candidates put clearly more points into free space than the cleanest one: more
    than ``ratio`` times its share and more than ``margin`` above it (NaN: not refuted; ratio
    0: the check is off)."""
    shares = np.asarray(shares, dtype=float)
    if ratio <= 0.0 or not np.isfinite(shares).any():
        return np.zeros(len(shares), dtype=bool)
    least = float(np.nanmin(shares))
    bound = max(ratio * least, least + margin)
    return np.isfinite(shares) & (shares > bound)


def distinct(a: np.ndarray, b: np.ndarray) -> bool:
    """Two planar poses (tx, ty, yaw; m, rad) are different poses, not one pose found twice."""
    near = np.hypot(a[0] - b[0], a[1] - b[1]) <= RIVAL_DISTANCE
    return not (near and abs(wrap_angle(a[2] - b[2])) <= RIVAL_YAW)


def turned(a: np.ndarray, b: np.ndarray) -> bool:
    """Two planar poses (tx, ty, yaw; m, rad) differ by a quarter or a half turn."""
    turn = abs(wrap_angle(a[2] - b[2]))
    return min(abs(turn - np.pi / 2), abs(turn - np.pi)) <= TURN_TOLERANCE


def judge(
    ranked: Ranked,
    shares: np.ndarray,
    ratio: float,
    margin: float,
    ambiguity: float | tuple[float, float],
) -> Judged:
    """The winner (first in the returned ``ranked``), the refuted candidates and the winner's
    rivals, from candidates ranked by evidence and their free-space ``shares``.
    ``ambiguity``: the share of the winner's evidence that makes a candidate a rival, and the
    share for one turned from it by 90 or 180 degrees (one number: both)."""
    same, turn = (ambiguity, ambiguity) if np.isscalar(ambiguity) else ambiguity
    out = refuted(shares, ratio, margin)
    allowed = np.flatnonzero(~out)
    win = int(allowed[0]) if len(allowed) else 0  # ranked by evidence: the first allowed
    kept = float(ranked.evidence[win] / max(float(ranked.evidence[0]), 1e-300))
    order = [win, *(k for k in range(len(ranked.poses)) if k != win)]
    ranked = ranked.promote(win) if win else ranked
    shares, out = np.asarray(shares, dtype=float)[order], out[order]
    best = ranked.evidence[0]
    rivals = tuple(
        k
        for k in range(1, len(ranked.poses))
        if not out[k]
        and distinct(ranked.poses[k], ranked.poses[0])
        and ranked.evidence[k]
        >= (turn if turned(ranked.poses[k], ranked.poses[0]) else same) * best
    )
    note = "" if win == 0 else _promoted(shares[0], float(shares[1]))
    return Judged(ranked, shares, out, rivals, note, kept)


def judge_measured(
    ranked: Ranked,
    measure: Callable[[int], float] | None,
    ratio: float,
    margin: float,
    ambiguity: float | tuple[float, float],
) -> Judged:
    """:func:`judge` with the free-space shares that ``measure`` (candidate index -> share,
    0-1; None: nothing can be measured) gives for :func:`judged_ones`: measured again down to
    the rival level of the winner, whose evidence may be less than the first candidate's
    when the free space refutes that one."""
    shares = np.full(len(ranked.poses), np.nan)
    judged = judge(ranked, shares, ratio, margin, ambiguity)
    if measure is None or ratio <= 0.0:
        return judged
    least = min(np.atleast_1d(ambiguity))
    winner = float(ranked.evidence[0]) if len(ranked.evidence) else 0.0
    while todo := judged_ones(ranked.evidence, shares, least * winner):
        for k in todo:
            shares[k] = measure(k)
        judged = judge(ranked, shares, ratio, margin, ambiguity)
        winner = float(judged.ranked.evidence[0])
    return judged


def judged_ones(evidence: np.ndarray, shares: np.ndarray, least: float) -> list[int]:
    """The candidates (ranked by ``evidence``, most first) whose free space is still to be
    measured (``shares`` NaN): the :data:`MAX_JUDGED` of most evidence, and every further one
    with at least ``least`` evidence, which could be the winner's rival. A candidate left
    unmeasured cannot be refuted, so it would make a link ambiguous that the free space
    clears: on an office floor, a pose slid 0.7 m along the corridor, the 17th candidate with
    0.53 of the evidence, was the only rival of a right link, and the free space refutes
    it."""
    evidence = np.asarray(evidence, dtype=float)
    wanted = (np.arange(len(evidence)) < MAX_JUDGED) | (evidence >= least)
    return [int(k) for k in np.flatnonzero(wanted & np.isnan(shares))]


def _promoted(kept: float, given_up: float) -> str:
    return (
        f"free space: the pose of most evidence puts {given_up:.1%} of the points into space "
        f"the other scanner saw empty, the pose kept {kept:.1%}"
    )


def describe_rival(winner: np.ndarray, rival: np.ndarray, evidence: float, share: float) -> str:
    """How a rival pose differs from the winner, in words: its turn (degrees) and the distance
    (m) between where the two poses put the source's origin, its share of the winner's
    evidence and of the points in free space."""
    turn = float(np.degrees(wrap_angle(rival[2] - winner[2])))
    apart = float(np.hypot(rival[0] - winner[0], rival[1] - winner[1]))
    seen = "" if not np.isfinite(share) else f", {share:.1%} of the points in free space"
    return (
        f"a pose turned {turn:+.1f} deg and {apart:.2f} m away ({evidence:.2f} of the "
        f"evidence{seen})"
    )
