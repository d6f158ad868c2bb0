"""The forest simulator: trunks of varied diameter, some leaning, on a slope, crowns, shrubs and
fallen logs, scanned on a grid or along a line."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from ndt_cli import sim
from ndt_cli.core.transforms import apply
from ndt_cli.sim.forest import ForestWorld, forest_scene, scan_forest

SMALL = (360, 60)
SLOPE, TOWARDS = 0.15, 125.0  # 15 % rising towards 125 degrees from +x


@pytest.fixture(scope="module")
def plot():
    world = ForestWorld(seed=3, slope=SLOPE, slope_deg=TOWARDS, leaning=0.5, rays=SMALL)
    scene, stand = forest_scene(world)
    _, scans, poses = scan_forest(world)
    return world, scene, stand, scans, poses


def _world_points(scans, poses):
    return [apply(T, pts) for pts, T in zip(scans, poses, strict=True)]


def _in_crown(scene, p: np.ndarray) -> np.ndarray:
    """Which points lie inside a (porous) crown or shrub."""
    inside = np.zeros(len(p), dtype=bool)
    for x, y, z, rx, ry, rz, _ in scene.crowns:
        inside |= (((p - (x, y, z)) / (rx, ry, rz)) ** 2).sum(axis=1) <= 1.0 + 1e-9
    return inside


@pytest.mark.slow
def test_points_lie_on_the_scenes_surfaces_or_in_its_foliage():
    world = ForestWorld(seed=5, slope=0.1, slope_deg=300.0, shape=(1, 2), rays=SMALL)
    scene, _ = forest_scene(world)
    exact = replace(world, range_noise=0.0)
    _, scans, poses = scan_forest(exact)
    eps = 1e-6
    for p in _world_points(scans, poses):
        on_ground = np.abs(p[:, 2] - scene.ground_z(p[:, 0], p[:, 1])) < eps
        on_solid = scene.contains(p, margin=-eps) & ~scene.contains(p, margin=eps)
        assert (on_ground | on_solid | _in_crown(scene, p)).all()
        assert not scene.contains(p, margin=eps).any()  # nothing inside a trunk or a log
        assert on_solid.sum() > 100 and on_ground.sum() > 0.2 * len(p)


@pytest.mark.slow
def test_the_ground_slopes_as_asked(plot):
    _, _, _, scans, poses = plot
    p = np.vstack(_world_points(scans, poses))
    _, cell = np.unique(np.floor(p[:, :2] / 2.0), axis=0, return_inverse=True)
    order = np.lexsort((p[:, 2], cell.ravel()))
    first = np.r_[True, np.diff(cell.ravel()[order]) != 0]
    g = p[order[first]]  # the lowest point of every 2 m cell
    scanners = np.array([T[:2, 3] for T in poses])
    near = np.hypot(*(g[:, None, :2] - scanners[None]).transpose(2, 0, 1)).min(axis=1) < 25.0
    g = g[near]  # where the ground is seen: farther, many cells hold only trunks and crowns
    A = np.column_stack([g[:, 0], g[:, 1], np.ones(len(g))])
    keep = np.ones(len(g), dtype=bool)
    for _ in range(6):  # least trimmed squares: the cells whose lowest point is not ground go
        coef, *_ = np.linalg.lstsq(A[keep], g[keep, 2], rcond=None)
        miss = np.abs(A @ coef - g[:, 2])
        keep = miss <= np.quantile(miss, 0.7)
    assert (miss < 0.03).mean() > 0.6  # most cells near a scanner see the ground
    gx, gy, _ = coef
    assert np.hypot(gx, gy) == pytest.approx(SLOPE, abs=0.002)
    assert np.degrees(np.arctan2(gy, gx)) == pytest.approx(TOWARDS, abs=1.0)


def test_trunks_are_0_1_to_0_8_m_thick_many_thin_few_thick(plot):
    _, scene, stand, _, _ = plot
    feet = stand.trunks[:, 2]
    assert feet.min() >= 0.1 and feet.max() <= 0.8
    assert np.median(feet) < 0.35 and (feet > 0.55).any() and (feet < 0.2).any()
    r = scene.cylinders[:, 2]  # every piece, tapering up the trunk to 0.6 of its foot
    assert r.min() >= 0.6 * 0.05 - 1e-12 and r.max() <= 0.4
    side = np.ptp(stand.stations, axis=0) + 2 * 40.0  # the plot: 40 m beyond the standpoints
    assert len(feet) / (side[0] * side[1] / 1e4) == pytest.approx(400, rel=0.25)


def _circle_centre(xy: np.ndarray) -> np.ndarray:
    """The centre of the circle through points (N, 2), by least squares (Kasa's fit)."""
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    sol, *_ = np.linalg.lstsq(A, (xy**2).sum(axis=1), rcond=None)
    return sol[:2]


def test_leaning_trunks_lean_as_asked(plot):
    """A close scan of thick leaning trunks (each alone): the centres of circles fitted to
    its points 1 m band by 1 m band climb along the lean asked for."""
    world, scene, stand, _, _ = plot
    lean, trunks = stand.trunks[:, 4], stand.trunks
    assert 0.35 < (lean > 0).mean() < 0.65 and lean[lean > 0].min() >= 1.0
    assert lean.max() <= world.lean_deg
    gap = np.hypot(*(trunks[:, None, :2] - trunks[None, :, :2]).transpose(2, 0, 1))
    alone = np.sort(gap, axis=1)[:, 1] > 3.0
    picked = np.flatnonzero((lean > 2.5) & (trunks[:, 2] > 0.35) & alone)[:4]
    assert len(picked) >= 3
    for k in picked:
        x, y, _, _, asked, towards = trunks[k]
        side = np.radians(towards + 90.0)  # look at it across its lean
        at = np.array([x, y]) + 5.0 * np.array([np.cos(side), np.sin(side)])
        T = sim.scanner_pose(*at, 0.0, float(world.ground.z(*at)) + 1.6)
        own = np.hypot(scene.cylinders[:, 0] - x, scene.cylinders[:, 1] - y) < 1.5
        alone_scene = sim.Scene(np.zeros((0, 3)), np.zeros((0, 3)), scene.cylinders[own])
        pts = sim.simulate_scan(
            alone_scene,
            T,
            n_azimuth=3600,
            n_elevation=120,
            elevation_range_deg=(-5.0, 60.0),
            range_noise=0.0,
        )
        p = apply(T, pts)
        up = p[:, 2] - world.ground.z(x, y)
        mine = (np.hypot(p[:, 0] - x, p[:, 1] - y) < 1.2) & (up > 2.0) & (up < 8.0)
        p = p[mine]
        bands = [p[np.floor(p[:, 2]) == z] for z in np.unique(np.floor(p[:, 2]))]
        bands = [b for b in bands if len(b) > 20]
        assert len(bands) >= 4
        centres = np.array([_circle_centre(b[:, :2]) for b in bands])
        z = np.array([b[:, 2].mean() for b in bands])
        slope = np.polyfit(z, centres, 1)[0]  # metres sideways per metre up, in x and y
        assert np.degrees(np.arctan(np.hypot(*slope))) == pytest.approx(asked, abs=0.5)
        direction = np.degrees(np.arctan2(slope[1], slope[0]))
        assert abs((direction - towards + 180.0) % 360.0 - 180.0) < 10.0


def test_shrubs_are_low_and_logs_lie_on_the_ground(plot):
    world, scene, _, _, _ = plot
    top = scene.crowns[:, 2] + scene.crowns[:, 5]
    ground = world.ground.z(scene.crowns[:, 0], scene.crowns[:, 1])
    shrubs = top - ground < 2.0
    assert shrubs.sum() > 100
    assert (scene.crowns[~shrubs, 2] - scene.crowns[~shrubs, 5] > ground[~shrubs] + 3.0).all()
    lo, hi = scene.boxes_min, scene.boxes_max
    assert len(lo) > 20 and len(np.unique(scene.boxes_yaw)) > 3
    c, s = np.cos(scene.boxes_yaw), np.sin(scene.boxes_yaw)
    u, v = 0.5 * (lo[:, 0] + hi[:, 0]), 0.5 * (lo[:, 1] + hi[:, 1])
    g = world.ground.z(c * u - s * v, s * u + c * v)  # the ground under each piece's centre
    assert (lo[:, 2] < g).all() and (hi[:, 2] - g <= 0.6 + 1e-9).all()
    assert (hi[:, 2] - g >= 0.2 - 1e-9).all()


def test_standpoints_on_a_grid_and_a_line_10_to_20_m_apart(plot):
    world, scene, stand, _, poses = plot
    xy = np.array([T[:2, 3] for T in poses])
    assert len(xy) == 9 and np.array_equal(xy, stand.stations)
    steps = np.hypot(*np.diff(xy, axis=0).T)  # the walk goes row by row
    assert steps.min() > 10.0 - 2 * np.sqrt(2) and steps.max() < 20.0 + 2 * np.sqrt(2)
    for T in poses:
        assert 1.45 <= T[2, 3] - scene.ground_z(T[0, 3], T[1, 3]) <= 1.8
        assert np.degrees(np.arccos(T[2, 2])) <= world.tilt_deg * np.sqrt(2) + 1e-9
    line = forest_scene(ForestWorld(seed=3, shape=(1, 5), rays=SMALL))[1].stations
    d = line - line.mean(axis=0)
    _, sv, _ = np.linalg.svd(d, full_matrices=False)
    assert sv[1] < 0.1 * sv[0]  # along one line
    assert (np.hypot(*np.diff(line, axis=0).T) > 10.0 - 2 * np.sqrt(2)).all()


def test_a_forest_is_deterministic_in_its_seed():
    world = ForestWorld(seed=4, shape=(1, 2), rays=(120, 30))
    a, b = scan_forest(world), scan_forest(world)
    c = scan_forest(ForestWorld(seed=5, shape=(1, 2), rays=(120, 30)))
    assert a[0] == b[0] and a[0] != c[0]
    assert all(np.array_equal(p, q) for p, q in zip(a[1], b[1], strict=True))
    assert all(np.array_equal(p, q) for p, q in zip(a[2], b[2], strict=True))
