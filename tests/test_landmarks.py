"""Landmarks of a scan, the triangles they make and the index that ranks which scans may
overlap. Expected landmarks are the objects the tests put there; expected triangles come from
an independent loop over every triple of points; expected neighbours from the simulator's
ground truth."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from ndt_cli import sim
from ndt_cli.config import Config
from ndt_cli.ndt import landmarks as lm
from ndt_cli.ndt.landmarks import KEY_STEP, LONGEST, SHORTEST, landmarks, triangle_keys
from ndt_cli.pipeline import links, placement
from ndt_cli.pipeline.candidates import (
    CANDIDATES,
    MIN_KEYS,
    WIDER,
    LandmarkIndex,
    next_tier,
    shortlists,
)
from ndt_cli.pipeline.discovery import Placed
from ndt_cli.pipeline.links import LinkStore
from ndt_cli.pipeline.tasks import prepare_scan, summarise_scan

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data"


def _post(rng: np.random.Generator, centre: tuple[float, float], r: float = 0.15) -> np.ndarray:
    """Points on the face of a round post (a trunk, a pole) of radius ``r`` m."""
    a = rng.uniform(0.0, 2.0 * np.pi, 40)
    return np.asarray(centre) + r * np.stack([np.cos(a), np.sin(a)], axis=1)


def _slice_with_posts(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A slice: a facade along y = 8 m, a parked car (4.5 x 1.8 m), a post 0.8 m from the
    facade (not alone) and five free-standing posts; the five posts' centres."""
    wall = np.stack([np.arange(-30.0, 30.0, 0.05), np.full(1200, 8.0)], axis=1)
    u, v = np.meshgrid(np.arange(0.0, 4.5, 0.1), np.arange(0.0, 1.8, 0.1))
    car = np.stack([u.ravel() + 5.0, v.ravel() + 3.0], axis=1)
    free = np.array([[-12.0, -4.0], [-3.0, 4.5], [2.0, -6.0], [14.0, 2.0], [20.0, -9.0]])
    posts = [_post(rng, tuple(c)) for c in free]
    crowded = _post(rng, (-20.0, 7.2))
    return np.concatenate([wall, car, crowded, *posts]), free


def test_landmarks_are_the_objects_standing_alone():
    rng = np.random.default_rng(1)
    cut, free = _slice_with_posts(rng)
    found = landmarks((cut, cut[::2] + 0.01))  # two slices of the same posts: merged
    assert len(found) == len(free), found
    for c in free:
        assert np.min(np.hypot(*(found - c).T)) < 0.05, c
    d = np.hypot(*found.T)
    assert np.all(np.diff(d) >= 0)  # nearest the scanner first


def _triangles_by_loop(points: np.ndarray) -> set[tuple[int, int, int]]:
    out = set()
    for a, b, c in itertools.combinations(range(len(points)), 3):
        sides = sorted(
            float(np.linalg.norm(points[i] - points[j])) for i, j in ((a, b), (b, c), (a, c))
        )
        if sides[0] >= SHORTEST and sides[2] <= LONGEST:
            out.add(tuple(int(np.floor(x / KEY_STEP)) for x in sides))
    return out


@pytest.mark.slow
def _alone_scipy(xy: np.ndarray) -> np.ndarray:
    """The landmarks of one slice as scipy finds them: its image labelled by
    ``ndimage.label``, boxes by ``find_objects``, points around by a k-d tree."""
    from scipy import ndimage
    from scipy.spatial import cKDTree

    ij = np.floor((xy - (xy.min(axis=0) - lm.CELL)) / lm.CELL).astype(np.int64)
    image = np.zeros(tuple(ij.max(axis=0) + 1), dtype=bool)
    image[ij[:, 0], ij[:, 1]] = True
    labels, n = ndimage.label(image, structure=np.ones((3, 3)))
    label = labels[ij[:, 0], ij[:, 1]]
    count = np.bincount(label, minlength=n + 1)[1:]
    centre = np.stack([np.bincount(label, xy[:, k], n + 1)[1:] for k in (0, 1)], axis=1)
    centre /= np.maximum(count, 1)[:, None]
    boxes = ndimage.find_objects(labels)
    wide = np.array([max(b[0].stop - b[0].start, b[1].stop - b[1].start) for b in boxes])
    wide = wide * lm.CELL
    small = (count >= lm.MIN_POINTS) & (wide <= lm.MAX_EXTENT)
    if not small.any():
        return np.zeros((0, 2))
    r = lm.ALONE + 0.5 * wide[small]
    around = cKDTree(xy).query_ball_point(centre[small], r, return_length=True)
    return centre[np.flatnonzero(small)[around == count[small]]]


