"""Georeferencing that never fails silently, run as a surveyor runs it: the sample street with
control files written from its ground truth on UTM zone 32N, through ``ndt-chain``,
``ndt-export`` and ``ndt-watch`` as processes. The street's links are registered once; each
case runs the chain again on a copy with ``--resume`` (the same links, a new adjustment)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest
from surveyed import EPSG, SAMPLE, control_csv, grid_scale_at_street, utm_truth
from test_georef import ENV, _cli

from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import EXIT_INPUT, EXIT_REGISTRATION
from ndt_cli.io.matrices import read_pose_list

pytestmark = pytest.mark.slow
SCANS = [str(p) for p in sorted(SAMPLE.glob("scan_*.laz"))]
NAMES = [Path(s).name for s in SCANS]


@pytest.fixture(scope="module")
def street(tmp_path_factory) -> Path:
    """The sample street registered once, without control."""
    out = tmp_path_factory.mktemp("street") / "base"
    res = _cli("chain_app", *SCANS, "--out", str(out), "--jobs", "2", "-q")
    assert res.returncode == 0, res.stderr
    return out


def _run(street: Path, tmp_path: Path, control: str, *extra: str):
    """The street adjusted again with ``control`` (its links reused): the process and the
    result folder."""
    out = tmp_path / "out"
    shutil.copytree(street, out)
    (tmp_path / "control.csv").write_text(control, encoding="utf-8")
    args = [
        "--out",
        str(out),
        "--jobs",
        "2",
        "--resume",
        "--control",
        str(tmp_path / "control.csv"),
    ]
    return _cli("chain_app", *SCANS, *args, *extra), out


def _world(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())["world"]


def test_two_swapped_end_stations_are_rejected_and_the_street_lands_on_the_truth(street, tmp_path):
    """Two stations with swapped numbers among five (the street's ends): the three right ones
    place it (it used to be turned 180 degrees onto the wrong two, exit 0); the console and the
    report give the grid scale applied."""
    truth = utm_truth()
    control = control_csv(truth, NAMES, swap=("scan_00.laz", "scan_04.laz"))
    res, out = _run(street, tmp_path, control, "--crs", f"EPSG:{EPSG}")
    assert res.returncode == 0, res.stderr
    poses = read_pose_list(out / "poses.txt")
    for name, T in truth.items():
        rot, trans = transform_errors(poses[name], T)
        assert trans < 0.02 and rot < 0.03, (name, rot, trans)
    world = _world(out)
    assert world["georeferenced"] is True and world["not_georeferenced"] is None
    used = {row["scan"]: row["used"] for row in world["controls"]}
    assert used == {n: n not in ("scan_00.laz", "scan_04.laz") for n in NAMES}
    scale = grid_scale_at_street()
    assert abs(world["grid_scale"] - scale) < 2e-6
    applied = f"grid scale {scale:.6f} applied ({(scale - 1) * 1e6:+.0f} ppm)"
    assert applied in res.stdout
    assert applied in (out / "report.html").read_text()
    laz = tmp_path / "street.laz"
    res = _cli("export_app", str(out), "--out", str(laz), "-q")
    assert res.returncode == 0, res.stderr
    assert laspy.read(laz).header.parse_crs().to_epsg() == EPSG


@pytest.mark.parametrize(
    ("kind", "needle"),
    [
        ("two against two", "2 against 2 (scan_00.laz, scan_04.laz | scan_01.laz, scan_03.laz)"),
        ("northing first, no --crs", "mirrored: are x and y (easting, northing) swapped?"),
    ],
)
def test_control_that_cannot_place_the_street_is_not_georeferenced_anywhere(
    street, tmp_path, kind, needle
):
    """Every output says so, the run exits 1, and the export refuses in one line."""
    truth = utm_truth()
    if kind == "two against two":
        scans = ["scan_00.laz", "scan_01.laz", "scan_03.laz", "scan_04.laz"]
        control = control_csv(truth, scans, swap=("scan_00.laz", "scan_04.laz"))
        res, out = _run(street, tmp_path, control, "--crs", f"EPSG:{EPSG}")
    else:
        res, out = _run(street, tmp_path, control_csv(truth, NAMES, columns=(1, 0, 2)))
    assert res.returncode == EXIT_REGISTRATION, res.stderr
    console = " ".join(res.stdout.split())
    assert "NOT GEOREFERENCED: 0 of" in console and needle in console
    assert "NOT OK: NOT GEOREFERENCED; all 5 scans ok (adjusted)" in console
    summary = json.loads((out / "summary.json").read_text())
    assert summary["all_ok"] is False
    assert summary["world"]["georeferenced"] is False
    assert needle in summary["world"]["not_georeferenced"]
    assert "NOT GEOREFERENCED" in (out / "poses.txt").read_text().splitlines()[1]
    report = (out / "report.html").read_text()
    verdict = report[report.index('class="verdict') :][:2000]
    assert "NOT OK" in verdict and "not georeferenced: 0 of" in verdict
    res = _cli("export_app", str(out), "--out", str(tmp_path / "street.laz"))
    assert res.returncode == EXIT_INPUT
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "summary.json: not georeferenced: 0 of" in lines[0], res.stderr
    assert not (tmp_path / "street.laz").exists()


def test_one_station_names_its_crs_and_the_export_says_why_it_writes_none(street, tmp_path):
    truth = utm_truth()
    res, out = _run(street, tmp_path, control_csv(truth, ["scan_02.laz"]), "--crs", "EPSG:25832")
    assert res.returncode == 0, res.stderr
    world = _world(out)
    assert world["frame"] == "control, heading from the anchor"
    assert "ETRS89 / UTM zone 32N" in world["crs"] and world["georeferenced"] is True
    laz = tmp_path / "street.laz"
    res = _cli("export_app", str(out), "--out", str(laz))
    assert res.returncode == 0, res.stderr
    assert "in the CRS of --crs at one station only, its heading the anchor's" in res.stderr
    assert laspy.read(laz).header.parse_crs() is None
    at = read_pose_list(out / "poses.txt")["scan_02.laz"][:3, 3]
    np.testing.assert_allclose(at, truth["scan_02.laz"][:3, 3], atol=1e-3)


def test_field_mode_says_control_makes_the_world_and_names_a_station_that_never_came(tmp_path):
    """A station whose scan never lands (a typo: scan_4.laz) is reported as the watch stops;
    the first scan is not said to define the world."""
    truth = utm_truth()
    land = tmp_path / "card"
    land.mkdir()
    control = control_csv(truth, NAMES[:3]) + "scan_4.laz,500040.1833,5400025.2573,101.6000,,\n"
    (tmp_path / "control.csv").write_text(control)
    args = ["--out", str(tmp_path / "out"), "--jobs", "2", "--exit-when-idle", "3"]
    args += ["--control", str(tmp_path / "control.csv"), "--crs", "EPSG:25832"]
    code = "from ndt_cli.cli import watch_app; watch_app()"
    watch = subprocess.Popen(
        [sys.executable, "-c", code, str(land), *args],
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    for scan in SCANS[:3]:
        shutil.copy(scan, land / (Path(scan).name + ".part"))
        (land / (Path(scan).name + ".part")).rename(land / Path(scan).name)
        time.sleep(1.0)
    _, err = watch.communicate(timeout=600)
    assert watch.returncode == 0, err
    lines = err.strip().splitlines()
    first = next(line for line in lines if line.startswith("scan_00.laz:"))
    assert "the first scan, the world frame will be ETRS89 / UTM zone 32N (EPSG:25832)" in first
    assert "once 2 of its 4 stations are in" in first and "defines" not in first
    assert lines[-2].startswith("world frame = ETRS89 / UTM zone 32N (EPSG:25832), from 3")
    assert lines[-1] == "control station scan_4.laz (line 5) not used: no scan named 'scan_4.laz'"
    rows = {r["scan"]: r for r in _world(tmp_path / "out")["controls"]}
    assert rows["scan_4.laz"]["reason"] == "line 5: no scan named 'scan_4.laz'"
    assert [rows[n]["used"] for n in NAMES[:3]] == [True, True, True]
