"""The exact global search (branch and bound): bounds, brute force, twins, simulated streets.

Expected values come from an exhaustive search written here from the definitions in the
docstring of :mod:`ndt_cli.ndt.bnb` (not from the code under test), or from the simulator's
ground truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.core import threads
from ndt_cli.ndt import bnb, bnb_kernels
from ndt_cli.ndt.slicing import voxel_filter_2d


def _walls(rng: np.random.Generator, n: int = 300) -> list[np.ndarray]:
    """Two slices of noisy wall-like 2D points (metres) within about 30 m."""
    out = []
    for k in range(2):
        t = rng.uniform(-12, 12, n)
        side = rng.integers(0, 4, n)
        xy = np.select(
            [(side == c)[:, None] for c in range(4)],
            [
                np.column_stack([t, np.full(n, 4.0)]),
                np.column_stack([t, -5.0 + 0.8 * np.sin(t)]),
                np.column_stack([np.full(n, 8.0 + k), 0.4 * t]),
                np.column_stack([-3.0 + 0.3 * np.cos(3 * t), 2.0 + 0.1 * t]),  # a pole-ish blob
            ],
        )
        out.append(xy + rng.normal(0, 0.05, xy.shape))
    return out


def _moved(slices: list[np.ndarray], t: np.ndarray, yaw: float) -> list[np.ndarray]:
    """Source slices that the pose (t, yaw) maps onto ``slices``: R^T (x - t)."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s], [s, c]])
    return [(x - t) @ R for x in slices]


def brute_force(field: bnb.ScoreField, source: list[np.ndarray], window: float, yaw_step: float):
    """Every pose's score (n_yaw, 2n+1, 2n+1) int64, straight from the definitions."""
    res = field.resolution
    centre_s = np.median(np.concatenate(source), axis=0)
    n_yaw = int(np.ceil(2 * np.pi / yaw_step - 1e-9))
    n = int(np.floor(window / res + 1e-9))
    pad = 4 * n + 400
    vals = np.pad(field.values.astype(np.int64), ((0, 0), (pad, pad), (pad, pad)))
    scores = np.zeros((n_yaw, 2 * n + 1, 2 * n + 1), np.int64)
    for m in range(n_yaw):
        c, s = np.cos(2 * np.pi * m / n_yaw), np.sin(2 * np.pi * m / n_yaw)
        for k, sl in enumerate(source):
            x = voxel_filter_2d(sl, res) - centre_s
            p = np.column_stack([c * x[:, 0] - s * x[:, 1], s * x[:, 0] + c * x[:, 1]])
            q = np.floor((p + field.centre - n * res - field.origin) / res).astype(int) + pad
            for qx, qy in q:
                scores[m] += vals[k, qx : qx + 2 * n + 1, qy : qy + 2 * n + 1]
    return scores


def greedy(scores: np.ndarray, k: int, r2_same: int, yaw_same: int) -> list[tuple[int, ...]]:
    """The first ``k`` picks (score, m, i, j) of greedy suppression over all positive poses."""
    n_yaw = scores.shape[0]
    m, i, j = np.nonzero(scores > 0)
    order = np.lexsort((j, i, m, -scores[m, i, j]))
    picks: list[tuple[int, ...]] = []
    for o in order:
        cand = (int(scores[m[o], i[o], j[o]]), int(m[o]), int(i[o]), int(j[o]))
        if all(
            (cand[2] - p[2]) ** 2 + (cand[3] - p[3]) ** 2 > r2_same
            or min(abs(cand[1] - p[1]), n_yaw - abs(cand[1] - p[1])) > yaw_same
            for p in picks
        ):
            picks.append(cand)
            if len(picks) == k:
                break
    return picks


def _rows(found: bnb.GlobalSearch) -> list[tuple[int, ...]]:
    ints = np.rint(found.scores * bnb.FIELD_MAX).astype(np.int64)
    return [(int(s), *map(int, ix)) for s, ix in zip(ints, found.indices, strict=True)]


