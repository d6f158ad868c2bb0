"""Coarse matches of many pairs on a campaign's workers, and the partners they rank. The
matches computed by the workers (or here, for a batch whose worker was lost) are compared with
those computed here, one by one; the ranking with scores made up for the test."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from ndt_cli import sim
from ndt_cli.config import Config
from ndt_cli.ndt.overlap import coarse_match, sketch
from ndt_cli.ndt.prepare import prepare
from ndt_cli.pipeline.coarse import BATCH_PAIRS, match_pairs, partners
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.workers import Failure


@pytest.fixture(scope="module")
def sketches():
    route = sim.route(seed=4, n_scans=13, rays=(600, 90))
    return {k: sketch(prepare(pts, Config())) for k, pts in enumerate(route.scans)}


@pytest.mark.slow
def test_the_workers_give_every_pair_the_match_computed_here(sketches):
    pairs = [(a, b) for a in sketches for b in sketches if a < b]
    assert len(pairs) > 2 * BATCH_PAIRS  # several batches, the last one short
    pool = WorkerPool(2)
    try:
        found = match_pairs(pool, sketches, pairs)
    finally:
        pool.close()
    assert sorted(found) == pairs
    for a, b in pairs:
        here = coarse_match(sketches[a], sketches[b])
        assert found[(a, b)].score == here.score, (a, b)
        assert np.array_equal(found[(a, b)].T_target_source, here.T_target_source), (a, b)


def test_each_pair_is_matched_on_the_target_given_and_kept_as_its_source_on_its_target(
    sketches,
):
    """Given (hi, lo), the match is hi's sketch matched with lo's as the source, kept by
    (lo, hi) as the inverse pose; the search is not symmetric, so that differs from matching
    lo's first (which the keys alone would not tell)."""
    pairs = [(b, a) for a in sketches for b in sketches if a < b][:6]
    found = match_pairs(_LosesBatch(lost=-1), sketches, pairs)
    assert sorted(found) == sorted((a, b) for b, a in pairs)
    differs = 0
    for b, a in pairs:
        there = coarse_match(sketches[b], sketches[a])
        np.testing.assert_array_equal(
            found[(a, b)].T_target_source, np.linalg.inv(there.T_target_source)
        )
        direct = coarse_match(sketches[a], sketches[b]).T_target_source
        differs += not np.array_equal(direct, found[(a, b)].T_target_source)
    assert differs > 0


class _LosesBatch:
    """An executor whose worker is lost on one batch: that batch's value is a failure, the
    others are computed (in this process)."""

    ships_data = True

    def __init__(self, lost: int) -> None:
        self.lost = lost

    def run(self, tasks, then=None):
        for key, task in tasks.items():
            yield key, (Failure("worker error: lost") if key == self.lost else task())


@pytest.mark.slow
def test_a_batch_whose_worker_was_lost_is_computed_here(sketches):
    pairs = [(a, b) for a in sketches for b in sketches if a < b]
    found = match_pairs(_LosesBatch(lost=1), sketches, pairs)
    assert sorted(found) == pairs  # the lost batch's pairs too, none twice or missing
    for a, b in pairs[BATCH_PAIRS : 2 * BATCH_PAIRS]:  # the second batch: the one lost
        here = coarse_match(sketches[a], sketches[b])
        assert found[(a, b)].score == here.score, (a, b)
        assert np.array_equal(found[(a, b)].T_target_source, here.T_target_source), (a, b)


def test_partners_are_the_best_scores_either_way_round_ties_by_index():
    scores = {(0, 3): 0.5, (1, 3): 0.9, (3, 4): 0.7, (2, 3): 0.7, (3, 5): 0.1}
    matches = {p: SimpleNamespace(score=s) for p, s in scores.items()}
    assert partners(matches, 3, [0, 1, 2, 4, 5], k=2) == [1, 2]
    assert partners(matches, 3, [0, 1, 2, 4, 5], k=3) == [1, 2, 4]
    assert partners(matches, 3, [0, 5], k=2) == [0, 5]
