"""A scan's vertical (from its walls, not its ground) and the ground model under it."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli import sim
from ndt_cli.core.transforms import levelling_rotation, rotation_from_vector
from ndt_cli.ndt.terrain import Terrain, height_offset, terrain_of
from ndt_cli.ndt.vertical import Patches, VerticalSource, vertical_of


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    cos = a @ b / np.linalg.norm(a) / np.linalg.norm(b)
    return float(np.degrees(np.arccos(np.clip(cos, -1, 1))))


def _plane(rng, origin, u, v, size, n):
    """``n`` points (1 cm noise along the normal) of a rectangle spanned by unit u, v."""
    a, b = rng.uniform(0, size[0], n), rng.uniform(0, size[1], n)
    normal = np.cross(u, v)
    return origin + a[:, None] * u + b[:, None] * v + rng.normal(0, 0.01, n)[:, None] * normal


def _yard(rng, slope=(0.06, -0.03), both_ways=True):
    """Walls on sloping ground, world frame (z the vertical): two facades along x, and (when
    ``both_ways``) two walls across them."""
    x, y, z = np.eye(3)
    parts = [  # at places no thinning grid lines up with
        _plane(rng, [-30, 9.137, -3], x, z, (60, 12), 40_000),
        _plane(rng, [-30, -8.953, -3], x, z, (60, 12), 40_000),
    ]
    if both_ways:
        parts += [
            _plane(rng, [-20.31, -9, -3], y, z, (18, 10), 15_000),
            _plane(rng, [25.173, -9, -3], y, z, (18, 10), 15_000),
        ]
    g = rng.uniform([-30, -9], [30, 9], (60_000, 2))
    ground = np.column_stack([g, slope[0] * g[:, 0] + slope[1] * g[:, 1] - 1.6])
    return np.vstack([*parts, ground + rng.normal(0, 0.01, ground.shape) * [0, 0, 1]])


def _tilted(points: np.ndarray, tilt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points as a scanner tilted by the rotation vector ``tilt`` sees them, and the true
    vertical in its frame."""
    R = rotation_from_vector(tilt)  # scanner axes in the world
    return points @ R, R.T @ [0.0, 0.0, 1.0]


@pytest.mark.parametrize("tilt_deg", [(0.0, 0.0), (0.7, -0.4), (-6.0, 4.0)])
def test_the_vertical_comes_from_the_walls_not_the_sloping_ground(tilt_deg):
    rng = np.random.default_rng(1)
    pts, truth = _tilted(_yard(rng), np.radians([*tilt_deg, 0.0]))
    v = vertical_of(Patches.of(pts))
    assert v.source is VerticalSource.STRUCTURES
    assert _angle(v.up, truth) < 0.03
    ground = vertical_of(Patches.of(pts), "ground")  # the ground's normal: 3.8 deg off
    assert ground.source is VerticalSource.GROUND and _angle(ground.up, truth) > 3.0
    assert vertical_of(Patches.of(pts), "scanner").up.tolist() == [0.0, 0.0, 1.0]


def test_walls_facing_one_way_leave_the_direction_along_them_to_the_ground():
    rng = np.random.default_rng(2)
    pts, truth = _tilted(_yard(rng, slope=(0.0, 0.05), both_ways=False), np.radians([0.5, 0.3, 0]))
    v = vertical_of(Patches.of(pts))
    assert v.source is VerticalSource.STRUCTURES_GROUND
    facing = rotation_from_vector(np.radians([0.5, 0.3, 0])).T @ [0.0, 1.0, 0.0]
    assert abs(v.up @ facing) < np.sin(np.radians(0.02))  # perpendicular to the walls
    assert _angle(v.up, truth) < 0.02  # and the ground is level along them here


def test_too_few_walls_leave_the_vertical_to_the_ground():
    rng = np.random.default_rng(3)
    g = rng.uniform(-30, 30, (50_000, 2))
    pts = np.column_stack([g, 0.02 * g[:, 0] - 1.6 + rng.normal(0, 0.01, len(g))])
    v = vertical_of(Patches.of(pts))
    assert v.source is VerticalSource.GROUND
    assert _angle(v.up, [-0.02, 0.0, 1.0]) < 0.05


@pytest.mark.slow
def test_simulated_sloping_streets_get_their_vertical_within_three_hundredths_of_a_degree():
    errors = []
    for seed, world in enumerate(
        [
            sim.StreetWorld(n_scans=3, grade=0.08, camber=0.03, tilt_deg=1.0),
            sim.StreetWorld(n_scans=3, grade=-0.05, curve=0.0004, cross_fall=0.02, tilt_deg=0.6),
        ]
    ):
        _, scans, poses = sim.scan_street(sim.StreetWorld(**{**vars(world), "seed": seed}))
        for pts, T in zip(scans, poses, strict=True):
            v = vertical_of(Patches.of(pts - np.median(pts, axis=0)))
            errors.append(_angle(v.up, T[:3, :3].T @ [0.0, 0.0, 1.0]))
    assert max(errors) < 0.03, errors