def test_max_pyramid_is_the_block_maximum():
    values = np.random.default_rng(0).integers(0, 256, (2, 13, 11)).astype(np.uint8)
    pyramid = bnb.max_pyramid(values, 3)
    for h in range(4):
        w = 1 << h
        for a in range(13):
            for b in range(11):
                expect = values[:, a : a + w, b : b + w].max(axis=(1, 2))
                np.testing.assert_array_equal(pyramid[h, :, a, b], expect)


@pytest.mark.parametrize(("sigma_px", "resolution"), [(1.0, 1.0), (0.7, 0.5), (1.6, 2.0)])
def test_likelihood_field_is_the_gaussian_of_the_distance_transform(sigma_px, resolution):
    """Against scipy's exact Euclidean distance transform: 255 on a target pixel, 255
    exp(-d^2 / 2 sigma^2) rounded at the distance d to the nearest one; an empty slice and a
    slice of one point included."""
    from scipy import ndimage

    rng = np.random.default_rng(7)
    slices = [*_walls(rng, 200), np.zeros((0, 2)), np.array([[3.2, -4.9]])]
    field = bnb.likelihood_field(slices, resolution=resolution, sigma_px=sigma_px)
    assert field.values.shape[0] == len(slices)
    for k, s in enumerate(slices):
        held = np.zeros(field.values.shape[1:], bool)
        lo = np.rint(field.origin / resolution).astype(np.int64)  # origin: whole pixels
        ij = np.floor(s / resolution).astype(np.int64) - lo
        held[ij[:, 0], ij[:, 1]] = True
        if not held.any():
            assert not field.values[k].any()
            continue
        d = ndimage.distance_transform_edt(~held)
        expect = np.rint(255 * np.exp(-0.5 * (d / sigma_px) ** 2)).astype(np.uint8)
        np.testing.assert_array_equal(field.values[k], expect)
        assert (field.values[k][held] == 255).all()
        border = np.concatenate([expect[0], expect[-1], expect[:, 0], expect[:, -1]])
        assert not border.any()  # the margin holds the whole fall-off


@pytest.mark.parametrize("seed", [1, 2])
def test_node_bound_covers_every_translation_of_its_block(seed):
    rng = np.random.default_rng(seed)
    target = _walls(rng)
    field = bnb.likelihood_field(target)
    field = bnb.ScoreField(  # random values: the bound must hold for any field
        rng.integers(0, 256, field.values.shape).astype(np.uint8),
        field.origin,
        field.resolution,
        field.centre,
    )
    source = _moved(_walls(rng, 100), np.array([0.5, -0.3]), 0.3)
    step = np.radians(15.0)
    grid = bnb.search_grid(field, source, window=7.0, yaw_step=step)
    lat, bases = bnb.lattice(field, grid, 2.0, 0.1)
    scores = brute_force(field, source, 7.0, step)
    for m in rng.choice(grid.n_yaw, 4, replace=False):
        for h in range(lat.top + 1):
            w = 1 << h
            for i0 in range(0, lat.last + 1, w):
                for j0 in range(0, lat.last + 1, w):
                    at = h * lat.level_size + bases[m] + i0 * lat.ny + j0
                    bound = lat.flat[at].astype(np.int64).sum()
                    block = scores[m, i0 : i0 + w, j0 : j0 + w]
                    assert bound >= block.max()
                    if h == 0:
                        assert bound == block[0, 0]


