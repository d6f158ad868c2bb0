"""The street scanner simulator that makes the sample data and the test scenes."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli import simulate
from ndt_cli.transforms import apply

SMALL = {"n_azimuth": 360, "n_elevation": 60}


@pytest.fixture(scope="module")
def street():
    return simulate.make_street(seed=3)


def test_same_seed_same_scan_other_seed_other_scan():
    a = simulate.make_sequence(seed=4, n_scans=2, scan_kwargs=SMALL)
    b = simulate.make_sequence(seed=4, n_scans=2, scan_kwargs=SMALL)
    c = simulate.make_sequence(seed=5, n_scans=2, scan_kwargs=SMALL)
    assert all(np.array_equal(x, y) for x, y in zip(a[1], b[1], strict=True))
    assert all(np.array_equal(x, y) for x, y in zip(a[2], b[2], strict=True))
    assert not np.array_equal(a[2][1], c[2][1])


def test_points_are_in_the_scanner_frame(street):
    T = simulate.scanner_pose(5.0, 1.0, 40.0, height=1.6)
    pts = simulate.simulate_scan(street, T, **SMALL, range_noise=0.0)
    assert len(pts) > 1000
    world = apply(T, pts)
    on_ground = np.abs(world[:, 2]) < 0.01
    assert on_ground.mean() > 0.2  # a large share of the scan is the ground at world z = 0
    assert np.median(pts[on_ground, 2]) == pytest.approx(-1.6, abs=0.01)  # scanner frame: z = -h
    assert np.any(world[:, 2] > 8.0)  # facades above the ground floor are seen


def test_no_point_lies_inside_a_box(street):
    T = simulate.scanner_pose(-20.0, -2.0, 10.0)
    world = apply(T, simulate.simulate_scan(street, T, **SMALL, range_noise=0.0))
    lo, hi = street.boxes_min, street.boxes_max
    inside = np.zeros(len(world), dtype=bool)
    for a, b in zip(lo, hi, strict=True):
        inside |= np.all((world > a + 1e-6) & (world < b - 1e-6), axis=1)
    assert not inside.any()


def test_range_noise_has_the_requested_spread(street):
    T = simulate.scanner_pose(0.0, 0.0, 0.0)
    exact = simulate.simulate_scan(street, T, **SMALL, range_noise=0.0)
    noisy = simulate.simulate_scan(street, T, **SMALL, range_noise=0.008, seed=1)
    dr = np.linalg.norm(noisy, axis=1) - np.linalg.norm(exact, axis=1)
    assert np.std(dr) == pytest.approx(0.008, rel=0.1)


def test_tilt_changes_scanner_points_not_the_world(street):
    level = simulate.scanner_pose(0.0, 0.0, 0.0)
    tilted = simulate.scanner_pose(0.0, 0.0, 0.0, roll_deg=0.5, pitch_deg=-0.4)
    w_level = apply(level, simulate.simulate_scan(street, level, **SMALL, range_noise=0.0))
    pts_tilted = simulate.simulate_scan(street, tilted, **SMALL, range_noise=0.0)
    w_tilted = apply(tilted, pts_tilted)
    ground_scan = pts_tilted[np.abs(w_tilted[:, 2]) < 0.01]
    # in the tilted scanner frame the ground is a tilted plane; in the world it is flat
    slope = np.linalg.lstsq(np.c_[ground_scan[:, :2], np.ones(len(ground_scan))],
                            ground_scan[:, 2], rcond=None)[0][:2]  # fmt: skip
    assert np.degrees(np.abs(slope)).max() > 0.3
    assert np.abs(w_tilted[np.abs(w_tilted[:, 2]) < 0.05, 2]).max() < 0.05
    assert np.abs(np.median(w_level[:, 2]) - np.median(w_tilted[:, 2])) < 0.5


def test_corridor_facades_have_no_gaps():
    scene = simulate.make_street(seed=1, corridor=True)
    T = simulate.scanner_pose(0.0, 0.0, 0.0)
    world = apply(T, simulate.simulate_scan(scene, T, n_azimuth=720, n_elevation=40,
                                            range_noise=0.0))  # fmt: skip
    level = world[np.abs(world[:, 2] - 2.0) < 0.3]
    for side in (1, -1):
        wall = level[np.sign(level[:, 1]) == side]
        xs = np.sort(wall[np.abs(wall[:, 0]) < 40, 0])
        assert len(xs) > 50 and np.diff(xs).max() < 2.0  # continuous facade along the street
    assert len(scene.cylinders) == 0