@pytest.mark.parametrize("fill", [0.05, 0.3, 0.55, 0.8])
def test_cell_groups_are_scipy_s_8_connected_labels(fill):
    from scipy import ndimage

    rng = np.random.default_rng(int(fill * 100))
    image = rng.random((60, 45)) < fill
    image[:, 0] = image[:, -1] = False  # the first and last columns free, as the slices' are
    image[10:50, 20] = True  # a long wall through many small groups
    cells = np.flatnonzero(image)
    expected, _ = ndimage.label(image, structure=np.ones((3, 3)))
    got = lm.components(cells, image.shape[1])
    np.testing.assert_array_equal(got, expected.ravel()[cells] - 1)


def test_points_within_a_radius_are_those_a_k_d_tree_counts():
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(5)
    xy = np.concatenate([rng.uniform(-40, 25, (4000, 2)), rng.normal(3.0, 0.4, (500, 2))])
    centres = np.concatenate([rng.uniform(-45, 30, (300, 2)), xy[:50]])
    radius = rng.uniform(0.1, 2.5, len(centres))
    expected = cKDTree(xy).query_ball_point(centres, radius, return_length=True)
    np.testing.assert_array_equal(lm.points_within(xy, centres, radius), expected)


def test_a_real_scan_s_landmarks_are_those_scipy_finds():
    """The sample street's slices: every slice's landmarks equal scipy's, to 1e-9 m."""
    scan = prepare_scan(str(SAMPLE / "scan_00.laz"), Config())
    thin = [lm.voxel_filter_2d(np.reshape(s, (-1, 2)), lm.THIN) for s in scan.slices]
    found = 0
    for cut in thin:
        expected = _alone_scipy(cut)
        np.testing.assert_allclose(lm._alone(cut), expected, atol=1e-9)
        found += len(expected)
    assert found >= 5  # the street's posts and trunks


def test_triangle_keys_are_every_triangle_in_range_and_do_not_turn_with_the_scan():
    rng = np.random.default_rng(2)
    points = rng.uniform(-40.0, 40.0, (30, 2))
    keys = triangle_keys(points)
    assert {tuple(k) for k in keys.tolist()} == _triangles_by_loop(points)
    assert len(keys) > 50
    a = np.radians(137.0)
    turned = points @ np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]) + [55.0, -9.0]
    moved = {tuple(k) for k in triangle_keys(turned).tolist()}
    # the same triangles, each side within a step (a length on a step's edge may fall either way)
    assert len(moved) == len(keys)
    for k in keys:
        assert any(max(abs(k - np.array(m))) <= 1 for m in moved), k


@pytest.mark.slow
def test_the_index_ranks_first_the_scans_that_saw_the_same_objects():
    """Four scans of a field of posts, each seeing those within 30 m of it, in frames turned
    and moved at random, with 3 cm of noise: each ranks first the scan nearest it."""
    rng = np.random.default_rng(3)
    field = rng.uniform([0.0, -20.0], [160.0, 20.0], (120, 2))
    stands = np.array([[20.0, 0.0], [45.0, 2.0], [100.0, -1.0], [125.0, 0.0]])
    keys = {}
    for k, xy in enumerate(stands):
        seen = field[np.hypot(*(field - xy).T) < 30.0] - xy
        a = rng.uniform(0.0, 2.0 * np.pi)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        keys[k] = triangle_keys(seen @ R.T + rng.normal(0.0, 0.03, seen.shape))
    index = LandmarkIndex(keys)
    assert all(index.knows(k) for k in keys)
    assert index.ranked(0, range(4), 1) == [1]
    assert index.ranked(1, range(4), 1) == [0]
    assert index.ranked(2, range(4), 1) == [3]
    assert index.ranked(3, range(4), 1) == [2]


def test_a_scan_the_index_does_not_know_is_listed_with_every_scan():
    index = LandmarkIndex({0: np.zeros((0, 3), dtype=np.int64)})
    index.add(1, np.array([[10, 20, 30]]))
    assert not index.knows(0) and not index.knows(1)
    assert shortlists(index, [0, 1], [0, 1, 2, 3]) == {0: [1, 2, 3], 1: [0, 2, 3]}