@pytest.mark.parametrize(
    ("seed", "k", "exclusion", "exclusion_deg", "window"),
    [
        (3, 1, 2.0, 6.0, 5.0),
        (4, 3, 2.0, 6.0, 5.0),
        (23, 5, 3.0, 20.0, 5.0),  # exact only with anchors twice the exclusion apart
        (36, 4, 2.0, 12.0, 5.0),  # likewise
        (6, 4, 0.0, 0.0, 5.0),  # every pose distinct: the 4 best leaves
        (10, 3, 2.0, 8.0, 10.0),  # 4 root blocks per yaw, 3 of them reaching past the window
    ],
)
def test_search_equals_brute_force(seed, k, exclusion, exclusion_deg, window):
    rng = np.random.default_rng(seed)
    target = _walls(rng)
    source = _moved(_walls(rng, 150), rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi))
    step = np.radians(4.0)
    field = bnb.likelihood_field(target)
    kw = {"window": window, "yaw_step": step, "candidates": k, "exclusion": exclusion}
    kw["exclusion_yaw"] = np.radians(exclusion_deg)
    scores = brute_force(field, source, window, step)
    expect = greedy(scores, k, int(exclusion**2 + 1e-9), int(exclusion_deg / 4.0 + 1e-9))
    assert len(expect) == k and expect[0][0] > 0
    for kernels in (bnb_kernels.NUMBA, bnb_kernels.NUMPY):
        found = bnb.search_field(field, source, kernels=kernels, **kw)
        assert _rows(found) == expect
        assert found.nodes < scores.size  # pruning happened


def _costly(field: bnb.ScoreField, rng: np.random.Generator, share: float, penalty: int):
    """The field with a random ``share`` of its pixels in free space, each costing ``penalty``."""
    free = rng.random(field.values.shape) < share
    return bnb.penalised(field, free, penalty), free


def test_a_penalised_field_costs_only_the_free_pixels_no_target_point_is_near():
    rng = np.random.default_rng(11)
    field = bnb.likelihood_field(_walls(rng))
    costly, free = _costly(field, rng, 0.3, 700)
    assert costly.values.dtype == np.int16
    cost = free & (field.values == 0)
    assert cost.any() and (free & (field.values > 0)).any()
    np.testing.assert_array_equal(costly.values[cost], -700)
    np.testing.assert_array_equal(costly.values[~cost], field.values[~cost])
    for bad in (-1, bnb.PENALTY_MAX + 1):
        with pytest.raises(ValueError, match="penalty"):
            bnb.penalised(field, free, bad)


@pytest.mark.parametrize(("seed", "share", "penalty"), [(12, 0.3, 255), (13, 0.6, 1020)])
def test_search_on_a_penalised_field_equals_brute_force(seed, share, penalty):
    rng = np.random.default_rng(seed)
    target = _walls(rng)
    source = _moved(_walls(rng, 150), rng.uniform(-2, 2, 2), rng.uniform(-np.pi, np.pi))
    step, window, k = np.radians(4.0), 5.0, 4
    field, _ = _costly(bnb.likelihood_field(target), rng, share, penalty)
    scores = brute_force(field, source, window, step)
    assert (scores < 0).any()  # the costs reach the search
    expect = greedy(scores, k, 4, 1)
    assert len(expect) == k and expect[0][0] > 0
    kw = {"window": window, "yaw_step": step, "candidates": k, "exclusion": 2.0}
    kw["exclusion_yaw"] = np.radians(4.0)
    for kernels in (bnb_kernels.NUMBA, bnb_kernels.NUMPY):
        found = bnb.search_field(field, source, kernels=kernels, **kw)
        assert _rows(found) == expect
        assert found.nodes < scores.size


def test_thread_counts_and_numpy_twin_agree_exactly():
    rng = np.random.default_rng(7)
    target = _walls(rng, 600)
    source = _moved(_walls(rng, 400), np.array([1.3, -2.2]), 2.5)
    kw = {"window": 8.0, "yaw_step": np.radians(3.0), "candidates": 3, "exclusion": 3.0}
    field = bnb.likelihood_field(target, resolution=0.5)
    runs = [bnb.search_field(field, source, kernels=bnb_kernels.NUMPY, **kw)]
    before = threads.threads()
    try:
        for n in (1, 2, 3):
            threads.set_threads(n)
            runs.append(bnb.search_field(field, source, **kw))
    finally:
        threads.set_threads(before)
    assert len(runs[0].scores) == 3 and runs[0].scores[0] > 0
    for other in runs[1:]:
        np.testing.assert_array_equal(other.poses, runs[0].poses)
        np.testing.assert_array_equal(other.scores, runs[0].scores)
        np.testing.assert_array_equal(other.indices, runs[0].indices)
        assert other.nodes == runs[0].nodes


