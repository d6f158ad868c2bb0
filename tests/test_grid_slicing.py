"""Grid statistics, covariance regularisation, ground estimate, slicing and thinning."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.grid import build_map, regularised_inverse
from ndt_cli.slicing import cut_slices, estimate_ground, subsample, voxel_filter_2d


def test_cell_mean_and_covariance_match_numpy():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-7, 13, (5000, 2))
    m = build_map([xy], 5.0, min_points=3, min_eigen_ratio=1e-9, min_variance=1e-12)
    ij = np.floor((xy - m.grid_origin[0]) / 5.0).astype(int)
    ny = m.grid_shape[0, 1]
    for key in [0, 5, 11]:
        cell = (ij[:, 0] * ny + ij[:, 1]) == key
        row = m.cell_index[key]
        assert row >= 0
        np.testing.assert_allclose(m.means[row], xy[cell].mean(axis=0))
        inv = np.linalg.inv(np.cov(xy[cell].T))
        np.testing.assert_allclose(m.icov[row], [inv[0, 0], inv[0, 1], inv[1, 1]], rtol=1e-9)
    assert m.counts.sum() == len(xy)  # the grid covers all points: none dropped


def test_cells_with_too_few_points_are_empty():
    xy = np.array([[0.1, 0.1], [0.2, 0.3], [0.4, 0.2], [5.5, 5.5], [5.6, 5.7]])
    m = build_map([xy], 1.0, min_points=3)
    assert m.n_cells == 1
    assert (m.cell_index >= 0).sum() == 1


def test_line_cell_is_regularised_and_finite():
    x = np.linspace(0, 0.9, 50)
    xy = np.column_stack([x, np.full_like(x, 0.5)])  # a perfect line: singular covariance
    m = build_map([xy], 1.0, min_eigen_ratio=1e-3, min_variance=1e-6)
    a, b, c = m.icov[0]
    assert np.isfinite([a, b, c]).all()
    lam_max = np.var(x, ddof=1)
    assert c == pytest.approx(1.0 / (1e-3 * lam_max), rel=1e-6)  # clamped small eigenvalue


def test_regularised_inverse_keeps_well_conditioned_covariances():
    cov = np.array([[[2.0, 0.3], [0.3, 1.0]]])
    inv = regularised_inverse(cov, 1e-3, 1e-6)[0]
    ref = np.linalg.inv(cov[0])
    np.testing.assert_allclose(inv, [ref[0, 0], ref[0, 1], ref[1, 1]])


def test_overlap_builds_four_shifted_grids_per_slice():
    rng = np.random.default_rng(1)
    slices = [rng.uniform(0, 30, (3000, 2)), rng.uniform(0, 30, (3000, 2))]
    m = build_map(slices, 4.0, overlap=True)
    assert list(m.slice_grids) == [0, 4, 8]
    frac = (m.grid_origin[:4] / 4.0) % 1.0
    assert sorted(map(tuple, np.round(frac, 6))) == [(0, 0), (0, 0.5), (0.5, 0), (0.5, 0.5)]


def test_ground_is_found_under_facades_and_noise():
    rng = np.random.default_rng(2)
    ground = rng.normal(-1.73, 0.01, 20000)
    walls = rng.uniform(-1.7, 15.0, 30000)
    car_roofs = rng.normal(-0.2, 0.02, 3000)
    z = np.concatenate([ground, walls, car_roofs])
    assert estimate_ground(z) == pytest.approx(-1.73, abs=0.01)


def test_slices_take_points_by_height_above_ground():
    pts = np.array([[0, 0, 10.0], [1, 1, 10.19], [2, 2, 10.25], [3, 3, 12.0], [4, 4, 11.85]])
    s = cut_slices(pts, ground_z=9.0, heights=[1.0, 3.0], thickness=0.4)
    np.testing.assert_array_equal(s[0], [[0, 0], [1, 1]])
    np.testing.assert_array_equal(s[1], [[3, 3], [4, 4]])


def test_voxel_filter_and_subsample_are_deterministic():
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 10, (20000, 2))
    v = voxel_filter_2d(xy, 0.5)
    assert len(v) == 400
    np.testing.assert_allclose(v, voxel_filter_2d(xy[::-1], 0.5))  # order-independent
    a, b = subsample(v, 100, seed=4), subsample(v, 100, seed=4)
    assert len(a) == 100 and np.array_equal(a, b)
