"""Simulated campaigns: where their scans stand, what the scanners see, the orders and sites."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli import sim


@pytest.fixture(scope="module")
def junction():
    return sim.junction(seed=3, rays=(300, 60))


def test_a_junction_walks_the_main_street_and_up_the_side_street(junction):
    xy = np.array([T[:2, 3] for T in junction.poses])
    up = xy[:, 1] > 12.0  # in the side street (the main street's facades are at +-9 m)
    assert up.sum() >= 3 and (~up).sum() >= 6
    assert np.abs(xy[up, 0]).max() < 3.0  # along the side street's centre line
    steps = np.hypot(*np.diff(xy, axis=0).T)
    assert sorted(steps)[-2] < 24.0  # every scan stands near the one before it, but ...
    assert steps.max() > 60.0  # ... the one after the walk back from the side street
    assert len(set(junction.names)) == len(junction)


def test_scans_see_the_scene_around_them(junction):
    for pts, T in zip(junction.scans, junction.poses, strict=True):
        world = pts @ T[:3, :3].T + T[:3, 3]
        assert len(pts) > 1000
        assert np.hypot(*(world[:, :2] - T[:2, 3]).T).max() <= 121.0  # the scanner's range


def test_the_side_street_opens_into_the_main_street(junction):
    """No building of either street stands where the side street meets the main street."""
    mouth = np.array([[x, y, 2.0] for x in np.linspace(-6, 6, 13) for y in (3.0, 9.5, 12.0)])
    assert not junction.scene.contains(mouth).any()


def test_a_loop_comes_back_to_where_it_entered_the_block():
    loop = sim.block_loop(seed=1, rays=(200, 40))
    xy = np.array([T[:2, 3] for T in loop.poses])
    start_of_loop = np.argmin(np.hypot(*(xy - [-50.0, 0.0]).T)[: len(xy) // 2])
    assert np.hypot(*(xy[-1] - xy[start_of_loop])) < 25.0  # the walk closes the loop
    assert xy[:, 1].max() > 70.0 and xy[:, 0].max() > 45.0  # it went round the block


def test_shuffled_keeps_each_scan_with_its_pose_and_renames_them():
    route = sim.route(seed=2, n_scans=6, rays=(200, 40))
    mixed = sim.shuffled(route, seed=5)
    assert mixed.names == tuple(f"scan_{k:02d}" for k in range(6))
    order = [next(k for k, p in enumerate(route.poses) if p is q) for q in mixed.poses]
    assert sorted(order) == list(range(6)) and order != list(range(6))
    for k, j in enumerate(order):
        assert mixed.scans[k] is route.scans[j]


def test_two_sites_are_out_of_range_of_each_other_and_labelled():
    both = sim.two_sites(seed=4, n_scans=(3, 2), rays=(200, 40))
    assert both.site == (0, 0, 0, 1, 1)
    assert both.names == ("a_00", "a_01", "a_02", "b_00", "b_01")
    a = np.array([T[:2, 3] for T in both.poses[:3]])
    b = np.array([T[:2, 3] for T in both.poses[3:]])
    assert np.hypot(*(a[:, None] - b[None]).transpose(2, 0, 1)).min() > 500.0


def test_campaigns_are_deterministic_in_the_seed():
    one, two = sim.route(seed=7, n_scans=3, rays=(100, 20)), sim.route(7, 3, rays=(100, 20))
    assert all(np.array_equal(a, b) for a, b in zip(one.scans, two.scans, strict=True))
    assert all(np.array_equal(a, b) for a, b in zip(one.poses, two.poses, strict=True))


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_route_written_scan_by_scan_is_the_route_simulated_at_once(tmp_path, jobs):
    """``write_route`` (memory for one scan a worker) writes the files ``route`` and
    ``write_survey`` write: the same points, times and poses."""
    from ndt_cli import io

    route = sim.route(seed=2, n_scans=4, rays=(200, 40))
    whole = sim.write_survey(route, tmp_path / "whole", times=True)
    files, poses = sim.write_route(
        tmp_path / "streamed", seed=2, n_scans=4, rays=(200, 40), times=True, jobs=jobs
    )
    assert [f.name for f in files] == [f.name for f in whole]
    for a, b, T, P in zip(whole, files, route.poses, poses, strict=True):
        assert np.array_equal(io.read(a).points, io.read(b).points)
        assert io.acquired(a) == io.acquired(b) is not None
        assert np.array_equal(T, P)
