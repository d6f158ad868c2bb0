"""The street scanner simulator that makes the sample data and the test scenes."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli import sim
from ndt_cli.core.transforms import apply

SMALL = {"n_azimuth": 360, "n_elevation": 60}


@pytest.fixture(scope="module")
def street():
    return sim.make_street(seed=3)


def test_same_seed_same_scan_other_seed_other_scan():
    a = sim.make_sequence(seed=4, n_scans=2, scan_kwargs=SMALL)
    b = sim.make_sequence(seed=4, n_scans=2, scan_kwargs=SMALL)
    c = sim.make_sequence(seed=5, n_scans=2, scan_kwargs=SMALL)
    assert all(np.array_equal(x, y) for x, y in zip(a[1], b[1], strict=True))
    assert all(np.array_equal(x, y) for x, y in zip(a[2], b[2], strict=True))
    assert not np.array_equal(a[2][1], c[2][1])


def test_points_are_in_the_scanner_frame(street):
    T = sim.scanner_pose(5.0, 1.0, 40.0, height=1.6)
    pts = sim.simulate_scan(street, T, **SMALL, range_noise=0.0)
    assert len(pts) > 1000
    world = apply(T, pts)
    on_ground = np.abs(world[:, 2]) < 0.01
    assert on_ground.mean() > 0.2  # a large share of the scan is the ground at world z = 0
    assert np.median(pts[on_ground, 2]) == pytest.approx(-1.6, abs=0.01)  # scanner frame: z = -h
    assert np.any(world[:, 2] > 8.0)  # facades above the ground floor are seen


def test_no_point_lies_inside_a_box(street):
    T = sim.scanner_pose(-20.0, -2.0, 10.0)
    world = apply(T, sim.simulate_scan(street, T, **SMALL, range_noise=0.0))
    lo, hi = street.boxes_min, street.boxes_max
    inside = np.zeros(len(world), dtype=bool)
    for a, b in zip(lo, hi, strict=True):
        inside |= np.all((world > a + 1e-6) & (world < b - 1e-6), axis=1)
    assert not inside.any()


def test_range_noise_has_the_requested_spread(street):
    T = sim.scanner_pose(0.0, 0.0, 0.0)
    exact = sim.simulate_scan(street, T, **SMALL, range_noise=0.0)
    noisy = sim.simulate_scan(street, T, **SMALL, range_noise=0.008, seed=1)
    dr = np.linalg.norm(noisy, axis=1) - np.linalg.norm(exact, axis=1)
    assert np.std(dr) == pytest.approx(0.008, rel=0.1)


def test_tilt_changes_scanner_points_not_the_world(street):
    level = sim.scanner_pose(0.0, 0.0, 0.0)
    tilted = sim.scanner_pose(0.0, 0.0, 0.0, roll_deg=0.5, pitch_deg=-0.4)
    w_level = apply(level, sim.simulate_scan(street, level, **SMALL, range_noise=0.0))
    pts_tilted = sim.simulate_scan(street, tilted, **SMALL, range_noise=0.0)
    w_tilted = apply(tilted, pts_tilted)
    ground_scan = pts_tilted[np.abs(w_tilted[:, 2]) < 0.01]
    # in the tilted scanner frame the ground is a tilted plane; in the world it is flat
    slope = np.linalg.lstsq(
        np.c_[ground_scan[:, :2], np.ones(len(ground_scan))], ground_scan[:, 2], rcond=None
    )[0][:2]
    assert np.degrees(np.abs(slope)).max() > 0.3
    assert np.abs(w_tilted[np.abs(w_tilted[:, 2]) < 0.05, 2]).max() < 0.05
    assert np.abs(np.median(w_level[:, 2]) - np.median(w_tilted[:, 2])) < 0.5


def test_corridor_facades_have_no_gaps():
    scene = sim.make_street(seed=1, corridor=True)
    T = sim.scanner_pose(0.0, 0.0, 0.0)
    world = apply(T, sim.simulate_scan(scene, T, n_azimuth=720, n_elevation=40, range_noise=0.0))
    level = world[np.abs(world[:, 2] - 2.0) < 0.3]
    for side in (1, -1):
        wall = level[np.sign(level[:, 1]) == side]
        xs = np.sort(wall[np.abs(wall[:, 0]) < 40, 0])
        assert len(xs) > 50 and np.diff(xs).max() < 2.0  # continuous facade along the street
    assert len(scene.cylinders) == 0


def test_scene_is_deterministic_in_its_seed():
    assert sim.make_street(seed=3) == sim.make_street(seed=3)
    assert sim.make_street(seed=3) != sim.make_street(seed=4)
    assert sim.make_street(seed=3, corridor=True) == sim.make_street(3, corridor=True)
    a, b = sim.make_street(seed=3), sim.make_street(seed=4)
    assert not np.array_equal(a.boxes_min[:10], b.boxes_min[:10])


def test_noise_seed_changes_the_points_and_only_the_noise(street):
    T = sim.scanner_pose(2.0, -1.0, 15.0)
    a = sim.simulate_scan(street, T, **SMALL, seed=1)
    b = sim.simulate_scan(street, T, **SMALL, seed=1)
    c = sim.simulate_scan(street, T, **SMALL, seed=2)
    assert np.array_equal(a, b)
    assert a.shape == c.shape and not np.array_equal(a, c)
    # same rays: the directions agree, only the ranges differ (by the noise)
    ua = a / np.linalg.norm(a, axis=1, keepdims=True)
    uc = c / np.linalg.norm(c, axis=1, keepdims=True)
    assert np.abs(ua - uc).max() < 1e-9


def test_scan_sees_facades_between_4_and_12_m(street):
    T = sim.scanner_pose(-5.0, 0.5, 70.0)
    world = apply(T, sim.simulate_scan(street, T, **SMALL))
    high = world[(world[:, 2] > 4.0) & (world[:, 2] < 12.0)]
    assert len(high) > 500
    # they are facades: at or behind the facade lines y = +-9 m (protrusions up to 0.6 m)
    assert np.mean(np.abs(high[:, 1]) > 8.3) > 0.95
    assert (high[:, 1] > 0).any() and (high[:, 1] < 0).any()


def test_occluder_casts_a_shadow_on_the_wall_behind_it():
    wall = ([20.0, -30.0, 0.0], [21.0, 30.0, 15.0])
    post = ([5.0, -1.0, 0.0], [6.0, 1.0, 3.0])
    T = sim.scanner_pose(0.0, 0.0, 0.0)
    kw = {"n_azimuth": 720, "n_elevation": 120, "range_noise": 0.0}
    open_scene = sim.Scene(np.array([wall[0]]), np.array([wall[1]]), np.zeros((0, 5)))
    blocked = sim.Scene(
        np.array([wall[0], post[0]]), np.array([wall[1], post[1]]), np.zeros((0, 5))
    )

    def shadow_region(points: np.ndarray) -> np.ndarray:
        on_wall = np.abs(points[:, 0] - 20.0) < 1e-6
        return on_wall & (np.abs(points[:, 1]) < 3.0) & (points[:, 2] > 2.0) & (points[:, 2] < 6.0)

    assert shadow_region(apply(T, sim.simulate_scan(open_scene, T, **kw))).sum() > 50
    seen = apply(T, sim.simulate_scan(blocked, T, **kw))
    assert not shadow_region(seen).any()
    assert (np.abs(seen[:, 0] - 5.0) < 1e-6).sum() > 50  # the post's front face is seen instead


@pytest.mark.slow
def test_tilted_scan_points_lie_on_the_scene_surfaces(street):
    eps = 1e-6
    tilted = sim.scanner_pose(8.0, 1.0, -30.0, roll_deg=3.0, pitch_deg=-2.0)
    pts = sim.simulate_scan(street, tilted, **SMALL, range_noise=0.0)

    def on_surface(world: np.ndarray) -> np.ndarray:
        near = (np.abs(world[:, 2]) < eps) | street.contains(world, margin=-eps)
        return near & ~street.contains(world, margin=eps)

    assert on_surface(apply(tilted, pts)).all()
    level = sim.scanner_pose(8.0, 1.0, -30.0)  # ignoring the tilt misplaces the points
    assert on_surface(apply(level, pts)).mean() < 0.5


def test_corridor_is_gapless_and_uniform_but_the_street_has_gaps():
    def facade_coverage_holes(scene: sim.Scene, side: int, x_lo: float, x_hi: float) -> float:
        lo, hi = scene.boxes_min, scene.boxes_max
        front = (side * lo[:, 1] > 8.0) if side > 0 else (side * hi[:, 1] > 8.0)
        tall = hi[:, 2] > 5.0
        spans = np.c_[lo[front & tall, 0], hi[front & tall, 0]]
        xs = np.arange(x_lo, x_hi, 0.25)
        covered = ((xs[:, None] >= spans[:, 0]) & (xs[:, None] <= spans[:, 1])).any(axis=1)
        return float((~covered).mean())

    corridor = sim.make_street(seed=2, corridor=True)
    street = sim.make_street(seed=2)
    for side in (1, -1):
        assert facade_coverage_holes(corridor, side, -250.0, 250.0) == 0.0
    assert max(facade_coverage_holes(street, s, -130.0, 130.0) for s in (1, -1)) > 0.02
    # uniform along x: every corridor box spans the whole street (and beyond)
    assert (corridor.boxes_min[:, 0] <= -200.0).all() and (corridor.boxes_max[:, 0] >= 200.0).all()
    assert len(street.cylinders) > 0 and len(corridor.cylinders) == 0


def test_sequence_standpoints_follow_the_street():
    scene, scans, poses = sim.make_sequence(
        seed=11, n_scans=4, tilt_deg=2.0, scan_kwargs={"n_azimuth": 90, "n_elevation": 20}
    )
    assert len(scans) == len(poses) == 4
    t = np.array([T[:3, 3] for T in poses])
    assert np.all((np.diff(t[:, 0]) >= 13.0) & (np.diff(t[:, 0]) <= 30.0))
    assert np.all(np.abs(t[:, 1]) <= 3.0) and np.allclose(t[:, 2], 1.6)
    for T in poses:
        R = T[:3, :3]
        assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
        assert np.allclose(T[3], [0, 0, 0, 1])
        assert 0.0 < np.degrees(np.arccos(np.clip(R[2, 2], -1, 1))) < 2.0 * np.sqrt(2) + 1e-9
    yaws = [np.degrees(np.arctan2(T[1, 0], T[0, 0])) for T in poses]
    assert len(set(np.round(yaws, 6))) == 4
    assert len(scene.boxes_min) > 100


def test_default_scan_density_and_range(street):
    T = sim.scanner_pose(0.0, 0.0, 0.0)
    pts = sim.simulate_scan(street, T)
    assert 100_000 <= len(pts) <= 300_000
    assert np.linalg.norm(pts, axis=1).max() < 120.0 + 0.1


def test_scanner_inside_an_object_is_refused(street):
    centre = 0.5 * (street.boxes_min[0] + street.boxes_max[0])
    with pytest.raises(ValueError, match="inside"):
        sim.simulate_scan(street, sim.scanner_pose(*centre[:2], 0.0, height=centre[2]), **SMALL)


# --- varied worlds: sloped and cambered ground, turned streets, crowns, people and traffic ---


def _first_crossing(ground: sim.Ground, origin: np.ndarray, d: np.ndarray) -> float:
    """Where a ray first crosses the ground, by fine steps and bisection (no algebra)."""
    ts = np.linspace(0.0, 300.0, 30001)
    p = origin + ts[:, None] * d
    gap = ground.z(p[:, 0], p[:, 1]) - p[:, 2]
    after = np.flatnonzero(gap >= 0.0)
    if not len(after):
        return np.inf
    lo, hi = ts[after[0] - 1], ts[after[0]]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        q = origin + mid * d
        lo, hi = (mid, hi) if ground.z(q[0], q[1]) - q[2] < 0 else (lo, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize(
    "ground",
    [
        sim.Ground(grade=0.08),
        sim.Ground(grade=-0.03, cross_fall=0.02, curve=0.0005, crown=-0.006),
        sim.Ground(curve=-0.001),
        sim.Ground(grade=0.04, curve=0.001),
    ],
)
def test_ray_ground_crossing_matches_a_marched_ray(ground):
    rng = np.random.default_rng(1)
    origin = np.array([3.0, -2.0, float(ground.z(3.0, -2.0)) + 1.6])
    d = rng.normal(size=(40, 3))
    d[:, 2] = -np.abs(d[:, 2]) * rng.uniform(0.02, 1.0, 40)  # many grazing rays
    d[30:, 2] = rng.uniform(0.0, 0.03, 10)  # and some rising: a sag or a rising road meets them
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = ground.hit(origin, d)
    for k in range(len(d)):
        marched = _first_crossing(ground, origin, d[k])
        if np.isfinite(marched):
            assert t[k] == pytest.approx(marched, abs=1e-6)
        else:
            assert t[k] > 300.0  # beyond the marched stretch


def test_a_turned_street_on_a_slope_is_scanned_on_its_surfaces():
    ground = sim.Ground(grade=0.06, cross_fall=-0.02, crown=-0.005)
    scene = sim.make_street(seed=3, origin=(40.0, -25.0), axis_deg=35.0, ground=ground)
    a = np.radians(35.0)
    xy = np.array([40.0, -25.0]) + 10.0 * np.array([np.cos(a), np.sin(a)])
    T = sim.scanner_pose(*xy, 20.0, float(ground.z(*xy)) + 1.6)
    world = apply(T, sim.simulate_scan(scene, T, **SMALL, range_noise=0.0))
    assert not scene.contains(world, margin=1e-6).any()  # nothing inside a (turned) box
    height = world[:, 2] - ground.z(world[:, 0], world[:, 1])
    assert height.min() > -1e-6  # nothing below the ground
    assert (np.abs(height) < 1e-6).mean() > 0.2  # and much of the scan on it
    along = (world[:, :2] - [40.0, -25.0]) @ [np.cos(a), np.sin(a)]
    across = (world[:, :2] - [40.0, -25.0]) @ [-np.sin(a), np.cos(a)]
    facade = (np.abs(np.abs(across) - 9.0) < 0.5) & (height > 2.0)
    assert facade.sum() > 200  # the facade lines run along the turned axis, 9 m from it
    assert np.ptp(along[facade]) > 60.0


def test_objects_that_reach_the_ground_reach_into_a_sloped_one():
    ground = sim.Ground(grade=0.08, crown=-0.006)
    scene = sim.make_street(seed=5, ground=ground)
    touching = scene.boxes_min[:, 2] < scene.boxes_max[:, 2] - 0.5
    for lo, hi in zip(scene.boxes_min[touching], scene.boxes_max[touching], strict=True):
        xs, ys = np.meshgrid([lo[0], hi[0]], [lo[1], hi[1]])
        if lo[2] < ground.z(xs, ys).max():  # an object standing on the ground
            assert lo[2] <= ground.z(xs, ys).min() + 1e-9
    poles = scene.cylinders
    assert np.all(poles[:, 3] < ground.z(poles[:, 0], poles[:, 1]))


def test_rays_into_a_crown_stop_at_the_depth_its_density_gives():
    density = 1.5
    crown = np.array([[10.0, 0.0, 1.6, 3.0, 3.0, 3.0, density]])
    scene = sim.Scene(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 5)), crowns=crown)
    T = sim.scanner_pose(0.0, 0.0, 0.0, height=1.6)
    pts = sim.simulate_scan(
        scene,
        T,
        n_azimuth=3600,
        n_elevation=21,
        elevation_range_deg=(-2.0, 2.0),
        range_noise=0.0,
        seed=3,
    )
    world = apply(T, pts)
    ahead = (np.abs(world[:, 1]) < 0.3) & (world[:, 2] > 1.0)  # rays through the centre
    depth = np.linalg.norm(world[ahead] - [0, 0, 1.6], axis=1) - 7.0  # past where they enter
    assert len(depth) > 100
    assert np.all((depth > -1e-9) & (depth < 6.0))
    # an exponential depth of mean 1/density, cut at the 6 m chord: its mean is known
    d = 6.0
    expected = 1 / density - d * np.exp(-density * d) / (1 - np.exp(-density * d))
    assert depth.mean() == pytest.approx(expected, rel=0.15)
    again = sim.simulate_scan(
        scene,
        T,
        n_azimuth=3600,
        n_elevation=21,
        elevation_range_deg=(-2.0, 2.0),
        range_noise=0.0,
        seed=4,
    )
    assert not np.array_equal(pts, again)  # foliage differs between scans


def test_street_world_poses_stand_on_the_ground_and_people_move():
    world = sim.StreetWorld(
        seed=2,
        n_scans=3,
        grade=0.05,
        camber=0.03,
        tilt_deg=0.8,
        people=12,
        traffic=2,
        rays=(360, 60),
    )
    scene, _, poses = sim.scan_street(world)
    for T in poses:
        above = T[2, 3] - scene.ground_z(T[0, 3], T[1, 3])
        assert 1.4 < above < 1.85
        tilt = np.degrees(np.arccos(T[2, 2]))
        assert tilt < 0.8 * np.sqrt(2) + 1e-9
    rng = np.random.default_rng(0)
    a = sim.passers_by(world, np.zeros(2), 0.0, rng)
    b = sim.passers_by(world, np.zeros(2), 0.0, rng)
    assert len(a.cylinders) == len(b.cylinders) == 12
    assert not np.allclose(a.cylinders, b.cylinders)
    compensated = sim.scan_street(
        sim.StreetWorld(seed=2, n_scans=2, compensated=True, tilt_deg=1.0, rays=(360, 60))
    )[2]
    assert all(np.degrees(np.arccos(T[2, 2])) < 0.0043 for T in compensated)
