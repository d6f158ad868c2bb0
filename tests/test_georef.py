"""Georeferencing from the command line: a control file and its coordinate system given to
``ndt-chain`` (or ``ndt-watch``), checked before any work, and a street that ends in those
coordinates, its exported cloud carrying the system."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest
from typer.testing import CliRunner

from ndt_cli import io, sim
from ndt_cli.cli import chain_app, watch_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import EXIT_INPUT
from ndt_cli.io.matrices import read_pose_list
from ndt_cli.pipeline.control import read_stations

ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
runner = CliRunner()
EPSG = 25832  # ETRS89 / UTM zone 32N


def _scans(tmp_path: Path, n: int = 2) -> list[str]:
    """Stand-in scan files (each its own content: a copy is refused): the checks below come
    before any scan is prepared."""
    files = []
    for k in range(n):
        files.append(str(tmp_path / f"scan_{k}.xyz"))
        Path(files[-1]).write_text(f"{k} 0 0\n1 0 0\n0 1 0\n")
    return files


@pytest.mark.parametrize(
    ("control", "extra", "needle"),
    [
        ("scan_7.xyz,1,2,3\n", [], "line 1: no scan named 'scan_7.xyz'"),
        ("scan_0.xyz,1,2\n", [], "line 1: 3 fields; expected 'scan,x,y,z'"),
        ("scan_0.xyz,1,2,3,-1,1\n", [], "standard deviations must be positive"),
        ("scan_0.xyz,1,2,3\n", ["--crs", "EPSG:999999"], "--crs 'EPSG:999999' is not"),
        ("scan_0.xyz,1,2,3\n", ["--no-adjust"], "--control needs the adjustment"),
        (None, ["--crs", "EPSG:25832"], "--crs names the coordinate system of --control"),
        ("scan_0.xyz,1,2,3\n", ["--crs", "EPSG:4326"], "is geographic (degrees)"),
        ("scan_0.xyz,1,2,3\n", ["--crs", "EPSG:2263"], "has axes in us survey foot"),
    ],
)
def test_a_bad_control_option_is_one_line_and_exit_2_before_any_work(
    tmp_path, control, extra, needle
):
    files = _scans(tmp_path)
    args = [*files, "--out", str(tmp_path / "out"), *extra]
    if control is not None:
        (tmp_path / "control.csv").write_text(control)
        args += ["--control", str(tmp_path / "control.csv")]
    res = runner.invoke(chain_app, args)
    assert res.exit_code == EXIT_INPUT, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "out").exists()


UTM = (
    "scan_0.xyz,499959.5266,5399975.2489,101.6000,,\nscan_1.xyz,499978.2599,5399990.0355,101.6,,\n"
)
HEADER = "scan,x,y,z,sigma_xy,sigma_z\n"


@pytest.mark.parametrize(
    ("control", "crs", "needle"),
    [
        (  # Excel in a German locale: decimal commas, the row has seven fields
            HEADER + "scan_0.xyz,499959,5266,5399975.2489,101.6,,\n",
            "EPSG:25832",
            "line 2: 7 fields where the header has 6 (a decimal comma? write 499959.5266)",
        ),
        (  # northing first, as Gauss-Krueger's Hochwert or CS92 users write it
            "scan_0.xyz,5399975.2489,499959.5266,101.6,,\n",
            "EPSG:25832",
            "line 1: x, y (5399975.249, 499959.527) lie outside the area of ETRS89 / UTM zone "
            "32N (EPSG:25832), and inside it with columns x and y swapped",
        ),
        (  # y and z swapped: a height in the millions
            "scan_0.xyz,499959.5266,101.6,5399975.2489,,\n",
            None,
            "line 1: column z: 5,399,975.249 m is no height",
        ),
        (UTM, "EPSG:2056", "line 1: x, y (499959.527, 5399975.249) lie outside the area of "),
        (  # a German habit: the zone number before the easting
            "scan_0.xyz,32499959.5266,5399975.2489,101.6,,\n",
            "EPSG:25832",
            "inside it as 499959.527: the easting carries a zone number (32)? give it without",
        ),
        ("scan_0.xyz,9.0,48.75,400\n", "EPSG:25832", "degrees of longitude and latitude?"),
        (UTM, "EPSG:31467", "DHDN / 3-degree Gauss-Kruger zone 3 (EPSG:31467): at 27.44°W"),
        (UTM, "EPSG:5514", "S-JTSK / Krovak East North (EPSG:5514): at 29.20°E 73.44°N, not in"),
        (UTM, "EPSG:4978", "--crs 'EPSG:4978' is geocentric"),
        (UTM, "EPSG:4936", "--crs 'EPSG:4936' is geocentric"),
        (UTM, "EPSG:5783", "--crs 'EPSG:5783' holds heights only"),
        (UTM, "EPSG:3857", "its grid scale at the stations is 1.38"),
        ("scan_0.xyz,1e300,1e300,1e300\nscan_1.xyz,1,2,3\n", "EPSG:25832", "column x: 1e+300"),
        ("scan_0.xyz,1,2,3,1e300,1e300\n", None, "line 1: sigma_xy 1e+300 m is out of range"),
    ],
)
@pytest.mark.parametrize("tool", ["chain", "watch"])
def test_control_that_cannot_hold_is_refused_before_any_scan_is_read(
    tmp_path, control, crs, needle, tool
):
    """Each is one line naming the file, its line and column, exit 2, nothing written; the
    stand-in scans are not scans at all: they are never read."""
    files = _scans(tmp_path)
    (tmp_path / "control.csv").write_text(control, encoding="utf-8")
    args = ["--out", str(tmp_path / "out"), "--control", str(tmp_path / "control.csv")]
    args += ["--crs", crs] if crs else []
    if tool == "chain":
        res = runner.invoke(chain_app, [*files, *args])
    else:
        res = runner.invoke(watch_app, [str(tmp_path), *args, "--exit-when-idle", "0.1"])
    lines = res.output.strip().splitlines()
    assert res.exit_code == EXIT_INPUT, res.output
    assert len(lines) == 1 and needle in lines[0], res.output
    assert "control.csv" in lines[0] or "--crs" in lines[0]
    assert not (tmp_path / "out").exists()


def test_field_mode_reads_the_control_file_before_its_scans_land(tmp_path):
    (tmp_path / "land").mkdir()
    (tmp_path / "control.csv").write_text("scan_4.laz,1,2,3\nscan_5.laz,1,2,3,0,1\n")
    args = [str(tmp_path / "land"), "--out", str(tmp_path / "out"), "--exit-when-idle", "0.1"]
    res = runner.invoke(watch_app, [*args, "--control", str(tmp_path / "control.csv")])
    assert res.exit_code == EXIT_INPUT and "line 2: standard deviations" in res.output
    (tmp_path / "control.csv").write_text("scan_4.laz,1,2,3\n")  # names a scan yet to come
    res = runner.invoke(watch_app, [*args, "--control", str(tmp_path / "control.csv")])
    assert res.exit_code == 1, res.output  # no scan landed: nothing is ok, no input error
    assert [s.name for s in read_stations(tmp_path / "control.csv")] == ["scan_4.laz"]


def _cli(tool: str, *args: str) -> subprocess.CompletedProcess:
    code = f"from ndt_cli.cli import {tool}; {tool}()"
    return subprocess.run(
        [sys.executable, "-c", code, *args], env=ENV, capture_output=True, text=True, check=False
    )


@pytest.mark.slow
def test_a_street_with_gnss_on_three_scanners_and_one_blunder_ends_in_their_crs(tmp_path):
    """8 scans of a sloped, cambered street from tilted scanners; GNSS positions of 3 scanners
    (1 cm / 1.5 cm noise) and a 4th 60 cm off: the poses and the exported cloud are in the
    stations' coordinates (the truth's, moved to UTM-like numbers and turned 30 degrees), the
    blunder is named and not used, and the LAZ says EPSG:25832."""
    world = sim.StreetWorld(seed=51, grade=0.05, camber=0.025, tilt_deg=0.8)
    _, scans, truth = sim.scan_street(world)
    G = np.eye(4)
    yaw = np.radians(30.0)
    G[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
    G[:3, 3] = [500_000.0, 5_400_000.0, 100.0]  # on zone 32's central meridian
    T_crs_scan = [G @ T for T in truth]
    # UTM's grid shrinks ground distances by its scale on the central meridian, 0.9996, and
    # by R / (R + h) at 100 m: the stations' coordinates are on that grid (6 cm over the street)
    scale = 0.9996 * 6_371_000.0 / (6_371_000.0 + 100.0)
    centre = np.mean([T[:3, 3] for T in T_crs_scan], axis=0)
    for T in T_crs_scan:
        T[:2, 3] = centre[:2] + scale * (T[:2, 3] - centre[:2])
    files = []
    for k, pts in enumerate(scans):
        files.append(tmp_path / f"scan_{k}.laz")
        io.write(files[-1], pts)
    rng = np.random.default_rng(0)
    rows = ["scan,x,y,z,sigma_xy,sigma_z"]
    for k in (0, 3, 7):
        xyz = T_crs_scan[k][:3, 3] + rng.normal(0.0, [0.01, 0.01, 0.015])
        rows.append(f"scan_{k}.laz,{xyz[0]:.4f},{xyz[1]:.4f},{xyz[2]:.4f},0.02,0.03")
    blunder = T_crs_scan[5][:3, 3] + [0.6, 0.0, 0.0]
    rows.append(f"scan_5.laz,{blunder[0]:.4f},{blunder[1]:.4f},{blunder[2]:.4f},0.02,0.03")
    (tmp_path / "control.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "out"
    args = ["--control", str(tmp_path / "control.csv"), "--crs", f"EPSG:{EPSG}", "-q"]
    res = _cli("chain_app", *map(str, files), "--out", str(out), "--jobs", "2", *args)
    assert res.returncode == 0, res.stderr

    poses = read_pose_list(out / "poses.txt")
    for k, T in enumerate(T_crs_scan):
        rot, trans = transform_errors(poses[f"scan_{k}.laz"], T)
        assert trans < 0.03 and rot < 0.05, (k, rot, trans)
    world_info = json.loads((out / "summary.json").read_text())["world"]
    assert world_info["frame"] == "control" and "25832" in world_info["crs"]
    assert abs(world_info["grid_scale"] - scale) < 1e-6
    used = {row["scan"]: row["used"] for row in world_info["controls"]}
    assert used == {"scan_0.laz": True, "scan_3.laz": True, "scan_7.laz": True, "scan_5.laz": False}
    assert "EPSG:25832" in (out / "poses.txt").read_text().splitlines()[1]

    laz = tmp_path / "street.laz"
    res = _cli("export_app", str(out), "--out", str(laz), "-q")
    assert res.returncode == 0, res.stderr
    cloud = laspy.read(laz)
    assert cloud.header.parse_crs().to_epsg() == EPSG
    xyz = np.column_stack([cloud.x, cloud.y, cloud.z])
    for k in (1, 6):  # scans without a station, far from the anchor
        mine = xyz[np.asarray(cloud.scan_index) == k]
        homog = np.column_stack([scans[k], np.ones(len(scans[k]))])
        true_points = (homog @ T_crs_scan[k].T)[:, :3]  # on the grid: scaled about the scanner
        true_points[:, :2] = T_crs_scan[k][:2, 3] + scale * (
            true_points[:, :2] - T_crs_scan[k][:2, 3]
        )
        assert len(mine) == len(true_points)  # in the order of the scan's file
        d = np.linalg.norm(mine - true_points, axis=1)
        assert np.percentile(d, 99) < 0.04, (k, np.percentile(d, 99))


@pytest.mark.parametrize("easting", [500_000.0, 650_000.0, 780_000.0])
def test_the_grid_scale_is_utms_point_scale_times_the_height_reduction(easting):
    """Independent reference: UTM's point scale k0 (1 + x^2 / 2R^2), x the distance from the
    central meridian (good to 1e-6 within a zone), and R / (R + h)."""
    from ndt_cli.io.crs import crs_wkt, grid_scale

    x, h, R = easting - 500_000.0, 350.0, 6_381_000.0
    expected = 0.9996 * (1 + x**2 / (2 * R**2)) * 6_371_000.0 / (6_371_000.0 + h)
    got = grid_scale(crs_wkt("EPSG:25832"), np.array([easting, 5_400_000.0, h]))
    assert abs(got - expected) < 1e-6
    assert grid_scale(crs_wkt("EPSG:25832+5783"), np.array([easting, 5_400_000.0, h])) == got


def test_a_station_named_by_a_file_name_two_folders_share_is_refused(tmp_path):
    """north/scan.xyz and south/scan.xyz: 'scan.xyz' names neither (the last one used to be
    taken, silently); the outputs' names do."""
    files = []
    for k, side in enumerate(("north", "south")):
        (tmp_path / side).mkdir()
        files.append(tmp_path / side / "scan.xyz")
        files[-1].write_text(f"{k} 0 0\n1 0 0\n0 1 0\n")  # two scans, not one copied
    (tmp_path / "control.csv").write_text("scan.xyz,1,2,3\n")
    args = [*map(str, files), "--out", str(tmp_path / "out"), "--control"]
    res = runner.invoke(chain_app, [*args, str(tmp_path / "control.csv")])
    assert res.exit_code == EXIT_INPUT, res.output
    needle = "line 1: 'scan.xyz' names 2 scans (north/scan.xyz, south/scan.xyz): name one as"
    assert needle in res.output and len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
