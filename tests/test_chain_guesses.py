"""ndt-chain with guesses: approximate poses per scan (--init-poses) and per pair (--pairs rows
with a pose). A right guess keeps every scan right; a wrong one leaves its scan right or not
ok, never ok and wrong; a bad guess file is one line, exit 2, before any scan is read."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.io.matrices import read_pose_list

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
SCANS = sorted(SAMPLE.glob("scan_*.laz"))
TRUTH = read_pose_list(SAMPLE / "poses_T_world_scan.txt")
CHAIN = [sys.executable, "-c", "from ndt_cli.cli import chain_app; chain_app()"]
ROT_DEG, TRANS_M = 0.1, 0.05  # a right pose


def _chain(tmp_path: Path, *extra: str) -> subprocess.CompletedProcess:
    args = [*map(str, SCANS), "-o", str(tmp_path / "out"), "-j", "2", "-q", *extra]
    return subprocess.run([*CHAIN, *args], capture_output=True, text=True, check=False)


def _init(tmp_path: Path, moved: dict[str, np.ndarray]) -> Path:
    """An --init-poses file: the truth, each scan moved by ``moved[name]`` (world frame)."""
    path = tmp_path / "init.txt"
    lines = []
    for name, T in TRUTH.items():
        G = moved.get(name, np.eye(4)) @ T
        lines.append(name + " " + " ".join(f"{v:.9f}" for v in G.ravel()))
    path.write_text("\n".join(lines) + "\n")
    return path


def _errors(out: Path) -> dict[str, tuple[str, float, float]]:
    """Per scan: status, yaw error (deg) and horizontal error (m) of its pose relative to the
    anchor's, against the truth."""
    rows = {Path(r["file"]).name: r for r in csv.DictReader((out / "poses.csv").open())}
    anchor = TRUTH[SCANS[0].name]
    found = {}
    for name, r in rows.items():
        if r["has_pose"] != "true":
            found[name] = (r["status"], np.inf, np.inf)
            continue
        T = np.array([float(r[f"m{i}{j}"]) for i in range(4) for j in range(4)]).reshape(4, 4)
        ref = np.linalg.inv(anchor) @ TRUTH[name]
        d = np.linalg.inv(ref) @ T
        found[name] = (
            r["status"],
            abs(np.degrees(np.arctan2(d[1, 0], d[0, 0]))),
            np.hypot(*d[:2, 3]),
        )
    return found


@pytest.mark.slow
def test_approximate_poses_keep_every_scan_right_and_a_wrong_one_is_never_ok(tmp_path):
    rng = np.random.default_rng(3)
    near = {
        n: pose2d_matrix(*rng.uniform(-0.7, 0.7, 2), np.radians(rng.uniform(-3, 3))) for n in TRUTH
    }
    run = _chain(tmp_path, "--init-poses", str(_init(tmp_path, near)))
    assert run.returncode == 0, run.stderr
    for name, (status, rot, trans) in _errors(tmp_path / "out").items():
        assert status == "ok" and rot < ROT_DEG and trans < TRANS_M, (name, rot, trans)
    slid = {SCANS[3].name: pose2d_matrix(9.0, 0.0, 0.0)}  # a facade bay or two along the street
    wrong = tmp_path / "wrong"
    wrong.mkdir()
    _chain(wrong, "--init-poses", str(_init(wrong, slid)))
    for name, (status, rot, trans) in _errors(wrong / "out").items():
        assert status != "ok" or (rot < ROT_DEG and trans < TRANS_M), (name, status, rot, trans)


@pytest.mark.slow
def test_a_bad_guess_file_is_one_line_before_any_scan_is_read(tmp_path):
    bad = tmp_path / "init.txt"
    bad.write_text("scan_00.laz 0 0 0 0\nscan_09.laz 1 2 3 4\n")
    run = _chain(tmp_path, "--init-poses", str(bad))
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "init.txt: line 2: no scan named 'scan_09.laz'" in lines[0], lines
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("scan_00.laz,scan_01.laz,1,2\n")
    run = _chain(tmp_path, "--pairs", str(pairs))
    assert run.returncode == 2 and "pairs.csv: line 1: a guess is" in run.stderr
    run = _chain(tmp_path, "--init-poses", str(_init(tmp_path, {})), "--init-sigma", "1")
    assert run.returncode == 2 and "--init-sigma" in run.stderr
    assert not (tmp_path / "out").exists()
