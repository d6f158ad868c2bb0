"""Guesses a surveyor gives: approximate poses per scan and per pair, their uncertainty, and
which result of a link registered from the search and from its guess is kept."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.errors import ConfigError, InputError
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.guesses import (
    better,
    pair_pose,
    parse_sigma,
    pose_of,
    read_init_poses,
    relative,
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


def test_two_approximate_poses_guess_their_pair_within_root_two_sigma():
    W = {0: pose2d_matrix(10, 5, 0.3), 1: pose2d_matrix(40, 9, 1.2)}
    g = relative(W, 0, 1, (1.0, 5.0))
    np.testing.assert_allclose(W[0] @ g.T_target_source, W[1], atol=1e-12)
    assert g.sigma_m == pytest.approx(np.sqrt(2)) and g.sigma_deg == pytest.approx(5 * np.sqrt(2))
    assert relative(W, 0, 2, (1.0, 5.0)) is None


class _R:
    """The fields :func:`better` reads of a registration result."""

    def __init__(self, ok: bool, score: float) -> None:
        self.ok, self.score = ok, score
        self.status = Status.OK if ok else Status.SUSPECT


def test_the_result_kept_is_the_ok_one_then_the_higher_score():
    search, guessed = _R(True, 380.0), _R(True, 421.0)
    assert better(search, guessed) is guessed  # the search missed a pose that scores higher
    assert better(guessed, search) is guessed
    assert better(_R(True, 300.0), _R(False, 900.0)).score == 300.0  # a doubted guess: never
    assert better(_R(False, 300.0), _R(True, 100.0)).score == 100.0
    tie = _R(True, 400.0)
    assert better(tie, _R(True, 400.0)) is tie
