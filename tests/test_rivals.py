"""Candidates judged by what the scanners saw: which are refuted, which wins, which rival it.
Expected values are worked out by hand from the rules of :mod:`ndt_cli.ndt.rivals`."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.ndt.coarse_to_fine import Ranked
from ndt_cli.ndt.rivals import (
    MAX_JUDGED,
    describe_rival,
    distinct,
    judge,
    judge_measured,
    judged_ones,
    refuted,
    turned,
)


def _ranked(poses: list[tuple[float, float, float]], evidence: list[float]) -> Ranked:
    n = len(poses)
    return Ranked(np.array(poses, float), np.ones(n), np.array(evidence, float), np.ones(n, bool))


@pytest.mark.parametrize(
    ("shares", "ratio", "margin", "out"),
    [
        ([0.0, 0.002, 0.0031], 2.0, 0.003, [False, False, True]),  # least 0: the margin counts
        ([0.01, 0.019, 0.021], 2.0, 0.003, [False, False, True]),  # twice the least counts
        ([0.01, 0.012], 1.0, 0.003, [False, False]),  # within the margin
        ([0.3, 0.0], 0.0, 0.003, [False, False]),  # switched off
        ([np.nan, 0.2, 0.0], 2.0, 0.003, [False, True, False]),  # not measured: not refuted
        ([np.nan, np.nan], 2.0, 0.003, [False, False]),  # nothing measured
    ],
)
def test_a_candidate_is_refuted_when_it_conflicts_clearly_more_than_the_cleanest(
    shares, ratio, margin, out
):
    assert refuted(np.array(shares), ratio, margin).tolist() == out


def test_the_winner_is_the_most_evident_candidate_the_free_space_allows():
    ranked = _ranked([(0, 0, 0), (10, 0, np.pi), (3.6, 0, 0), (0.2, 0.1, 0.01)], [3, 2.5, 2, 1.9])
    got = judge(ranked, np.array([0.02, 0.0, 0.001, 0.019]), 2.0, 0.003, 0.5)
    assert got.ranked.poses[0].tolist() == [10, 0, np.pi]  # the first two are refuted ...
    assert got.refuted.tolist() == [False, True, False, True]  # ... (reordered, winner first)
    assert got.rivals == (2,)  # slid by a room: 2 / 2.5 of the evidence, allowed
    assert "2.0%" in got.note and "0.0%" in got.note  # what was given up and what is kept
    alone = judge(ranked, np.array([0.0, 0.05, 0.06, 0.07]), 2.0, 0.003, 0.5)
    assert alone.rivals == () and alone.note == ""


def test_a_candidate_below_the_evidence_share_or_at_the_same_place_is_no_rival():
    ranked = _ranked([(0, 0, 0), (0.3, 0.2, 0.02), (0, 0, np.pi), (8, 0, 0)], [3, 2.9, 2.8, 1.4])
    got = judge(ranked, np.zeros(4), 2.0, 0.003, 0.5)
    assert got.rivals == (2,)  # 1: the same pose found twice; 3: below half the evidence
    blind = judge(ranked, np.full(4, np.nan), 2.0, 0.003, 0.95)  # no free space: evidence
    assert blind.rivals == () and not blind.refuted.any()
    assert distinct(np.array([0, 0, 0]), np.array([0.6, 0, 0]))
    assert not distinct(np.array([0, 0, 0]), np.array([0.3, 0.3, np.radians(2.0)]))


def test_a_candidate_turned_by_a_quarter_or_half_turn_is_a_rival_at_a_lower_share():
    """A district's blocks matched turned: the candidate turned by 180 degrees with 0.85 of the
    evidence is a rival at the turned share (0.8), the one slid by a block (no turn) with 0.9
    is not (below 0.95); the one turned by 45 degrees with 0.88 neither."""
    poses = [(0, 0, 0.3), (7, 0, 0.3 - np.pi), (60, 0, 0.3), (5, 5, 0.3 + np.pi / 4)]
    ranked = _ranked(poses, [1.0, 0.85, 0.9, 0.88])
    got = judge(ranked, np.zeros(4), 2.0, 0.003, (0.95, 0.8))
    assert got.rivals == (1,)
    quarter = _ranked([(0, 0, 3.0), (4, 4, 3.0 + np.pi / 2 - np.radians(1.5))], [1.0, 0.81])
    assert judge(quarter, np.zeros(2), 2.0, 0.003, (0.95, 0.8)).rivals == (1,)
    assert judge(quarter, np.zeros(2), 2.0, 0.003, 0.95).rivals == ()  # one share for both
    assert turned(np.array([0, 0, -3.1]), np.array([0, 0, 0.04]))  # a half turn, wrapped
    assert not turned(np.array([0, 0, 0.0]), np.array([0, 0, np.radians(86.0)]))
    assert not turned(np.array([0, 0, 0.0]), np.array([9, 0, 0.0]))


def test_a_rival_is_described_by_its_turn_and_distance():
    text = describe_rival(np.array([1.0, 2.0, 0.1]), np.array([4.0, 6.0, 0.1 - np.pi]), 0.8, 0.0)
    assert "turned -180.0 deg" in text and "5.00 m away" in text and "0.80 of the" in text


def test_the_free_space_is_measured_for_the_first_candidates_and_every_possible_rival():
    n = MAX_JUDGED + 6
    evidence = np.linspace(1.0, 0.1, n)  # the 17th and 18th keep more than 0.3 of the first
    want = [*range(MAX_JUDGED), *(k for k in range(MAX_JUDGED, n) if evidence[k] >= 0.3)]
    assert judged_ones(evidence, np.full(n, np.nan), 0.3) == want
    assert len(want) > MAX_JUDGED  # the case is one the limit alone would leave unmeasured
    done = np.full(n, np.nan)
    done[:MAX_JUDGED] = 0.0
    assert judged_ones(evidence, done, 0.3) == want[MAX_JUDGED:]  # measured once
    assert judged_ones(np.array([]), np.array([]), 0.5) == []


def _slid_corridor(n: int, slid: int) -> Ranked:
    """``n`` candidates of falling evidence, all turned 90 degrees from the first but ``slid``,
    a pose slid 0.7 m from the first with 0.53 of its evidence."""
    poses = [(0.0, 0.0, 0.0), *((5.0 + k, 0.0, np.pi / 2) for k in range(1, n))]
    poses[slid] = (0.7, 0.0, 0.0)
    evidence = [*np.linspace(1.0, 0.55, slid), 0.53, *np.linspace(0.4, 0.2, n - slid - 1)]
    return _ranked(poses, evidence)


def test_a_rival_beyond_the_first_candidates_is_measured_and_refuted():
    """A pose slid along a corridor, the 17th candidate: unmeasured, it would be the winner's
    only rival; measured, the free space refutes it (2 % of its points against none)."""
    n, slid = MAX_JUDGED + 4, MAX_JUDGED
    ranked = _slid_corridor(n, slid)
    assert ranked.poses[slid].tolist() == [0.7, 0.0, 0.0]
    shares = np.where(np.arange(n) == 0, 0.0, 0.02)
    asked = []

    def measure(k: int) -> float:
        asked.append(k)
        return float(shares[k])

    got = judge_measured(ranked, measure, 2.0, 0.003, (0.5, 0.5))
    assert got.rivals == () and got.refuted[slid] and slid in asked
    blind = judge(ranked, np.where(np.arange(n) < MAX_JUDGED, shares, np.nan), 2.0, 0.003, 0.5)
    assert blind.rivals == (slid,)  # what measuring only the first candidates left
    assert sorted(asked) == sorted(set(asked))  # each candidate measured once


def test_when_the_free_space_refutes_the_first_the_winners_rivals_are_measured_too():
    """The first candidate is refuted, so the winner has 0.6 of the most evidence and a
    candidate with 0.35 of it could be its rival (0.5 of 0.6 = 0.3): it is measured too, and
    refuted; unmeasured, it would have been the winner's rival."""
    n = MAX_JUDGED + 3
    poses = [(float(k), 0.0, 0.0) for k in range(n)]
    evidence = [1.0, *np.linspace(0.6, 0.36, MAX_JUDGED - 1), 0.35, 0.1, 0.05]
    ranked = _ranked(poses, evidence)
    shares = np.full(n, 0.05)
    shares[1] = 0.0  # the winner

    got = judge_measured(ranked, lambda k: float(shares[k]), 2.0, 0.003, 0.5)
    assert got.ranked.poses[0].tolist() == [1.0, 0.0, 0.0]
    assert got.rivals == ()
    at = next(k for k, p in enumerate(got.ranked.poses) if p[0] == MAX_JUDGED)
    assert got.shares[at] == 0.05 and got.refuted[at]
    assert np.isnan(got.shares[-1]) and np.isnan(got.shares[-2])  # 0.1 and 0.05: no rivals
    assert judge_measured(ranked, None, 2.0, 0.003, 0.5).refuted.sum() == 0  # nothing seen
