"""The free-space check: what a scanner saw to be empty, and the pose it prefers. Expected values
come from geometry built by hand and from the simulator's true poses."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli import sim
from ndt_cli.config import Config
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import ConfigError
from ndt_cli.ndt.bnb import pixel_centres
from ndt_cli.ndt.coarse_to_fine import Ranked
from ndt_cli.ndt.prepare import prepare
from ndt_cli.ndt.register import register_prepared
from ndt_cli.ndt.result import RegistrationResult
from ndt_cli.ndt.search import search_field_of
from ndt_cli.ndt.visibility import (
    MARGIN,
    MIN_HEIGHT,
    RangeImage,
    Sight,
    free_at_heights,
    free_space_share,
    margin,
    scanner_inside,
)


def _room(half: float = 5.0, n: int = 200) -> np.ndarray:
    """Points on the four walls (0 to 3 m high) of a square room around the scanner."""
    rng = np.random.default_rng(0)
    s, z = rng.uniform(-half, half, 4 * n * n), rng.uniform(0.0, 3.0, 4 * n * n)
    side = np.repeat(np.arange(4), n * n)
    x = np.where(side == 0, half, np.where(side == 1, -half, s))
    y = np.where(side == 2, half, np.where(side == 3, -half, s))
    return np.column_stack([x, y, z])


def test_a_point_in_front_of_a_wall_conflicts_one_behind_it_or_unseen_does_not():
    img = RangeImage.of(_room())
    inside = np.array([[2.0, 0.3, 1.0], [-1.0, -3.0, 1.0]])  # well inside the 5 m room
    at_wall = np.array([[5.0 - 0.8 * MARGIN, 1.0, 1.5]])  # within the margin of the wall
    behind = np.array([[8.0, 0.5, 1.0], [-0.5, -9.0, 1.0]])  # beyond a wall: not seen there
    unseen = np.array([[0.5, 0.5, -3.0]])  # straight down: the room has no floor
    assert img.conflicts(inside) == (2, 2)
    assert img.conflicts(at_wall) == (0, 1)
    assert img.conflicts(behind) == (0, 2)
    assert img.conflicts(unseen) == (0, 0)
    near = np.array([[5.0 - 0.8, 1.0, 1.5]])  # 0.8 m in front of the wall
    assert img.conflicts(near, margin(0.1)) == (1, 1)
    assert img.conflicts(near, margin(1.0)) == (0, 1)  # coarse thinning: a wider margin


def test_the_share_is_symmetric_in_frames_and_zero_for_the_true_pose():
    room = _room()
    T = np.eye(4)  # the second scanner stands 1 m east, turned by 90 degrees
    T[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    T[:3, 3] = [1.0, 0.0, 0.0]
    second = (room - T[:3, 3]) @ T[:3, :3]  # the same walls in the second scanner's frame
    high = np.full(len(room), 2.0)
    a, b = Sight.of(room, high), Sight.of(second, high)
    assert free_space_share(a, b, T) == pytest.approx(0.0, abs=1e-3)
    wrong = T.copy()
    wrong[:3, 3] = [-3.0, 0.0, 0.0]  # 4 m off: a wall of the second scan lands inside the room
    assert free_space_share(a, b, wrong) > 0.1
    assert free_space_share(b, a, np.linalg.inv(wrong)) == pytest.approx(
        free_space_share(a, b, wrong)
    )


def test_only_points_above_the_ground_are_checked():
    room = _room()
    sight = Sight.of(room, room[:, 2] - 1.0)  # heights: 1 m below the scanner is the ground
    assert sight.checked[:, 2].min() > 1.5
    assert len(sight.image.ranges) == 360 * 120


def test_a_tilted_scan_is_checked_above_its_own_ground_and_in_its_own_frame():
    rng = np.random.default_rng(1)
    walls = _room() - [0.0, 0.0, 1.5]  # the scanner 1.5 m above the floor
    floor = np.column_stack([rng.uniform(-5, 5, (40_000, 2)), np.full(40_000, -1.5)])
    level = np.concatenate([walls, floor])
    a = np.radians(10.0)  # the scanner tilted by 10 degrees about x: the floor rises 0.9 m
    R = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])
    scan = level @ R.T
    sight = Sight.of_scan(prepare(scan, Config()))
    assert sight is not None
    height = (sight.checked @ R)[:, 2] + 1.5  # back in the untilted frame: above the floor
    assert height.min() > MIN_HEIGHT - 0.1  # 0.1 m: the voxel centroids of ICP's thinning
    assert len(sight.checked) > 1000
    inside = np.array([[2.0, 0.0, 0.0]]) @ R.T  # in the room, in the tilted scanner's frame
    assert sight.image.conflicts(inside) == (1, 1)
    assert Sight.of_scan(prepare(scan + np.array([6.0e5, 5.4e6, 0.0]), Config())) is None


def test_free_at_heights_places_each_slice_above_the_ground_of_a_tilted_scan():
    rng = np.random.default_rng(2)
    walls = _room() - [0.0, 0.0, 1.5]  # the scanner 1.5 m above the floor
    floor = np.column_stack([rng.uniform(-5, 5, (40_000, 2)), np.full(40_000, -1.5)])
    a = np.radians(8.0)
    R = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    scan = prepare(np.concatenate([walls, floor]) @ R.T, Config())

    def local_xy(x: float, y: float) -> np.ndarray:  # untilted, from the scanner -> reduced
        p = R @ np.array([x, y, 0.0])
        return (scan.to_local() @ np.append(p, 1.0))[:2]

    places = np.array([local_xy(2.0, 0.5), local_xy(8.0, 0.0), local_xy(4.8, -1.0)])
    free = free_at_heights(scan, places, [1.0, 2.0, 4.0])
    assert free is not None and free.shape == (3, 3)
    # in the room at 1 and 2 m: seen empty; 4 m up, the walls (3 m high) show nothing behind
    assert free[:, 0].tolist() == [True, True, False]
    assert not free[:, 1].any()  # beyond a wall
    assert not free[:, 2].any()  # within the margin of a wall
    far = np.concatenate([walls, floor]) + np.array([6.0e5, 5.4e6, 0.0])  # georeferenced
    assert free_at_heights(prepare(far, Config()), places, [1.0]) is None


def test_the_search_field_costs_free_space_only_when_asked_and_known():
    rng = np.random.default_rng(3)
    walls = _room() - [0.0, 0.0, 1.5]
    floor = np.column_stack([rng.uniform(-5, 5, (40_000, 2)), np.full(40_000, -1.5)])
    scan = prepare(np.concatenate([walls, floor]), Config())
    heights = Config().slices.heights
    plain = search_field_of(scan, 0.5, heights, 0.0)
    costly = search_field_of(scan, 0.5, heights, 2.0)
    assert plain.values.dtype == np.uint8 and costly.values.dtype == np.int16
    free = free_at_heights(scan, pixel_centres(plain), heights).reshape(plain.values.shape)
    cost = free & (plain.values == 0)
    assert cost[0].sum() > 100  # the room's inside, 1 m up
    np.testing.assert_array_equal(costly.values[cost], -2 * 255)
    np.testing.assert_array_equal(costly.values[~cost], plain.values[~cost])
    assert search_field_of(scan, 0.5, heights[:2], 2.0).values.dtype == np.uint8
    away = prepare(np.concatenate([walls, floor]) + np.array([6.0e5, 5.4e6, 0.0]), Config())
    assert search_field_of(away, 0.5, heights, 2.0).values.dtype == np.uint8


def test_a_prepared_scan_builds_its_sight_once_and_ships_it_with_itself():
    import pickle

    scan = prepare(_room() - [0.0, 0.0, 1.5], Config())
    sight = scan.sight
    assert sight is scan.sight  # built once
    direct = Sight.of_scan(scan)
    assert direct is not None and sight is not None
    np.testing.assert_array_equal(sight.image.ranges, direct.image.ranges)
    np.testing.assert_array_equal(sight.checked, direct.checked)
    copy = pickle.loads(pickle.dumps(scan))  # as a chain's worker receives it
    assert "sight" in vars(copy)  # travels with the scan: not rebuilt by the link
    np.testing.assert_array_equal(copy.sight.image.ranges, direct.image.ranges)
    np.testing.assert_array_equal(copy.sight.checked, direct.checked)


def test_the_origin_must_lie_inside_the_scan():
    room = _room()
    assert scanner_inside(room)
    assert not scanner_inside(room + np.array([500_000.0, 5_400_000.0, 0.0]))  # georeferenced
    floor = np.column_stack([np.random.default_rng(1).uniform(-5, 5, (4000, 2)), np.zeros(4000)])
    floor = floor[np.hypot(floor[:, 0], floor[:, 1]) > 0.5]  # the scanner's own blind spot
    both = np.vstack([room, floor])
    sector = both[(both[:, 0] > 0.0) & (np.abs(both[:, 1]) < both[:, 0])]  # a 90 degree sector
    assert sector[:, 0].min() > 0.0 and scanner_inside(sector)  # its apex is the scanner
    assert not scanner_inside(sector + np.array([5.0, 0.0, 0.0]))  # 5 m beyond its edge


def test_promoting_a_candidate_keeps_the_ambiguity_below_one():
    ranked = Ranked(
        np.arange(9.0).reshape(3, 3),
        np.array([5.0, 4.0, 1.0]),
        np.array([3, 2.7, 1]),
        np.array([True, False, True]),
    )
    second = ranked.promote(1)
    assert second.poses[0].tolist() == [3.0, 4.0, 5.0]
    assert second.evidence.tolist() == [2.7, 3.0, 1.0]
    assert second.converged.tolist() == [False, True, True]
    assert second.ambiguity == pytest.approx(ranked.ambiguity) == pytest.approx(0.9)


@pytest.mark.parametrize("ratio", [0.5, 0.999])
def test_a_ratio_between_zero_and_one_is_refused_by_name(ratio):
    with pytest.raises(ConfigError, match=r"'search\.free_space_ratio'"):
        Config().replace(search={"free_space_ratio": ratio})


@pytest.fixture(scope="module")
def far_link():
    """Scans 1 and 3 of a simulated street (34-48 m apart): NDT's evidence ranks a wrong pose
    first, the true pose second."""
    _, scans, poses = sim.make_sequence(
        seed=115, n_scans=4, spacing=(17.0, 24.0), scan_kwargs={"n_azimuth": 1000}
    )
    truth = np.linalg.inv(poses[1]) @ poses[3]
    return scans[1], scans[3], truth


def _register(target: np.ndarray, source: np.ndarray, cfg: Config) -> RegistrationResult:
    return register_prepared(prepare(target, cfg), prepare(source, cfg), cfg)


def _right(T: np.ndarray, truth: np.ndarray) -> bool:
    rot, trans = transform_errors(T, truth)
    return rot < 0.3 and trans < 0.15


@pytest.mark.slow
def test_free_space_corrects_a_far_link_that_evidence_gets_wrong(far_link):
    target, source, truth = far_link
    off_cfg = Config().replace(search={"free_space_ratio": 0.0})
    off = _register(target, source, off_cfg)
    assert not _right(off.T_target_source, truth), "NDT alone is right here: pick another link"
    on = _register(target, source, Config())
    assert _right(on.T_target_source, truth)
    assert on.status.value == "ok", on.warnings  # the kept pose is free of contradiction
    assert any(w.startswith("free space: the pose of most evidence") for w in on.notes)
    assert on.free_space < 0.05 and on.free_space_around < 0.005  # the kept pose is clean,
    assert on.free_space_second > 0.05  # the one given up is not
    first, second = on.candidates[0].evidence, on.candidates[1].evidence
    assert first < second  # the kept pose is not the one of most evidence
    assert on.ambiguity == pytest.approx(first / second)
    offset = np.array([500_000.0, 5_400_000.0, 100.0])  # georeferenced: nothing to check
    geo = _register(target + offset, source + offset, Config())
    geo_off = _register(target + offset, source + offset, off_cfg)
    assert not any(w.startswith("free space") for w in geo.warnings + geo.notes)
    assert np.isnan(geo.free_space) and np.isnan(geo_off.free_space)
    np.testing.assert_array_equal(geo.T_target_source, geo_off.T_target_source)  # skipped
    back = np.linalg.inv(_shift(offset)) @ geo.T_target_source @ _shift(offset)
    assert not _right(back, truth)  # the pose of most evidence, wrong: and not vouched for,
    assert not geo.ok and not off.ok  # the slices' fit judged as strictly as the gate can
    assert any("free space not checkable" in w for w in geo.warnings)


def _shift(offset: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = offset
    return T


def _ceiling_scan(height: float, reach: float, step_deg: float = 0.5) -> np.ndarray:
    """Points a scanner at the origin measures on a ceiling ``height`` m above it, out to
    ``reach`` m horizontally: rays on a regular grid of azimuths and elevations."""
    az = np.radians(np.arange(0.0, 360.0, step_deg))
    el = np.radians(np.arange(step_deg, 90.0, step_deg))
    a, e = (g.ravel() for g in np.meshgrid(az, el))
    r = height / np.sin(e)
    keep = r * np.cos(e) < reach
    return (
        np.column_stack([np.cos(a) * np.cos(e), np.sin(a) * np.cos(e), np.sin(e)])[keep]
        * r[keep, None]
    )


def test_a_surface_seen_at_a_grazing_angle_does_not_contradict_itself():
    """A ceiling 1.4 m above two scanners 15 m apart: each sees the other's part of it at
    grazing angles, where one bin's nearest range lies metres behind a point of the same
    ceiling seen from elsewhere; only the bins around it hold the nearer part."""
    a = _ceiling_scan(1.4, 25.0)
    b = _ceiling_scan(1.4, 25.0) + np.array([15.0, 0.0, 0.0])  # the second, in the first's frame
    img = RangeImage.of(a)
    bad, seen = img.conflicts(b)
    assert seen > 1000 and bad == 0
    raw = RangeImage(img.ranges, img.n_az, img.n_el, img.ranges)  # each bin alone
    assert raw.conflicts(b)[0] > 0.001 * seen
    hanging = np.array([[6.0, y, 0.9] for y in np.linspace(-2.0, 2.0, 9)])  # the scanner saw
    assert img.conflicts(hanging)[0] == 9  # the ceiling 9.5 m away through these points


def test_the_guard_is_the_smallest_range_of_each_bin_and_its_neighbours():
    rng = np.random.default_rng(4)
    pts = rng.normal(0.0, 10.0, (5000, 3))
    img = RangeImage.of(pts)
    grid = img.ranges.reshape(img.n_az, img.n_el)
    guard = img.guard.reshape(img.n_az, img.n_el)
    for a, e in zip(rng.integers(0, img.n_az, 300), rng.integers(0, img.n_el, 300), strict=True):
        if not np.isfinite(grid[a, e]):
            assert guard[a, e] == np.inf  # a direction never measured stays unmeasured
            continue
        around = [
            grid[(a + da) % img.n_az, e + de]
            for da in (-1, 0, 1)
            for de in (-1, 0, 1)
            if 0 <= e + de < img.n_el
        ]
        assert guard[a, e] == min(around)
