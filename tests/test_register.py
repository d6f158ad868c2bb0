"""End-to-end registration: known transforms on simulated streets, georeferenced coordinates,
initial guesses, failure reporting, and the real Velodyne pair."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_data

import ndt_cli
from ndt_cli import sim
from ndt_cli.config import Config
from ndt_cli.core.transforms import apply, pose2d_matrix, translation, yaw_of
from ndt_cli.io.matrices import read_matrix
from ndt_cli.ndt.register import Guess
from ndt_cli.ndt.result import Status

ROT_TOL_DEG = 0.3
TRANS_TOL_M = 0.15


def planar_errors(T: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """|yaw error| (deg) and horizontal translation error (m)."""
    dyaw = np.degrees(np.angle(np.exp(1j * (yaw_of(T) - yaw_of(T_ref)))))
    return abs(float(dyaw)), float(np.hypot(*(T[:2, 3] - T_ref[:2, 3])))


@pytest.fixture(scope="module")
def street():
    """Four scans along a simulated street, any heading, 13-30 m apart."""
    _, scans, poses = sim.make_sequence(seed=101, n_scans=4)
    return scans, poses


def relative(poses, i, j):
    return np.linalg.inv(poses[i]) @ poses[j]


@pytest.mark.parametrize(
    "method",
    [
        "newton",
        pytest.param("lm_fixed", marks=pytest.mark.slow),
        pytest.param("lm", marks=pytest.mark.slow),
    ],
)
@pytest.mark.slow
def test_recovers_every_link_of_a_street_with_each_optimizer(street, method):
    scans, poses = street
    cfg = Config().replace(optimizer={"method": method})
    for i in range(1, len(scans)):
        result = ndt_cli.register(scans[i - 1], scans[i], cfg)
        ref = relative(poses, i - 1, i)
        rot, trans = planar_errors(result.T_target_source, ref)
        assert result.ok, (method, i, result.status, result.warnings)
        assert rot < ROT_TOL_DEG and trans < TRANS_TOL_M, (method, i, rot, trans)
        assert abs(result.T_target_source[2, 3] - ref[2, 3]) < 0.05  # ground difference as tz


@pytest.mark.slow
def test_recovers_a_40_m_link():
    _, scans, poses = sim.make_sequence(seed=5, n_scans=2, spacing=(39.0, 40.0))
    ref = relative(poses, 0, 1)
    assert np.hypot(*ref[:2, 3]) > 38
    result = ndt_cli.register(scans[0], scans[1])
    rot, trans = planar_errors(result.T_target_source, ref)
    assert rot < ROT_TOL_DEG and trans < TRANS_TOL_M


def max_displacement(T: np.ndarray, T_ref: np.ndarray, points: np.ndarray) -> float:
    """Largest horizontal distance (m) between the points mapped by ``T`` and by ``T_ref``."""
    return float(np.max(np.hypot(*(apply(T, points) - apply(T_ref, points))[:, :2].T)))


@pytest.mark.slow
def test_georeferenced_coordinates_register_as_accurately_as_local_ones(street):
    scans, poses = street
    ref = relative(poses, 0, 1)
    near = scans[1][np.linalg.norm(scans[1][:, :2], axis=1) < 40]  # points near the scanner
    local = ndt_cli.register(scans[0], scans[1])
    err_local = max_displacement(local.T_target_source, ref, near)
    # target and source in two different georeferenced frames, ~5e6 m from their origins
    G_t = translation([512_345.0, 5_402_817.0, 87.0])
    G_s = translation([498_765.0, 5_399_123.0, 91.0]) @ pose2d_matrix(0, 0, 1.0)
    geo = ndt_cli.register(apply(G_t, scans[0]), apply(G_s, scans[1]))
    T_ref = G_t @ ref @ np.linalg.inv(G_s)
    err_geo = max_displacement(geo.T_target_source, T_ref, apply(G_s, near))
    assert err_local < TRANS_TOL_M
    assert abs(err_geo - err_local) < 0.005, (err_geo, err_local)


@pytest.mark.slow
def test_initial_guess_skips_the_search_and_the_cells_coarser_than_its_uncertainty(street):
    scans, poses = street
    ref = relative(poses, 1, 2)
    guess = ref @ pose2d_matrix(0.8, -0.6, np.radians(2.0))
    cfg = Config()
    result = ndt_cli.register(scans[1], scans[2], cfg, init=guess)  # within 1 m and 5 deg
    assert [level.cell_size for level in result.levels] == [2.0, 1.0]  # no search, no 20 m
    assert all(level.starts == 3 * 25 for level in result.levels)  # heading, +-5 deg
    rot, trans = planar_errors(result.T_target_source, ref)
    assert rot < ROT_TOL_DEG and trans < TRANS_TOL_M
    wide = ndt_cli.register(scans[1], scans[2], cfg, init=Guess(guess, 4.0, 1.0))
    # 4 m: its heading refined from 10 m, and a local search at 2 m cells from 9 x 9 positions
    # within +-4 m (1 m apart); the poses of both refined from 2 m on
    assert [level.cell_size for level in wide.levels] == [10.0, 5.0, 2.0, 2.0, 1.0]
    assert [level.starts for level in wide.levels[:3]] == [25, 25, 81]
    assert wide.levels[3].starts % 25 == 0 and wide.levels[3].starts >= 3 * 25
    assert planar_errors(wide.T_target_source, ref)[1] < TRANS_TOL_M


def test_a_position_without_a_heading_is_searched_all_round(street):
    """A control station gives where a scanner stood, not where it looked."""
    scans, poses = street
    ref = relative(poses, 1, 2)
    turned = ref @ pose2d_matrix(0.4, 0.3, np.radians(150.0))
    result = ndt_cli.register(scans[1], scans[2], Config(), init=Guess(turned, 1.0, 180.0))
    assert all(level.starts == 24 * 25 for level in result.levels)  # every 15 deg
    rot, trans = planar_errors(result.T_target_source, ref)
    assert rot < ROT_TOL_DEG and trans < TRANS_TOL_M


def test_a_wrong_guess_ends_right_or_not_ok(street):
    scans, poses = street
    ref = relative(poses, 1, 2)
    slid = ref @ pose2d_matrix(9.0, 0.0, 0.0)  # a facade bay or two along the street
    result = ndt_cli.register(scans[1], scans[2], Config(), init=slid)
    rot, trans = planar_errors(result.T_target_source, ref)
    assert not result.ok, (rot, trans)  # the truth is 9 m from the guess: beyond its reach
    if rot < ROT_TOL_DEG and trans < TRANS_TOL_M:
        assert any("from the guess, beyond 3 times" in w for w in result.warnings)


def test_no_common_slice_means_no_overlap():
    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(-20, 20, (20000, 2)), rng.normal(0, 0.01, 20000)])
    low = np.column_stack([rng.uniform(-10, 10, (3000, 2)), np.full(3000, 1.0)])
    high = np.column_stack([rng.uniform(-10, 10, (3000, 2)), np.full(3000, 8.0)])
    result = ndt_cli.register(np.vstack([ground, low]), np.vstack([ground, high]))
    assert result.status is Status.NO_OVERLAP and not result.ok
    assert result.score == 0.0


def test_identical_scans_give_identity(street):
    scans, _ = street
    result = ndt_cli.register(scans[0], scans[0].copy())
    rot, trans = planar_errors(result.T_target_source, np.eye(4))
    assert rot < 0.01 and trans < 0.01


@pytest.mark.slow
def test_same_input_gives_bit_identical_result(street):
    scans, _ = street
    a = ndt_cli.register(scans[0], scans[1])
    b = ndt_cli.register(scans[0], scans[1])
    assert np.array_equal(a.T_target_source, b.T_target_source)


def test_real_velodyne_pair_matches_reference():
    folder = shared_data("koide3_velodyne_pair")
    ref = read_matrix(folder / "relative_T_target_source.txt")
    result = ndt_cli.register(folder / "251370668.pcd", folder / "251371071.pcd")
    rot, trans = planar_errors(result.T_target_source, ref)
    assert result.ok, result.warnings
    assert rot < 1.0 and trans < 0.05, (rot, trans)


@pytest.mark.slow
def test_two_different_streets_are_suspect_not_ok(street):
    """Not ok, refuted by the free space, and so left out of any network (whether ICP also
    found a direction weakly constrained, making it degenerate, is secondary)."""
    scans, _ = street
    _, other, _ = sim.make_sequence(seed=77, n_scans=1)
    result = ndt_cli.register(scans[0], other[0])
    assert result.status in (Status.SUSPECT, Status.DEGENERATE) and not result.ok
    assert any(w.startswith("free space: the pose puts") for w in result.warnings)
    assert result.refuted


def test_search_includes_the_papers_zero_start_in_the_scan_frames(street):
    from ndt_cli.ndt.prepare import load_and_prepare
    from ndt_cli.ndt.search import search_starts

    scans, _ = street
    cfg = Config()
    t, s = load_and_prepare(scans[0], cfg), load_and_prepare(scans[1], cfg)
    starts = search_starts(t, s, cfg.search)
    assert len(starts) == cfg.search.yaw_starts * (9 * 9 + 1)
    # identity in the scans' own frames, expressed in the reduced frames
    T_local = t.to_local() @ np.eye(4) @ s.from_local()
    zero = np.array([T_local[0, 3], T_local[1, 3], yaw_of(T_local)])
    assert np.min(np.abs(starts - zero).sum(axis=1)) < 1e-9


@pytest.mark.slow
def test_corridor_is_flagged_degenerate_along_the_street_axis():
    _, scans, poses = sim.make_sequence(seed=3, n_scans=2, corridor=True)
    result = ndt_cli.register(scans[0], scans[1])
    assert result.status is Status.DEGENERATE and not result.ok
    flag = [w for w in result.warnings if w.startswith("degenerate")]
    assert flag, result.warnings
    named = result.weak_direction
    street_levelled = np.linalg.inv(poses[0])[:3, :3] @ np.array([1.0, 0.0, 0.0])
    assert abs(named @ street_levelled) > 0.95, result.degenerate
    # ICP's 6x6 normal matrix agrees: its weakest translation also runs along the street
    icp_flag = [w for w in result.warnings if w.startswith("degenerate (ICP)")]
    assert icp_flag and result.icp_hessian is not None, result.warnings
    from ndt_cli.ndt.quality import weakest_direction

    direction, ratio = weakest_direction(result.hessian)
    street_in_target = np.linalg.inv(poses[0])[:2, :2] @ np.array([1.0, 0.0])
    assert abs(direction @ street_in_target) > 0.95 and ratio < 0.01


@pytest.mark.slow
def test_degeneracy_flag_does_not_fire_on_ordinary_streets(street):
    scans, _ = street
    for i in range(1, len(scans)):
        result = ndt_cli.register(scans[i - 1], scans[i])
        assert not any(w.startswith("degenerate") for w in result.warnings), result.warnings
        assert result.status is Status.OK and result.weak_direction is None


@pytest.mark.slow
def test_tilted_scanners_are_levelled_from_their_ground():
    from ndt_cli.core.transforms import transform_errors

    _, scans, poses = sim.make_sequence(seed=101, n_scans=3, tilt_deg=0.5)
    unlevelled = Config().replace(ground={"level": False}, refine={"method": "none"})
    worst_unlevelled = 0.0
    for i in (1, 2):
        ref = relative(poses, i - 1, i)
        rot, trans = transform_errors(ndt_cli.register(scans[i - 1], scans[i]).T_target_source, ref)
        assert rot < 0.05 and trans < 0.02, (i, rot, trans)  # full 3D rotation and translation
        rot_u, _ = transform_errors(
            ndt_cli.register(scans[i - 1], scans[i], unlevelled).T_target_source, ref
        )
        worst_unlevelled = max(worst_unlevelled, rot_u)
    assert worst_unlevelled > 0.1  # the tilt is really there


def test_icp_refines_the_real_velodyne_pair_in_full_6dof():
    from ndt_cli.core.transforms import transform_errors

    folder = shared_data("koide3_velodyne_pair")
    ref = read_matrix(folder / "relative_T_target_source.txt")
    pair = (folder / "251370668.pcd", folder / "251371071.pcd")
    refined = ndt_cli.register(*pair)
    ndt_only = ndt_cli.register(*pair, Config().replace(refine={"method": "none"}))
    rot, trans = transform_errors(refined.T_target_source, ref)
    rot0, _ = transform_errors(ndt_only.T_target_source, ref)
    assert rot < 0.3 and trans < 0.02, (rot, trans)  # the reference itself is uncertain ~2 cm
    assert rot < rot0  # levelled from its ground, NDT alone is already within 2 cm here
    assert 0 < refined.icp_rms < 0.05 and refined.icp_inliers > 1000
