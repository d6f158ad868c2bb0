"""The district simulator: a grid of blocks whose streets cross, walked round its ring and
through its middle street."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ndt_cli.core.transforms import apply
from ndt_cli.sim.campaigns import within_reach
from ndt_cli.sim.district import DistrictWorld, district_scene, scan_district, walk

SMALL = (300, 50)
WORLD = DistrictWorld(seed=4, heading_deg=30.0, grade=0.04, cross_fall=-0.02, rays=SMALL)


@pytest.fixture(scope="module")
def district():
    return scan_district(WORLD)


def _local(world: DistrictWorld, xy: np.ndarray) -> np.ndarray:
    """World (x, y) in the grid's frame."""
    a = np.radians(world.heading_deg)
    return xy @ np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


@pytest.mark.slow
def test_the_walk_goes_round_the_ring_and_through_the_middle_street(district):
    _, _, poses = district
    xy = _local(WORLD, np.array([T[:2, 3] for T in poses]))
    assert 34 <= len(xy) <= 38
    (X, Y), mid = np.multiply(WORLD.blocks, WORLD.pitch), WORLD.pitch[1]
    on_ring = (
        (np.abs(xy[:, 0]) < 3)
        | (np.abs(xy[:, 0] - X) < 3)
        | (np.abs(xy[:, 1]) < 3)
        | (np.abs(xy[:, 1] - Y) < 3)
    )
    middle = (np.abs(xy[:, 1] - mid) < 3) & (xy[:, 0] > 3) & (xy[:, 0] < X - 3)
    assert (on_ring | middle).all() and middle.sum() >= 5
    steps = np.hypot(*np.diff(xy, axis=0).T)
    assert steps.max() < WORLD.spacing + 2 * np.sqrt(8)  # every scan near the one before
    for corner in ((0, 0), (X, 0), (X, Y), (0, Y)):  # the walk turns at every corner
        assert np.hypot(*(xy - corner).T).min() < WORLD.spacing


def test_loops_close_a_scan_comes_back_near_an_earlier_one(district):
    _, _, poses = district
    xy = np.array([T[:2, 3] for T in poses])
    first_back = next(k for k in range(5, len(xy)) if np.hypot(*(xy[k] - xy[0])) < 6.0)
    assert first_back < len(xy) - 3  # the ring closes at its first scan, then the middle ...
    d = np.hypot(*(xy[-1] - xy[: first_back - 1]).T)
    assert d.min() < WORLD.spacing  # ... street ends near a scan of the ring's east side


def test_the_crossings_are_open_and_the_streets_run_at_the_grids_heading():
    scene = district_scene(WORLD)
    X, Y = np.multiply(WORLD.blocks, WORLD.pitch)
    cross = [(i, j) for i in (0, X / 2, X) for j in (0, Y / 2, Y)]
    u = np.linspace(-8.0, 8.0, 9)
    grid = np.array([(cx + a, cy + b) for cx, cy in cross for a in u for b in u])
    xy = WORLD.to_world(grid)
    z = WORLD.ground.z(xy[:, 0], xy[:, 1])
    for h in (0.5, 2.0, 6.0):  # nothing stands in any crossing
        assert not scene.contains(np.column_stack([xy, z + h])).any()
    yaw = np.degrees(np.unique(scene.boxes_yaw)) % 180.0
    assert np.allclose(np.sort(yaw), [30.0, 120.0])


@pytest.mark.slow
def test_points_lie_on_the_scenes_surfaces():
    exact = replace(WORLD, blocks=(1, 2), pitch=(44.0, 44.0), spacing=30.0, range_noise=0.0)
    scene, scans, poses = scan_district(exact)
    rng = np.random.default_rng(0)
    for pts, T in list(zip(scans, poses, strict=True))[::3]:
        p = apply(T, pts)
        height = p[:, 2] - WORLD.ground.z(p[:, 0], p[:, 1])
        assert height.min() > -1e-6 and (np.abs(height) < 1e-6).mean() > 0.2
        assert (height > 8.0).sum() > 50  # facades seen above the ground floor
        some = p[rng.choice(len(p), 3000, replace=False)]
        assert not within_reach(scene, T[:2, 3]).contains(some, margin=1e-6).any()


@pytest.mark.slow
def test_scanners_stand_on_the_sloping_ground_people_and_traffic_move(district):
    scene, _, poses = district
    for T in poses:
        assert 1.5 <= T[2, 3] - scene.ground_z(T[0, 3], T[1, 3]) <= 1.8
    busy = replace(WORLD, blocks=(1, 1), pitch=(44.0, 44.0), people=15, traffic=2, tilt_deg=1.0)
    scene, scans, poses = scan_district(busy)
    assert len(scans) == len(walk(busy)) >= 8
    assert _off_the_static_scene(scene, scans, poses) > 100  # people and cars
    assert _off_the_static_scene(*district) <= 5  # only the range noise's tail


def _off_the_static_scene(scene, scans, poses) -> int:
    """Points more than 0.3 m above the ground and 5 cm off every box and cylinder, of 2000
    drawn from each of (at most) five scans."""
    out, rng = 0, np.random.default_rng(1)
    for pts, T in list(zip(scans, poses, strict=True))[:5]:
        p = apply(T, pts)
        p = p[p[:, 2] - scene.ground_z(p[:, 0], p[:, 1]) > 0.3]
        p = p[rng.choice(len(p), min(2000, len(p)), replace=False)]
        out += int((~within_reach(scene, T[:2, 3]).contains(p, margin=-0.05)).sum())
    return out


def test_a_district_is_deterministic_in_its_seed():
    small = DistrictWorld(seed=5, blocks=(1, 1), pitch=(44.0, 44.0), spacing=40.0, rays=(90, 20))
    a, b = scan_district(small), scan_district(small)
    c = scan_district(replace(small, seed=6))
    assert a[0] == b[0] and a[0] != c[0]
    assert all(np.array_equal(p, q) for p, q in zip(a[1], b[1], strict=True))
    assert all(np.array_equal(p, q) for p, q in zip(a[2], b[2], strict=True))