def _tiered_index(sharers: int, strangers: int) -> LandmarkIndex:
    """Scan 0 with 100 triangles; scan i of 1..``sharers`` holds the first 100 - i of them
    (so the index ranks them 1, 2, 3, ...); then ``strangers`` scans sharing none."""
    mine = np.array([[10 * j + 5, 7, 9] for j in range(100)], dtype=np.int64)
    keys = {0: mine} | {i: mine[: 100 - i] for i in range(1, sharers + 1)}
    far = np.array([[5000 + 10 * j, 7, 9] for j in range(30)], dtype=np.int64)
    return LandmarkIndex(keys | {sharers + 1 + i: far for i in range(strangers)})


def test_a_scan_left_alone_is_matched_with_the_next_tier_by_rank_then_with_the_rest():
    """80 scans share triangles with scan 0 in a known order, 4 share none: scan 0 is listed
    with the first 16 by rank, then the next up to 64, then up to 256 (the 16 sharers left),
    then the 4 strangers; with all tried, not at all."""
    assert (CANDIDATES, *WIDER) == (16, 64, 256)
    index, every = _tiered_index(80, 4), list(range(85))
    tried: dict[int, list[int]] = {}
    tiers = []
    while lists := next_tier(index, [0], every, tried):
        tiers.append(lists[0])
        tried = {0: [*tried.get(0, []), *lists[0]]}
    assert tiers == [
        list(range(1, 17)),
        list(range(17, 65)),
        list(range(65, 81)),
        list(range(81, 85)),
    ]


def test_a_scan_the_index_does_not_know_is_matched_with_every_scan_at_once():
    index = LandmarkIndex({0: np.zeros((0, 3), dtype=np.int64)})
    assert next_tier(index, [0], [0, 1, 2, 3], {}) == {0: [1, 2, 3]}
    assert next_tier(index, [0], [0, 1, 2, 3], {0: [3, 1, 2]}) == {}
    assert next_tier(index, [0], [0, 1, 2, 3], {0: [1]}) == {0: [2, 3]}


def test_a_scan_is_alone_in_a_group_of_its_own_or_unplaced():
    where = {0: Placed(0, np.eye(4)), 1: Placed(0, np.eye(4)), 2: Placed(2, np.eye(4))}
    assert [placement.alone(s, where) for s in (0, 1, 2, 3)] == [False, False, True, True]


@pytest.mark.slow
def test_on_a_simulated_route_a_scan_s_neighbour_is_among_its_first_candidates(tmp_path):
    """Forty scans of a route (trees, people, cars, facades), each prepared as a campaign
    does: for nearly every scan, one of its two neighbours on the route is among the scans
    the index ranks first (:data:`CANDIDATES`), out of 39."""
    route = sim.route(seed=8, n_scans=40, rays=(1000, 120))
    files = sim.write_survey(route, tmp_path)
    cfg = Config()
    keys = {k: triangle_keys(landmarks(prepare_scan(f, cfg).slices)) for k, f in enumerate(files)}
    index = LandmarkIndex(keys)
    xy = np.array([P[:2, 3] for P in route.poses])
    found = 0
    for k in range(len(files)):
        d = np.hypot(*(xy - xy[k]).T)
        d[k] = np.inf
        neighbours = set(np.argsort(d)[:2].tolist())
        found += bool(neighbours & set(shortlists(index, [k], range(len(files)))[k]))
    assert CANDIDATES < 39 and found >= 0.9 * len(files), found


def test_a_scan_s_triangles_are_kept_with_its_summary_and_an_older_summary_has_none(tmp_path):
    value = summarise_scan(SAMPLE / "scan_00.laz", Config(), ship=False)
    assert len(value.sketch.keys) >= MIN_KEYS  # a real street's scan has landmarks
    store = LinkStore(tmp_path / "out")
    store.save_scan("k" * 40, value.preview, value.sketch, value.sample)
    _, sketch, _ = store.load_scan("k" * 40)
    assert np.array_equal(sketch.keys, value.sketch.keys)
    path = next((tmp_path / "out").rglob("scan_*.npz"))
    with np.load(path) as z:  # as an older run wrote it: without the triangles
        arrays = {n: z[n] for n in z.files if n not in (links.DIGEST, "keys")}
    np.savez(path, **arrays, **{links.DIGEST: np.array(links._array_digest(arrays))})
    _, older, _ = store.load_scan("k" * 40)
    assert older.keys.shape == (0, 3) and not LandmarkIndex({0: older.keys}).knows(0)
