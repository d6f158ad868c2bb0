"""Grid statistics, covariance regularisation, ground estimate, slicing and thinning."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.core.groups import group_keys, group_sums
from ndt_cli.ndt.grid import build_map, regularised_inverse
from ndt_cli.ndt.slicing import cut_slices, subsample, voxel_filter_2d


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


@pytest.mark.parametrize("spread", [50, 10**9])  # a dense count array, and np.unique's path
def test_grouping_is_bit_identical_to_unique_and_add_at(spread):
    rng = np.random.default_rng(3)
    keys = rng.integers(0, spread, 20_000)
    values = rng.normal(0, 100, (20_000, 3))
    ref_keys, ref_inverse, ref_counts = np.unique(keys, return_inverse=True, return_counts=True)
    ref_sums = np.zeros((ref_keys.size, 3))
    np.add.at(ref_sums, ref_inverse, values)
    got_keys, got_inverse, got_counts = group_keys(keys)
    assert np.array_equal(got_keys, ref_keys) and np.array_equal(got_counts, ref_counts)
    assert np.array_equal(got_inverse, ref_inverse)
    assert np.array_equal(group_sums(got_inverse, values, got_keys.size), ref_sums)  # bits
    empty = group_keys(np.zeros(0, np.int64))
    assert all(len(a) == 0 for a in empty)


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


@pytest.fixture(scope="module")
def tilted_scan():
    """A simulated street scan from a scanner tilted 8 deg in roll and 6 deg in pitch."""
    from ndt_cli import sim

    scene = sim.make_street(seed=3)
    T = sim.scanner_pose(0.0, 0.0, 30.0, roll_deg=8.0, pitch_deg=-6.0)
    return sim.simulate_scan(scene, T, n_azimuth=720, n_elevation=100), T


def test_dominant_up_finds_the_ground_normal_of_a_strongly_tilted_scanner(tilted_scan):
    from ndt_cli.ndt.vertical import dominant_up

    pts, T = tilted_scan
    up = dominant_up(pts)
    truth = T[:3, :3].T @ [0.0, 0.0, 1.0]  # world up seen in the scanner frame
    assert np.degrees(np.arccos(np.clip(up @ truth, -1, 1))) < 0.2
    assert np.allclose(dominant_up(np.tile([0.0, 0.0, 1.0], (10, 1))), [0, 0, 1])  # too few points


def test_prepare_levels_a_strongly_tilted_scan(tilted_scan):
    from ndt_cli.config import Config
    from ndt_cli.ndt.prepare import prepare

    pts, T = tilted_scan
    scan = prepare(pts, Config())
    # the levelled frame differs from the world only by a turn about z
    R = scan.level @ T[:3, :3].T
    assert abs(np.degrees(np.arccos(np.clip(R[2, 2], -1, 1)))) < 0.1
    assert 9.0 < scan.tilt_deg < 11.0  # roll 8 and pitch 6 deg combine to 10 deg
    # the reduction point lies on the ground (world z = 0)
    assert abs((T[:3, :3] @ scan.reduction + T[:3, 3])[2]) < 0.03


def test_voxel_thinning_does_not_depend_on_chunking():
    from ndt_cli.core.geometry import VoxelThinner, voxel_thin

    rng = np.random.default_rng(5)
    pts = rng.uniform(-30, 30, (20000, 3))
    whole = voxel_thin(pts, 0.5)
    thinner = VoxelThinner(0.5)
    for part in np.array_split(pts, 7):
        thinner.add(part)
    np.testing.assert_allclose(thinner.result(), whole, atol=1e-12)
    # reference: the mean of the points sharing a voxel, voxels in lexicographic order
    ijk = np.floor(pts / 0.5).astype(int)
    order = sorted({tuple(v) for v in ijk})
    first = order[0]
    np.testing.assert_allclose(whole[0], pts[(ijk == first).all(axis=1)].mean(axis=0))
    assert len(whole) == len(order)


def test_a_streamed_scan_is_prepared_like_one_read_at_once(tilted_scan, tmp_path):
    from ndt_cli import io
    from ndt_cli.config import Config
    from ndt_cli.ndt.prepare import load_and_prepare

    pts, _ = tilted_scan
    path = tmp_path / "scan.las"
    io.write(path, pts)
    whole = load_and_prepare(path, Config())
    streamed = load_and_prepare(path, Config().replace(input={"chunk_points": len(pts) // 5}))
    assert streamed.n_points == whole.n_points == len(pts)
    np.testing.assert_array_equal(streamed.reduction, whole.reduction)
    np.testing.assert_array_equal(streamed.level, whole.level)
    for a, b in zip(streamed.slices, whole.slices, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(streamed.points3d, whole.points3d, atol=1e-9)


def test_a_pair_prepared_in_two_threads_equals_each_scan_prepared_alone(tilted_scan, tmp_path):
    from ndt_cli import io
    from ndt_cli.config import Config
    from ndt_cli.errors import InputError
    from ndt_cli.ndt.prepare import load_and_prepare, load_and_prepare_pair

    pts, _ = tilted_scan
    a, b = tmp_path / "a.las", tmp_path / "b.las"
    io.write(a, pts)
    io.write(b, pts[::2] + np.array([4.0, -3.0, 0.0]))
    cfg = Config().replace(input={"chunk_points": len(pts) // 3})  # a is streamed, b is not
    pair = load_and_prepare_pair(a, b, cfg)
    for got, path in zip(pair, (a, b), strict=True):
        alone = load_and_prepare(path, cfg)
        assert got.path == path
        np.testing.assert_array_equal(got.reduction, alone.reduction)
        np.testing.assert_array_equal(got.points3d, alone.points3d)
        for s, t in zip(got.slices, alone.slices, strict=True):
            np.testing.assert_array_equal(s, t)
    empty = Config().replace(input={"max_range": 0.01})  # both fail: the target's error wins
    with pytest.raises(InputError, match=r"a\.las"):
        load_and_prepare_pair(a, b, empty)


def test_slice_pass_matches_its_numpy_twin_with_overlapping_slices():
    from ndt_cli.core.geometry import VoxelThinner
    from ndt_cli.core.transforms import levelling_rotation
    from ndt_cli.ndt.passes import bounds, slice_pass, slice_pass_numpy
    from ndt_cli.ndt.terrain import Terrain

    rng = np.random.default_rng(8)
    pts = np.repeat(rng.uniform([-40, -40, -2], [40, 40, 15], (3000, 3)), 3, axis=0)  # runs
    pts += rng.normal(0, 0.01, pts.shape)
    pts[:20] *= 100.0  # stray points, most beyond the range kept
    reduction, level = np.array([3.0, -2.0, -1.5]), levelling_rotation(0.01, -0.02)
    heights = [1.0, 1.2, 4.0]  # the first two overlap: a point can be in both
    ground = Terrain(np.array([-30.0, -35.0]), 5.0, rng.uniform(-1, 1, (12, 14)), np.ones((12, 14)))
    args = (reduction, level, heights, 0.4, 0.1, ground, 200.0)
    fast, slow = slice_pass(pts, *args), slice_pass_numpy(pts, *args)
    for a, b in zip(fast.slices, slow.slices, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)
    assert fast.far == slow.far == int((np.linalg.norm(pts - reduction, axis=1) > 200.0).sum())
    assert fast.far > 10
    assert len(np.intersect1d(fast.slices[0][:, 0], fast.slices[1][:, 0])) > 0
    assert len(fast.grouped[0]) < len(pts)  # consecutive points in one voxel share a row
    t_fast, t_slow = VoxelThinner(0.1), VoxelThinner(0.1)
    t_fast.add_grouped(*fast.grouped)
    t_slow.add_grouped(*slow.grouped)
    np.testing.assert_allclose(t_fast.result(), t_slow.result(), atol=1e-9)
    lo, hi = bounds(pts)
    np.testing.assert_array_equal(lo, pts.min(axis=0))
    np.testing.assert_array_equal(hi, pts.max(axis=0))
    none = slice_pass(pts, reduction, level, heights, 0.4, 0.0, ground, 200.0)
    assert none.grouped is None
    assert all(np.array_equal(a, b) for a, b in zip(none.slices, fast.slices, strict=True))


def test_slices_are_cut_at_heights_above_the_ground_under_each_point():
    from ndt_cli.ndt.passes import slice_pass
    from ndt_cli.ndt.terrain import Terrain

    # ground at 0 m for x < 10 and at 2 m beyond; points 1 m above each, and one 1 m above
    # the plane z = 0 where the ground is at 2 m (it lies below the ground there)
    ground = Terrain(np.array([0.0, -10.0]), 10.0, np.array([[0.0], [2.0]]), np.ones((2, 1)))
    pts = np.array([[5.0, 0.0, 1.0], [15.0, 0.0, 3.0], [15.0, 1.0, 1.0], [25.0, 0.0, 3.1]])
    cut = slice_pass(pts, np.zeros(3), np.eye(3), [1.0], 0.4, 0.0, ground)
    np.testing.assert_array_equal(cut.slices[0], [[5.0, 0.0], [15.0, 0.0], [25.0, 0.0]])


@pytest.mark.parametrize("distinct", [50, 20_000])  # voxels between revisits: few, or evicted
def test_slice_pass_groups_revisited_voxels_like_its_numpy_twin(distinct):
    from ndt_cli.core.geometry import VoxelThinner
    from ndt_cli.ndt.passes import slice_pass, slice_pass_numpy

    rng = np.random.default_rng(11)
    line = rng.uniform([-40, -40, -2], [40, 40, 15], (distinct, 3))
    pts = np.vstack([line + rng.normal(0, 0.01, line.shape) for _ in range(4)])  # scan lines
    args = (np.zeros(3), np.eye(3), [1.0], 0.4, 0.1)
    grouped = slice_pass(pts, *args).grouped
    ref = slice_pass_numpy(pts, *args).grouped
    t_fast, t_slow = VoxelThinner(0.1), VoxelThinner(0.1)
    t_fast.add_grouped(*grouped)
    t_slow.add_grouped(*ref)
    np.testing.assert_allclose(t_fast.result(), t_slow.result(), rtol=0, atol=1e-9)
    n_voxels = len(np.unique(ref[0]))
    if distinct < 1000:  # the voxels of the line before are still known: about one row each
        assert len(grouped[0]) < 1.1 * n_voxels
    assert n_voxels <= len(grouped[0]) <= len(pts)


@pytest.mark.parametrize("shape", [(1, 2), (1000, 2), (777, 3), (50, 5)])
def test_column_bounds_are_the_axis_reductions(shape):
    from ndt_cli.core.arrays import column_bounds

    rng = np.random.default_rng(shape[0])
    floats = rng.normal(size=shape) * 1e3
    floats[rng.integers(0, shape[0]), 0] = np.nan if shape[0] > 1 else floats[0, 0]
    ints = rng.integers(-(2**40), 2**40, size=shape)
    for a in (floats, ints):
        lo, hi = column_bounds(a)
        np.testing.assert_array_equal(lo, a.min(axis=0))  # NaN where a column holds one
        np.testing.assert_array_equal(hi, a.max(axis=0))
        assert lo.dtype == a.dtype and hi.dtype == a.dtype
