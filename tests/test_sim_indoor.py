"""The interior simulator: floors of rooms, doors and furniture, scanned from corridors and
rooms."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.sim.indoor import FloorWorld, floor_scene, scan_floor

SMALL = (360, 60)


@pytest.fixture(scope="module", params=["double", "single", "open"])
def floor(request):
    world = FloorWorld(seed=4, layout=request.param, rays=SMALL)
    return world, *scan_floor(world)


def test_every_scan_stands_inside_under_the_ceiling_and_sees_it(floor):
    world, _scene, scans, poses = floor
    assert len(scans) >= 5
    for pts, T in zip(scans, poses, strict=True):
        x, _y, z = T[:3, 3]
        assert 0.0 < x < world.length and 1.4 < z < 1.8
        up = pts @ T[:3, :3].T + T[:3, 3]
        up = up[(pts[:, 2] / np.linalg.norm(pts, axis=1)) > np.sin(np.radians(45.0))]
        assert len(up) > 0.9 * SMALL[0] * 0.2  # every ray looking up returns ...
        on_ceiling = np.abs(up[:, 2] - world.ceiling) < 0.05  # ... from the ceiling, or
        assert on_ceiling.mean() > 0.8  # from a wall the scanner stands near


def test_points_lie_on_surfaces_not_inside_objects(floor):
    _, scene, scans, poses = floor
    for pts, T in zip(scans[:3], poses[:3], strict=True):
        world = pts @ T[:3, :3].T + T[:3, 3]
        assert not scene.contains(world, margin=0.03).any()


def test_room_sizes_repeat_along_the_corridor():
    world = FloorWorld(seed=2, rays=SMALL)
    _, plan = floor_scene(world)
    widths = np.array([r[1] - r[0] + 0.12 for r in plan.rooms]) / world.module
    whole = np.isclose(widths, np.round(widths), atol=1e-9)  # the last room of a side is not
    assert whole.sum() >= len(widths) - 2
    assert np.sum(np.isclose(widths, 1.0)) >= 4


def test_doors_are_open_and_closed_and_some_scans_stand_in_rooms():
    world = FloorWorld(seed=5, rays=SMALL, closed=0.4, room_scans=2)
    _scene, plan = floor_scene(world)
    is_open = [r[4] for r in plan.rooms]
    assert any(is_open) and not all(is_open)
    _, _, _scans, poses = (world, *scan_floor(world))
    inside_rooms = [abs(T[1, 3]) > world.corridor_width / 2 for T in poses]
    assert sum(inside_rooms) == 2


def test_the_floor_is_deterministic_in_its_seed():
    a = scan_floor(FloorWorld(seed=7, rays=SMALL))
    b = scan_floor(FloorWorld(seed=7, rays=SMALL))
    c = scan_floor(FloorWorld(seed=8, rays=SMALL))
    assert all(np.array_equal(p, q) for p, q in zip(a[1], b[1], strict=True))
    assert a[0] == b[0] and a[0] != c[0]