def _street_ground(rng, centre):
    """Points of a cambered, sloping street with cars and facades, in a levelled frame whose
    origin is ``centre`` (world x, y, z); the world ground is z = 0.04 x - 0.003 y^2."""

    def z(x, y):
        return 0.04 * x - 0.003 * y * y

    g = rng.uniform([-60, -9], [60, 9], (80_000, 2))
    ground = np.column_stack([g, z(g[:, 0], g[:, 1])])
    cars = []
    for cx in (-30.0, -5.0, 20.0):
        c = rng.uniform([cx, 4.0], [cx + 4.5, 5.8], (3000, 2))
        cars.append(np.column_stack([c, z(c[:, 0], c[:, 1]) + 1.45]))  # roofs only
    f = rng.uniform([-60, 0], [60, 12], (30_000, 2))
    facade = np.column_stack([f[:, 0], np.full(len(f), 9.0), z(f[:, 0], 9.0) + f[:, 1]])
    world = np.vstack([ground, *cars, facade])
    return world - centre, z


def test_the_ground_model_follows_the_street_and_leaves_out_car_roofs():
    rng = np.random.default_rng(4)
    centre = np.array([10.0, 1.0, 0.4])
    pts, z = _street_ground(rng, centre)
    t = terrain_of(pts)
    xy = rng.uniform([-50, -8], [50, 8], (2000, 2))
    truth = z(xy[:, 0] + centre[0], xy[:, 1] + centre[1]) - centre[2]
    err = t.at(xy) - truth
    assert np.abs(err).max() < 0.15  # a 2 m cell on a 4 % grade spans 8 cm
    assert abs(np.median(err)) < 0.05
    roofs = t.at(np.array([[-5.0 - centre[0] + 2.0, 5.0 - centre[1]]]))  # under a car
    assert roofs[0] - (z(-3.0, 5.0) - centre[2]) < 0.2
    behind = t.at(np.array([[0.0, 15.0]]))  # no ground behind the facade: the pavement's
    assert abs(behind[0] - (z(centre[0], 9.0) - centre[2])) < 0.3


def test_height_offset_of_two_scans_of_one_street_is_their_true_height_difference():
    rng = np.random.default_rng(5)
    a_centre, b_centre = np.array([-20.0, 0.0, -0.8]), np.array([15.0, 2.0, 0.6])
    a, _ = _street_ground(rng, a_centre)
    b, _ = _street_ground(rng, b_centre)
    yaw = np.radians(35.0)
    R = levelling_rotation(0.0, 0.0) @ np.array(
        [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
    )
    b_seen = b @ R  # scan b turned by -35 degrees about z
    ta, tb = terrain_of(a), terrain_of(b_seen)
    t_xy = (b_centre - a_centre)[:2]  # the planar pose from b's frame to a's
    tz = height_offset(ta, tb, np.array([*t_xy, yaw]))
    assert tz == pytest.approx(b_centre[2] - a_centre[2], abs=0.03)
    assert height_offset(Terrain.flat(), tb, np.zeros(3)) is None  # no measured ground


def _forest_patches(rng, slope_deg: float, tilt: np.ndarray) -> tuple[Patches, np.ndarray]:
    """Local planes of a forest plot as a scanner tilted by the rotation vector ``tilt`` sees
    them: 150 trunks (30 % leaning 1-6 degrees any way; bark rough by 1.2 degrees), 40 patches
    each, and ground patches sloping by ``slope_deg``; and the true vertical in the scanner's
    frame."""
    normals = []
    for k in range(150):
        lean = np.radians(rng.uniform(1.0, 6.0)) if k % 10 < 3 else 0.0
        axis = rotation_from_vector(np.array([lean, 0.0, 0.0])) @ [0.0, 0.0, 1.0]
        axis = rotation_from_vector(np.array([0.0, 0.0, rng.uniform(0, 2 * np.pi)])) @ axis
        e1 = np.cross(axis, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(axis, e1)
        t = rng.uniform(0, 2 * np.pi, 40)
        normals.append(np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)
    up = rotation_from_vector(np.radians([slope_deg, 0.0, 0.0])) @ [0.0, 0.0, 1.0]
    normals.append(np.tile(up, (3000, 1)))
    n = np.vstack(normals) + rng.normal(0, np.radians(1.2), (sum(map(len, normals)), 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    R = rotation_from_vector(tilt)
    n = n @ R  # the scanner's frame
    n *= np.where(n[:, 2] < 0, -1.0, 1.0)[:, None]
    return Patches(n, np.full(len(n), 0.95)), R.T @ [0.0, 0.0, 1.0]


def test_a_forest_slope_under_an_upright_scanner_does_not_tilt_its_vertical():
    """Leaning trunks make the structures unclean (their patches lean by more than 1 degree),
    so the ground's normal would be taken; on an 8.5 % slope (4.9 degrees) under a scanner
    within a degree of upright, the structures' vertical is kept. A level plot, or a scanner
    tilted 10 degrees (far from both), keeps the ground's, as before."""
    rng = np.random.default_rng(7)
    patches, truth = _forest_patches(rng, 4.86, np.radians([0.6, -0.5, 0.0]))
    assert vertical_of(patches, "structures").lean > 1.0  # the premise: unclean
    v = vertical_of(patches)
    assert v.source is VerticalSource.STRUCTURES and _angle(v.up, truth) < 0.3
    assert _angle(vertical_of(patches, "ground").up, truth) > 4.5
    level, truth = _forest_patches(rng, 0.0, np.radians([0.6, -0.5, 0.0]))
    assert vertical_of(level).source is VerticalSource.GROUND
    assert _angle(vertical_of(level).up, truth) < 0.1
    tilted, truth = _forest_patches(rng, 4.86, np.radians([10.0, 0.0, 0.0]))
    assert vertical_of(tilted).source is VerticalSource.GROUND