def test_pose_convention_puts_the_source_centre_on_the_lattice():
    rng = np.random.default_rng(8)
    field = bnb.likelihood_field(_walls(rng))
    grid = bnb.search_grid(field, _walls(rng, 50), window=6.0, yaw_step=0.1)
    index = np.array([[0, 0, 0], [17, 3, 9], [grid.n_yaw - 1, 12, 12]])
    for (m, i, j), (tx, ty, yaw) in zip(index, grid.poses(index), strict=True):
        assert np.isclose(yaw % (2 * np.pi), 2 * np.pi * m / grid.n_yaw)
        c, s = np.cos(yaw), np.sin(yaw)
        landed = np.array([[c, -s], [s, c]]) @ grid.source_centre + (tx, ty)  # x_t = R x_s + t
        expect = grid.target_centre + (np.array([i, j]) - grid.half) * grid.resolution
        np.testing.assert_allclose(landed, expect, atol=1e-9)


def test_nothing_to_match_gives_no_candidates():
    rng = np.random.default_rng(9)
    empty = [np.zeros((0, 2)), np.zeros((0, 2))]
    for target, source in ((_walls(rng), empty), (empty, _walls(rng))):
        found = bnb.global_search(target, source, window=5.0, yaw_step=0.2)
        assert found.poses.shape == (0, 3) and found.ratio == 0.0
        assert "0 candidates" in repr(found)


_SCANS: dict[tuple, tuple] = {}


def _prepared(seed: int, n_scans: int, corridor: bool = False):
    """Prepared scans (reduced, levelled frames) and poses of a simulated sequence, cached."""
    key = (seed, n_scans, corridor)
    if key not in _SCANS:
        from ndt_cli import sim
        from ndt_cli.config import Config
        from ndt_cli.ndt.prepare import prepare

        kw = {"scan_kwargs": {"n_azimuth": 720}, "corridor": corridor}
        _, scans, poses = sim.make_sequence(seed=seed, n_scans=n_scans, **kw)
        _SCANS[key] = ([prepare(s, Config()) for s in scans], poses)
    return _SCANS[key]


def _truth(prepared, poses, i: int, j: int) -> np.ndarray:
    """(tx, ty, yaw) of scan j in scan i, in their reduced, levelled frames."""
    L = prepared[i].to_local() @ (np.linalg.inv(poses[i]) @ poses[j]) @ prepared[j].from_local()
    return np.array([L[0, 3], L[1, 3], np.arctan2(L[1, 0], L[0, 0])])


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_street_links_recover_the_truth(seed):
    prepared, poses = _prepared(seed, 3)
    for i, j in ((0, 1), (1, 2)):
        found = bnb.global_search(prepared[i].slices, prepared[j].slices, candidates=2)
        truth = _truth(prepared, poses, i, j)
        best = found.poses[0]
        assert np.all(np.abs(best[:2] - truth[:2]) <= found.resolution), (i, j, found)
        # the slices' own optimum lies a fraction of a step off the truth: the grid's nearest
        # heading to it can be one and a half steps away
        assert abs(bnb.wrap_angle(best[2] - truth[2])) <= 1.5 * found.yaw_step, (i, j, found)
        assert found.ratio < 1.0


def test_corridor_is_ambiguous():
    prepared, _ = _prepared(3, 2, corridor=True)
    found = bnb.global_search(prepared[0].slices, prepared[1].slices, candidates=2)
    assert found.ratio > 0.95, found
