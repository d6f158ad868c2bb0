"""Exact nearest neighbours on a grid of cells: the kernels and their numpy twins against scipy's
k-d tree and against an exhaustive search, ties, bounds, empty and far-away cases, threads; the
rotation helpers that replaced scipy's against scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ndt_cli.core import neighbours, threads
from ndt_cli.core.transforms import quaternions, rotation_from_vector, rotation_to_quaternion

BACKENDS = [neighbours.NUMBA, neighbours.NUMPY]


def _exhaustive(points, queries, k, bound):
    """The k nearest of every query by sorting all distances: distance, then index."""
    e = queries[:, None, :] - points[None, :, :]
    d2 = e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1] + e[..., 2] * e[..., 2]
    idx = np.broadcast_to(np.arange(len(points)), d2.shape)
    order = np.lexsort((idx, d2), axis=1)[:, :k]
    d2k = np.take_along_axis(d2, order, axis=1)
    far = d2k >= bound * bound
    dist = np.where(far, np.inf, np.sqrt(d2k))
    index = np.where(far, len(points), order)
    pad = k - dist.shape[1]  # fewer points than k
    if pad > 0:
        dist = np.hstack([dist, np.full((len(queries), pad), np.inf)])
        index = np.hstack([index, np.full((len(queries), pad), len(points))])
    return dist, index


@pytest.mark.parametrize("kernels", BACKENDS, ids=repr)
@pytest.mark.parametrize(
    ("k", "bound", "cell"),
    [(1, np.inf, 0.7), (1, 0.3, 0.25), (7, 1.0, 0.7), (12, np.inf, 2.5), (12, 0.5, 0.1)],
)
def test_queries_equal_scipys_k_d_tree(kernels, k, bound, cell):
    rng = np.random.default_rng(k)
    away = np.array([3e4, -2e4, 50.0])  # from the origin
    points = rng.uniform(-5, 5, (4000, 3)) + away
    queries = rng.uniform(-7, 7, (600, 3)) + away  # some outside the points' box
    g = kernels.grid(points, cell)
    dist, index = kernels.knn(g, queries, k, bound)
    want_d, want_i = cKDTree(points).query(queries, k=k, distance_upper_bound=bound)
    np.testing.assert_array_equal(dist, want_d.reshape(len(queries), k))
    np.testing.assert_array_equal(index, want_i.reshape(len(queries), k))
    if k == 1:
        d1, i1 = kernels.nearest(g, queries, bound)
        np.testing.assert_array_equal(d1, dist[:, 0])
        np.testing.assert_array_equal(i1, index[:, 0])


@pytest.mark.parametrize("kernels", BACKENDS, ids=repr)
def test_ties_go_to_the_lower_index(kernels):
    """Points on a lattice, queried on the lattice and half-way between: many neighbours at
    exactly equal distances, and duplicates of one point."""
    rng = np.random.default_rng(3)
    points = np.round(rng.uniform(-2, 2, (1500, 3)) * 4) / 4
    points = np.vstack([points, points[:50]])  # exact duplicates
    queries = np.round(rng.uniform(-2.5, 2.5, (400, 3)) * 8) / 8
    for k, bound in ((1, np.inf), (9, 0.6), (20, np.inf)):
        dist, index = kernels.knn(kernels.grid(points, 0.5), queries, k, bound)
        want_d, want_i = _exhaustive(points, queries, k, bound)
        np.testing.assert_array_equal(dist, want_d)
        np.testing.assert_array_equal(index, want_i)


@pytest.mark.parametrize("kernels", BACKENDS, ids=repr)
def test_few_points_far_queries_and_empty_grids(kernels):
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 3.0, 0.0]])
    queries = np.array([[0.1, 0.0, 0.0], [500.0, -800.0, 20.0]])
    dist, index = kernels.knn(kernels.grid(points, 0.5), queries, 5)
    want_d, want_i = _exhaustive(points, queries, 5, np.inf)
    np.testing.assert_array_equal(dist, want_d)  # fewer points than k: inf and N after them
    np.testing.assert_array_equal(index, want_i)
    d, i = kernels.nearest(kernels.grid(points, 0.5), queries, 2.0)
    assert d[0] == pytest.approx(0.1) and i[0] == 0 and d[1] == np.inf and i[1] == 3
    empty = kernels.grid(np.zeros((0, 3)), 0.5)
    d, i = kernels.knn(empty, queries, 3)
    assert np.isinf(d).all() and (i == 0).all()
    assert kernels.knn(kernels.grid(points, 0.5), np.zeros((0, 3)), 3)[0].shape == (0, 3)
    with pytest.raises(ValueError, match="too far"):
        kernels.grid(np.array([[1e6, 0.0, 0.0]]), 0.25)


def test_results_do_not_depend_on_the_number_of_threads():
    rng = np.random.default_rng(5)
    points = rng.uniform(-20, 20, (20_000, 3))
    queries = points[::7] + rng.normal(0, 0.2, (len(points[::7]), 3))
    g = neighbours.grid(points, 1.0)
    runs = []
    before = threads.threads()
    try:
        for n in (1, 2, 3):
            threads.set_threads(n)
            runs.append(neighbours.knn(g, queries, 12))
    finally:
        threads.set_threads(before)
    for d, i in runs[1:]:
        np.testing.assert_array_equal(d, runs[0][0])
        np.testing.assert_array_equal(i, runs[0][1])


def test_both_grids_hold_the_same_points_per_cell():
    rng = np.random.default_rng(6)
    points = rng.uniform(-3, 3, (3000, 3))
    a, b = neighbours.grid(points, 0.4), neighbours.grid_numpy(points, 0.4)
    assert sorted(a.keys) == list(b.keys) and len(a.table) and not len(b.table)
    cells_a = {key: set(a.order[a.starts[m] : a.starts[m + 1]]) for m, key in enumerate(a.keys)}
    cells_b = {key: set(b.order[b.starts[m] : b.starts[m + 1]]) for m, key in enumerate(b.keys)}
    assert cells_a == cells_b
    np.testing.assert_array_equal(a.points, points[a.order])
    assert repr(a) == f"CellGrid(3000 points in {len(a.keys)} cells of 0.4 m)"


@pytest.mark.parametrize("angle", [0.0, 1e-14, 1e-9, 1e-4, 0.3, 2.0, np.pi - 1e-6, np.pi])
def test_rotation_from_vector_equals_scipys(angle):
    axis = np.array([0.3, -0.5, 0.81])
    v = angle * axis / np.linalg.norm(axis)
    R = rotation_from_vector(v)
    np.testing.assert_allclose(R, Rotation.from_rotvec(v).as_matrix(), rtol=0, atol=2e-16 * 8)
    np.testing.assert_allclose(R.T @ R, np.eye(3), rtol=0, atol=1e-15)


def test_quaternions_equal_scipys_up_to_sign():
    rng = np.random.default_rng(8)
    R = Rotation.random(200, random_state=rng)
    mats = np.concatenate(
        [R.as_matrix(), Rotation.from_rotvec([[np.pi, 0, 0], [0, 0, 0]]).as_matrix()]
    )
    q = quaternions(mats)
    xyzw = Rotation.from_matrix(mats).as_quat()
    want = np.column_stack([xyzw[:, 3], xyzw[:, :3]])
    want *= np.where(want[:, 0] < 0, -1.0, 1.0)[:, None]
    assert (q[:, 0] >= 0).all()
    close = np.abs(q - want).max(axis=1) < 1e-14
    flipped = np.abs(q + want).max(axis=1) < 1e-14  # w = 0: both signs are canonical
    assert (close | (flipped & (np.abs(q[:, 0]) < 1e-12))).all()
    np.testing.assert_array_equal(rotation_to_quaternion(mats[0]), q[0])
