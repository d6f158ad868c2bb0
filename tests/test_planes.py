"""Local planes (normals, planarity): the Numba kernel against the geometry of known
neighbourhoods and against its numpy twin."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ndt_cli.core.planes import local_planes, local_planes_numpy


def _box_corners(half: tuple[float, float, float], R: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The 8 corners of a box with half-sides ``half`` along the columns of ``R``: their
    covariance has the eigenvalues half**2 and the eigenvectors R's columns, exactly."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return at + (signs * half) @ R.T


@pytest.mark.parametrize("planes", [local_planes, local_planes_numpy])
def test_normal_and_planarity_of_boxes_with_known_eigenvectors(planes):
    rng = np.random.default_rng(5)
    data, want_n, want_p = [], [], []
    for _ in range(200):
        R = Rotation.random(random_state=rng).as_matrix()
        a, b, c = np.sort(rng.uniform(0.01, 2.0, 3))[::-1]  # a > b > c
        data.append(_box_corners((a, b, c), R, rng.uniform(-50, 50, 3)))
        want_n.append(R[:, 2])
        want_p.append(1.0 - c**2 / b**2)
    data = np.vstack(data)
    idx = np.arange(len(data)).reshape(-1, 8)
    n, p = planes(data, idx)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", n, want_n)), 1.0, atol=1e-9)
    np.testing.assert_allclose(p, want_p, atol=1e-9)


def test_kernel_matches_numpy_twin_on_scan_like_neighbourhoods():
    rng = np.random.default_rng(6)
    # a wall, a floor, a pole and a bush: planes, a line and a blob
    wall = np.column_stack([rng.uniform(0, 10, 3000), np.full(3000, 4.0), rng.uniform(0, 3, 3000)])
    floor = np.column_stack([rng.uniform(-5, 5, (3000, 2)), rng.normal(0, 0.005, 3000)])
    pole = np.column_stack([rng.normal(0, 0.01, (500, 2)) + 2.0, rng.uniform(0, 4, 500)])
    bush = rng.normal([6.0, -3.0, 1.0], 0.4, (1000, 3))
    data = np.vstack([wall, floor, pole, bush]) + rng.normal(0, 0.002, (7500, 3))
    _, idx = cKDTree(data).query(data[::3], k=12)
    n, p = local_planes(data, idx)
    n_ref, p_ref = local_planes_numpy(data, idx)
    np.testing.assert_allclose(p, p_ref, atol=1e-9)
    clear = p_ref > 0.05  # where the smallest eigenvalue is distinct, so is its eigenvector
    dots = np.abs(np.einsum("ij,ij->i", n, n_ref))[clear]
    np.testing.assert_allclose(dots, 1.0, atol=1e-9)
    on_wall = np.arange(0, 7500, 3) < 3000
    assert np.median(np.abs(n[on_wall, 1])) > 0.99  # the wall's normal is y
    assert np.median(p[on_wall]) > 0.9


def test_degenerate_neighbourhoods_give_finite_unit_normals():
    same = np.tile([[1.0, 2.0, 3.0]], (10, 1))
    line = np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)])
    for data in (same, line):
        n, p = local_planes(data, np.arange(10)[None, :])
        assert np.all(np.isfinite(n)) and np.isclose(np.linalg.norm(n), 1.0)
        assert np.all(np.isfinite(p))
    n, p = local_planes(same, np.empty((0, 12), np.int64))
    assert n.shape == (0, 3) and p.shape == (0,)
