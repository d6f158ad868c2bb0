"""Local solvers recover a known planar pose from inside the basin."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.config import OptimizerConfig
from ndt_cli.ndt.grid import build_map
from ndt_cli.ndt.kernels import SCORE, SourcePoints, accumulate
from ndt_cli.ndt.optimize import optimize


def _room(rng: np.random.Generator) -> np.ndarray:
    """Points on an irregular 2D floor plan (metres)."""
    corners = np.array([[0, 0], [30, 0], [30, 12], [22, 12], [22, 25], [-4, 25], [-4, 9], [0, 9]])
    segs = []
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        t = rng.uniform(0, 1, int(np.hypot(*(b - a)) * 40))[:, None]
        segs.append(a + t * (b - a))
    pillars = rng.normal([[10, 15]], 0.3, (400, 2))
    return np.concatenate([*segs, pillars]) + rng.normal(0, 0.02, (sum(map(len, segs)) + 400, 2))


@pytest.mark.parametrize("method", ["newton", "lm_fixed", "lm"])
def test_solvers_recover_a_known_pose(method):
    rng = np.random.default_rng(0)
    target = _room(rng)
    true = np.array([1.2, -0.8, np.radians(4.0)])
    c, s = np.cos(true[2]), np.sin(true[2])
    R = np.array([[c, -s], [s, c]])
    source = (_room(rng) - true[:2]) @ R  # source = R^T (target - t)
    src = SourcePoints.from_slices([source])
    cfg = OptimizerConfig(method=method, max_iterations=100, patience=5)
    p = np.zeros((1, 3))
    for cell in [4.0, 2.0, 1.0, 0.5]:
        ndt = build_map([target], cell)
        res = optimize(lambda P, m=ndt: accumulate(m, src, P), p, cfg, cell)
        assert res.score[0] >= accumulate(ndt, src, p)[0, SCORE]  # never worse than the start
        p = res.params
    assert abs(p[0, 0] - true[0]) < 0.02 and abs(p[0, 1] - true[1]) < 0.02
    assert abs(np.degrees(p[0, 2] - true[2])) < 0.05


def test_batch_starts_are_independent():
    rng = np.random.default_rng(1)
    target = _room(rng)
    src = SourcePoints.from_slices([_room(rng)])
    ndt = build_map([target], 2.0)
    cfg = OptimizerConfig()
    starts = np.array([[0.5, 0.3, 0.02], [3.0, -2.0, 0.3], [-1.0, 1.0, -0.1]])
    batch = optimize(lambda P: accumulate(ndt, src, P), starts, cfg, 2.0)
    for k in range(3):
        single = optimize(lambda P: accumulate(ndt, src, P), starts[k : k + 1], cfg, 2.0)
        np.testing.assert_array_equal(single.params[0], batch.params[k])
        assert single.iterations[0] == batch.iterations[k]


def test_patience_and_iteration_limit():
    rng = np.random.default_rng(2)
    target = _room(rng)
    src = SourcePoints.from_slices([_room(rng)])
    ndt = build_map([target], 2.0)
    res = optimize(
        lambda P: accumulate(ndt, src, P),
        np.array([[2.0, 1.0, 0.1]]),
        OptimizerConfig(max_iterations=2, patience=50),
        2.0,
    )
    assert res.iterations[0] == 2 and not res.converged[0]
    assert res.trace.shape == (2, 1)
    assert np.all(np.diff(res.trace[:, 0]) >= 0)  # best score never falls
