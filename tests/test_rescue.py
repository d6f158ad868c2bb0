"""A pair whose global search ends elsewhere, rescued by a guess: a busy simulated street
(20 pedestrians and a passing car in every scan, grade, camber, tilted scanners) with scans
36-48 m apart. Its last pair's search slides 19 m and turns 1 degree (suspect), while the true
pose scores twice as high at the finest cells. From a guess near the truth ``ndt-register``
ends at the truth, ok; ``ndt-chain --init-poses`` places the scan; a wrong guess leaves it
right or not ok."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.io.writers import write
from ndt_cli.sim.worlds import StreetWorld, scan_street

ROT_DEG, TRANS_M = 0.1, 0.05
WORLD = StreetWorld(
    seed=13,
    n_scans=4,
    spacing=(36, 48),
    people=20,
    traffic=1,
    grade=0.03,
    camber=0.02,
    tilt_deg=0.5,
)
CLI = [sys.executable, "-c"]


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The street's last two scans as LAZ files, and their true T_target_source."""
    _, scans, poses = scan_street(WORLD)
    folder = tmp_path_factory.mktemp("busy")
    files = [folder / "scan_2.laz", folder / "scan_3.laz"]
    for path, points in zip(files, scans[2:], strict=True):
        write(path, points)
    return files, poses[2:], np.linalg.inv(poses[2]) @ poses[3]


def _errors(T: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    d = np.linalg.inv(ref) @ T
    return abs(float(np.degrees(np.arctan2(d[1, 0], d[0, 0])))), float(np.hypot(*d[:2, 3]))


def _run(app: str, *args: str) -> subprocess.CompletedProcess:
    code = f"from ndt_cli.cli import {app}; {app}()"
    return subprocess.run([*CLI, code, *args], capture_output=True, text=True, check=False)


def _matrix(path: Path, T: np.ndarray) -> Path:
    path.write_text("\n".join(" ".join(f"{v:.9f}" for v in row) for row in T) + "\n")
    return path


@pytest.mark.slow
def test_the_search_alone_misses_and_a_guess_near_the_truth_ends_there(pair, tmp_path):
    (target, source), _, ref = pair
    alone = _run("register_app", str(target), str(source), "-o", str(tmp_path / "a"), "--json")
    found = json.loads(alone.stdout)
    T = np.array(found["T_target_source"])
    rot, trans = _errors(T, ref)
    assert alone.returncode == 1 and (rot > ROT_DEG or trans > TRANS_M)  # the premise
    near = ref @ pose2d_matrix(0.5, -0.4, np.radians(2.0))
    init = _matrix(tmp_path / "init.txt", near)
    run = _run(
        "register_app",
        str(target),
        str(source),
        "--init",
        str(init),
        "-o",
        str(tmp_path / "g"),
        "--json",
    )
    assert run.returncode == 0, run.stderr
    rot, trans = _errors(np.array(json.loads(run.stdout)["T_target_source"]), ref)
    assert rot < ROT_DEG and trans < TRANS_M
    assert json.loads(run.stdout)["score"] > found["score"]  # where the winner is judged


@pytest.mark.slow
def test_ndt_chain_places_the_scan_from_approximate_poses(pair, tmp_path):
    files, poses, ref = pair
    rng = np.random.default_rng(1)
    lines = []
    for path, T in zip(files, poses, strict=True):
        moved = pose2d_matrix(*rng.uniform(-0.7, 0.7, 2), np.radians(rng.uniform(-3, 3))) @ T
        lines.append(path.name + " " + " ".join(f"{v:.9f}" for v in moved.ravel()))
    (tmp_path / "init.txt").write_text("\n".join(lines) + "\n")
    for guessed, folder in ((False, "alone"), (True, "guessed")):
        extra = ["--init-poses", str(tmp_path / "init.txt")] if guessed else []
        out = tmp_path / folder
        run = _run("chain_app", *map(str, files), "-o", str(out), "-j", "2", "-q", *extra)
        rows = list(csv.DictReader((out / "poses.csv").open()))
        if not guessed:
            assert run.returncode == 1 and rows[1]["status"] != "ok"  # the premise
            continue
        assert run.returncode == 0, run.stderr
        T = np.array([float(rows[1][f"m{i}{j}"]) for i in range(4) for j in range(4)])
        T = np.linalg.inv(
            np.array([float(rows[0][f"m{i}{j}"]) for i in range(4) for j in range(4)]).reshape(4, 4)
        ) @ T.reshape(4, 4)
        rot, trans = _errors(T, ref)
        assert rows[1]["status"] == "ok" and rot < ROT_DEG and trans < TRANS_M, (rot, trans)
