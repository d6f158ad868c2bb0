"""Numba kernels against their numpy twins and against finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.core import threads
from ndt_cli.ndt import kernels
from ndt_cli.ndt.grid import build_map
from ndt_cli.ndt.kernels import GRAD, HESS, SCORE, SourcePoints, accumulate, accumulate_numpy, sym3


def _scene(seed: int = 0, n: int = 3000) -> list[np.ndarray]:
    """Two slices of wall-like 2D points with noise (metres)."""
    rng = np.random.default_rng(seed)
    walls = []
    for _ in range(2):
        t = rng.uniform(0, 40, n)
        side = rng.integers(0, 3, n)
        xy = np.where(
            (side == 0)[:, None],
            np.column_stack([t, np.full(n, 5.0)]),
            np.where(
                (side == 1)[:, None],
                np.column_stack([t, np.full(n, -6.0) + 0.3 * np.sin(t)]),
                np.column_stack([np.full(n, 12.0), t - 20]),
            ),
        )
        walls.append(xy + rng.normal(0, 0.05, xy.shape))
    return walls


@pytest.fixture(scope="module", params=[False, True], ids=["single", "overlap"])
def setup(request):
    slices = _scene()
    ndt = build_map(slices, 4.0, overlap=request.param)
    rng = np.random.default_rng(1)
    src = SourcePoints.from_slices([s[rng.choice(len(s), 500, replace=False)] for s in slices])
    return ndt, src


PARAMS = np.array([[0.0, 0.0, 0.0], [0.7, -0.4, 0.05], [-1.3, 0.9, -0.12], [30.0, 0.0, 2.0]])


def test_kernel_matches_numpy_twin(setup):
    ndt, src = setup
    fast = accumulate(ndt, src, PARAMS)
    slow = accumulate_numpy(ndt, src, PARAMS)
    assert fast[0, SCORE] > 10  # the aligned pose scores: the test is not vacuous
    np.testing.assert_allclose(fast, slow, rtol=1e-9, atol=1e-9)


def test_point_kernel_matches_twin_and_batch(setup):
    ndt, src = setup
    p = PARAMS[1]
    s, J = kernels.point_scores(ndt, src, p)
    s2, J2 = kernels.point_scores_numpy(ndt, src, p)
    np.testing.assert_allclose(s, s2, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(J, J2, rtol=1e-10, atol=1e-12)
    acc = accumulate(ndt, src, p)[0]
    assert acc[SCORE] == pytest.approx(s.sum(), rel=1e-12)
    np.testing.assert_allclose(acc[GRAD], -J.sum(axis=0), rtol=1e-9, atol=1e-9)


def _f(ndt, src, p):
    return -accumulate(ndt, src, p)[0, SCORE]


@pytest.mark.parametrize("k", [1, 2])
def test_gradient_and_hessian_match_finite_differences(setup, k):
    ndt, src = setup
    p = PARAMS[k]
    acc = accumulate(ndt, src, p)[0]
    g, H = acc[GRAD], sym3(acc[HESS])
    steps = np.array([1e-6, 1e-6, 1e-8])
    g_fd = np.zeros(3)
    H_fd = np.zeros((3, 3))
    for i in range(3):
        dp = np.zeros(3)
        dp[i] = steps[i]
        g_fd[i] = (_f(ndt, src, p + dp) - _f(ndt, src, p - dp)) / (2 * steps[i])
        a_plus = accumulate(ndt, src, p + dp)[0, GRAD]
        a_minus = accumulate(ndt, src, p - dp)[0, GRAD]
        H_fd[:, i] = (a_plus - a_minus) / (2 * steps[i])
    np.testing.assert_allclose(g, g_fd, rtol=1e-4, atol=1e-5 * np.abs(g).max())
    np.testing.assert_allclose(H, H_fd, rtol=1e-4, atol=1e-5 * np.abs(H).max())
    np.testing.assert_allclose(H, H.T)


def test_lm_quantities_match_point_jacobian(setup):
    """Without overlap a (point, grid) pair is a point: J^T J equals the per-point Jacobian's."""
    _, src = setup
    ndt = build_map(_scene(), 4.0, overlap=False)
    p = PARAMS[2]
    s, J = kernels.point_scores(ndt, src, p)
    acc = accumulate(ndt, src, p)[0]
    np.testing.assert_allclose(sym3(acc[kernels.JTJ]), J.T @ J, rtol=1e-9)
    # residual r = 1 - s: J_r = -J, gradient of E = J_r^T r
    np.testing.assert_allclose(acc[kernels.JTR], -J.T @ (1 - s), rtol=1e-9, atol=1e-12)
    assert acc[kernels.ERR] == pytest.approx(0.5 * np.sum((1 - s) ** 2), rel=1e-12)


def test_reduction_is_deterministic_across_threads(setup):
    ndt, src = setup
    runs = []
    before = threads.threads()
    try:
        for n in (1, 2, 3):
            threads.set_threads(n)
            runs.append((accumulate(ndt, src, PARAMS), kernels.point_scores(ndt, src, PARAMS[0])))
    finally:
        threads.set_threads(before)
    for acc, (s, J) in runs[1:]:
        assert np.array_equal(acc, runs[0][0])
        assert np.array_equal(s, runs[0][1][0]) and np.array_equal(J, runs[0][1][1])


def test_points_outside_every_cell_score_zero(setup):
    ndt, src = setup
    acc = accumulate(ndt, src, [1e4, 1e4, 0.0])[0]
    assert acc[SCORE] == 0.0 and acc[kernels.MATCHED] == 0.0
    per_point_pairs = np.diff(ndt.slice_grids)[src.slice_id].sum()
    assert acc[kernels.ERR] == pytest.approx(0.5 * per_point_pairs)
