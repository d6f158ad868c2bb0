"""Guesses a surveyor gives: approximate poses per scan and per pair, their uncertainty, and
which result of a link registered from the search and from its guess is kept."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.errors import ConfigError, InputError
from ndt_cli.ndt.coarse_to_fine import Ranked
from ndt_cli.ndt.guess import Guess, beyond_text, reach_of, within
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.guesses import (
    better,
    pair_pose,
    parse_sigma,
    pose_of,
    read_init_poses,
    relative,
    turned_round,
)
from ndt_cli.pipeline.network import LinkKind, read_pairs

NAMES = ["scan_00.laz", "scan_01.laz", "scan_02.laz"]


def test_sigma_is_metres_and_degrees_within_bounds():
    assert parse_sigma("0.5,2") == (0.5, 2.0)
    for bad in ("1", "1,2,3", "a,b", "0,5", "-1,5", "1,0", "1,181", "nan,5", "1,inf"):
        with pytest.raises(ConfigError, match="--init-sigma"):
            parse_sigma(bad)


def test_a_pose_is_sixteen_numbers_or_x_y_z_yaw():
    T = pose_of(["1", "2", "3", "90"])
    np.testing.assert_allclose(T[:3, 3], [1, 2, 3])
    np.testing.assert_allclose(T[:2, :2], [[0, -1], [1, 0]], atol=1e-12)  # 90 deg about z
    np.testing.assert_allclose(pose_of([str(v) for v in np.eye(4).ravel()]), np.eye(4))
    assert pose_of(["1", "2", "3"]) is None and pose_of(["1", "x", "3", "4"]) is None
    assert pose_of(["1", "2", "3", "nan"]) is None


def test_initial_poses_name_scans_and_bad_lines_are_named(tmp_path):
    good = tmp_path / "init.txt"
    good.write_text("# approximate\nscan_00.laz 0 0 0 0\n2 30 1 0.5 45\n")
    poses = read_init_poses(good, NAMES)
    assert sorted(poses) == [0, 2]
    np.testing.assert_allclose(poses[2][:3, 3], [30, 1, 0.5])
    cases = {
        "nowhere.laz 0 0 0 0\n": "line 1: no scan named 'nowhere.laz'",
        "scan_00.laz 0 0 0\n": "line 1: expected a name and 16 numbers",
        "scan_00.laz 1e308 0 0 0\n": "line 1: a coordinate of 1e\\+308 m is no place on earth",
        "scan_00.laz " + " ".join(["2"] * 16) + "\n": "line 1: ",
    }
    for text, needle in cases.items():
        bad = tmp_path / "bad.txt"
        bad.write_text(text)
        with pytest.raises(InputError, match=needle):
            read_init_poses(bad, NAMES)


def test_a_pairs_row_may_carry_a_guess(tmp_path):
    (tmp_path / "T.txt").write_text("1 0 0 5\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("target,source\nscan_00.laz,scan_01.laz,1,2,0,30\nscan_01.laz,2,T.txt\n0,2\n")
    links = read_pairs(pairs, NAMES, (0.5, 3.0))
    assert [(k.target, k.source, k.kind) for k in links] == [
        (0, 1, LinkKind.USER),
        (1, 2, LinkKind.USER),
        (0, 2, LinkKind.USER),
    ]
    np.testing.assert_allclose(
        links[0].guess.T_target_source, pose2d_matrix(1, 2, np.radians(30)), atol=1e-12
    )
    assert (links[0].guess.sigma_m, links[0].guess.sigma_deg) == (0.5, 3.0)
    assert links[1].guess.T_target_source[0, 3] == 5.0 and links[2].guess is None
    pairs.write_text("scan_00.laz,scan_01.laz,1,2\n")
    with pytest.raises(InputError, match="line 1: a guess is x,y,z,yaw_deg or a 4x4 file"):
        read_pairs(pairs, NAMES)
    assert pair_pose(["", ""], tmp_path) is None
    with pytest.raises(ValueError, match="more than 10000 m apart"):
        pair_pose(["1e6", "0", "0", "0"], tmp_path)
    (tmp_path / "far.txt").write_text("1 0 0 2e4\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
    with pytest.raises(ValueError, match="more than 10000 m apart"):
        pair_pose(["far.txt"], tmp_path)


def test_two_approximate_poses_guess_their_pair_with_the_spread_of_their_errors():
    """The pair's sigma against a Monte Carlo reference: both poses' errors drawn with the
    given spread (each position's rms error 1 m, heading 5 degrees, about the scanner), the
    rms error of the pair's pose. The target's heading error moves the source, 30 m away,
    across the line between them: the position's sigma is 2.9 m, not sqrt(2) m."""
    W = {0: pose2d_matrix(10, 5, 0.3), 1: pose2d_matrix(40, 9, 1.2)}
    g = relative(W, 0, 1, (1.0, 5.0))
    np.testing.assert_allclose(W[0] @ g.T_target_source, W[1], atol=1e-12)
    rng = np.random.default_rng(3)
    moved, trans, yaw = [], [], []
    for _ in range(5_000):
        moved = [
            W[k] @ pose2d_matrix(*rng.normal(0, np.sqrt(0.5), 2), np.radians(rng.normal(0, 5)))
            for k in (0, 1)
        ]
        d = np.linalg.inv(g.T_target_source) @ np.linalg.inv(moved[0]) @ moved[1]
        trans.append(np.hypot(*d[:2, 3]))
        yaw.append(np.degrees(np.arctan2(d[1, 0], d[0, 0])))
    assert g.sigma_m == pytest.approx(np.sqrt(np.mean(np.square(trans))), rel=0.03)
    assert g.sigma_deg == pytest.approx(np.sqrt(np.mean(np.square(yaw))), rel=0.03)
    assert g.sigma_m > 2.5  # the premise: far more than sqrt(2) m at 30 m
    assert relative(W, 0, 2, (1.0, 5.0)) is None


@dataclass(frozen=True)
class _R:
    """The fields :func:`better` reads of a registration result."""

    status: Status
    score: float
    scene: str = "street"
    T_target_source: np.ndarray = field(default_factory=lambda: np.eye(4))
    warnings: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status is Status.OK


def _r(ok: bool, score: float, scene: str = "street", x: float = 0.0) -> _R:
    return _R(Status.OK if ok else Status.SUSPECT, score, scene, pose2d_matrix(x, 0.0, 0.0))


def test_the_result_kept_is_the_ok_one_then_the_higher_score():
    search, guessed = _r(True, 380.0), _r(True, 421.0)
    assert better(search, guessed) is guessed  # the search missed a pose that scores higher
    assert better(guessed, search) is guessed
    assert better(_r(True, 300.0), _r(False, 900.0)).score == 300.0  # a doubted guess: never
    assert better(_r(False, 300.0), _r(True, 100.0, x=3.9)).score == 100.0  # rescued
    tie = _r(True, 400.0)
    assert better(tie, _r(True, 400.0)) is tie


def test_indoors_a_guess_rescues_only_the_pose_the_search_ended_at():
    """Indoors the guess's pose 3.9 m from where the search ended is kept, but suspect, with
    the distance; the search's own pose, doubted by it (a rival the guess rules out), is ok."""
    kept = better(_r(False, 50.0, "indoor"), _r(True, 100.0, "indoor", x=3.9))
    assert kept.status is Status.SUSPECT and kept.score == 100.0
    assert "not confirmed: the search ended 3.90 m and 0.0 deg from it" in kept.warnings[-1]
    assert better(_r(False, 300.0, "indoor"), _r(True, 100.0, "indoor", x=3.9)).score == 300.0
    same = _r(True, 100.0, "indoor", x=0.3)
    assert better(_r(False, 300.0, "indoor"), same) is same
    assert better(_r(True, 80.0, "indoor"), _r(True, 100.0, "indoor", x=3.9)).score == 80.0


def test_a_link_registered_the_other_way_round_keeps_its_guess_turned_round():
    """A suspect found link registered again the other way round (the link runner's second
    try) is judged against the same guess: T_source_target, the same uncertainty."""
    guess = Guess(pose2d_matrix(10.0, 2.0, 0.3), 3.3, 7.1)
    back = turned_round(guess)
    np.testing.assert_allclose(back.T_target_source @ guess.T_target_source, np.eye(4), atol=1e-12)
    assert (back.sigma_m, back.sigma_deg) == (3.3, 7.1)
    assert turned_round(None) is None


def test_a_search_that_ends_beyond_the_guess_is_suspect():
    """A search ending 180 degrees (or 6 m) from a guess within 1.4 m and 7 degrees
    contradicts it; within its reach it is kept as it is."""
    guess = Guess(pose2d_matrix(10.0, 2.0, 0.3), np.sqrt(2), 5 * np.sqrt(2))
    turned = _R(Status.OK, 500.0, T_target_source=pose2d_matrix(10.0, 2.0, 0.3 + np.pi))
    kept = better(turned, _r(False, 100.0), guess)
    assert kept.status is Status.SUSPECT and kept.score == 500.0
    assert "0.00 m and 180.0 deg from the guess, beyond 3 times" in kept.warnings[-1]
    slid = _R(Status.OK, 500.0, T_target_source=pose2d_matrix(16.0, 2.0, 0.3))
    assert "6.00 m and 0.0 deg" in better(slid, _r(False, 100.0), guess).warnings[-1]
    near = _R(Status.OK, 500.0, T_target_source=pose2d_matrix(11.0, 2.5, 0.35))
    assert better(near, _r(False, 100.0), guess) is near
    assert better(turned, _r(False, 100.0)) is turned  # no guess: nothing to contradict


def test_a_degenerate_result_beyond_the_guess_is_suspect():
    """A degenerate link fixes rotation and height in the network; one whose pose is 45 m
    along the street from a guess within 7 m contradicts it and is suspect. Within the reach,
    a degenerate result stays degenerate (its weak direction is no contradiction)."""
    guess = Guess(pose2d_matrix(78.0, 0.0, 0.0), 6.9, 7.1)
    slid = _R(Status.DEGENERATE, 500.0, T_target_source=pose2d_matrix(33.0, 0.0, 0.0))
    kept = better(slid, _r(False, 100.0), guess)
    assert kept.status is Status.SUSPECT
    assert "45.00 m and 0.0 deg from the guess" in kept.warnings[-1]
    near = _R(Status.DEGENERATE, 500.0, T_target_source=pose2d_matrix(70.0, 1.0, 0.02))
    assert better(near, _r(False, 100.0), guess).status is Status.DEGENERATE


def test_a_guess_allows_the_poses_within_three_times_its_uncertainty():
    """Reach in the scans' reduced frames: the source's origin within 3 sigma_m of where the
    guess puts it, the heading within 3 sigma_deg (any heading when it is 45 degrees or more);
    the candidates outside are dropped unless none is inside."""
    p0 = np.array([10.0, -4.0, np.radians(170.0)])

    def off(dx: float, dy: float, dyaw: float) -> np.ndarray:
        return p0 + np.array([dx, dy, dyaw])

    g = Guess(np.eye(4), 1.0, 5.0)
    assert not reach_of(off(2.0, 2.0, 0.0), p0, g)[2]  # 2.83 m
    assert reach_of(off(2.2, 2.2, 0.0), p0, g)[2]  # 3.11 m
    metres, degrees, far = reach_of(off(0.0, 0.0, np.radians(16.0)), p0, g)
    assert far and metres == 0.0 and degrees == pytest.approx(16.0)
    assert not reach_of(off(0.0, 0.0, np.radians(14.0)), p0, g)[2]  # across +-180 deg
    assert not reach_of(off(1.0, 0.0, np.pi), p0, Guess(np.eye(4), 1.0, 180.0))[2]
    poses = np.array([off(5.0, 0.0, 0.0), off(0.5, 0.0, 0.0), off(0.0, 0.0, 0.5)])
    ranked = Ranked(poses, np.array([3.0, 2.0, 1.0]), np.array([1.0, 0.9, 0.8]), np.ones(3, bool))
    kept = within(ranked, p0, g)
    np.testing.assert_array_equal(kept.poses, poses[[1]])  # 5 m and 28.6 deg are beyond
    assert kept.evidence.tolist() == [0.9]
    alone = Ranked(poses[:1], ranked.scores[:1], ranked.evidence[:1], ranked.converged[:1])
    assert within(alone, p0, g) is alone  # none inside: all kept (the verdict says why)
    text = beyond_text(poses[0], p0, g)
    assert "5.00 m and 0.0 deg from the guess, beyond 3 times its uncertainty (1 m, 5 deg)" in text
    assert beyond_text(poses[1], p0, g) == ""
