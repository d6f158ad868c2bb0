"""ndt-chain: chained poses against ground truth, parallel = serial, kill and resume,
unreadable scans, and the real MULLS street sequence."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import shared_data, street_files
from typer.testing import CliRunner

from ndt_cli import io, sim
from ndt_cli.cli import chain_app
from ndt_cli.core.transforms import yaw_of
from ndt_cli.io.matrices import read_matrix, read_pose_list
from ndt_cli.pipeline.chain import plan_links
from ndt_cli.pipeline.scans import natural_sort

runner = CliRunner()
CHAIN = [sys.executable, "-c", "from ndt_cli.cli import chain_app; chain_app()"]


def planar_errors(T, T_ref):
    dyaw = np.degrees(np.angle(np.exp(1j * (yaw_of(T) - yaw_of(T_ref)))))
    return abs(float(dyaw)), float(np.hypot(*(T[:2, 3] - T_ref[:2, 3])))


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    return street_files(tmp_path_factory.mktemp("seq"))


def link_T(out, a, b):
    """T_a_b of the link between scans a and b (file stems), whichever is its target."""
    forward = out / f"T_{a}_{b}.txt"
    if forward.exists():
        return read_matrix(forward)
    return np.linalg.inv(read_matrix(out / f"T_{b}_{a}.txt"))


def world_gt(poses):
    """Ground truth T_world_scan with scan 0 as the world."""
    inv0 = np.linalg.inv(poses[0])
    return [inv0 @ T for T in poses]


def run(files, out, *extra):
    return runner.invoke(chain_app, [*map(str, files), "--out", str(out), "--quiet", *extra])


def outputs(out):
    """The chain's outputs that must not depend on jobs or interruption (no timings)."""
    pairs = [line.rsplit(",", 3)[0] for line in (out / "pairs.csv").read_text().splitlines()]
    cols = (out / "pairs.csv").read_text().splitlines()[0].split(",")
    keep = [i for i, c in enumerate(cols) if c != "runtime_s"]
    pairs = [
        [row.split(",")[i] for i in keep] for row in (out / "pairs.csv").read_text().splitlines()
    ]
    links = {p.name: p.read_text() for p in sorted(out.glob("T_*.txt"))}
    return pairs, (out / "poses.txt").read_text(), (out / "poses.csv").read_text(), links


@pytest.mark.slow
def test_chain_recovers_ground_truth_and_jobs_do_not_matter(sequence, tmp_path):
    files, poses = sequence
    res1 = run(files, tmp_path / "j1", "--jobs", "1")
    assert res1.exit_code == 0, res1.output
    est = read_pose_list(tmp_path / "j1" / "poses.txt")
    gt = world_gt(poses)
    for k, f in enumerate(files):
        rot, trans = planar_errors(est[f.name], gt[k])
        assert rot < 0.3 and trans < 0.15 * max(k, 1), (k, rot, trans)
    for k in range(1, len(files)):
        T = link_T(tmp_path / "j1", f"scan_{k - 1}", f"scan_{k}")
        rot, trans = planar_errors(T, np.linalg.inv(poses[k - 1]) @ poses[k])
        assert rot < 0.3 and trans < 0.15
    summary = json.loads((tmp_path / "j1" / "summary.json").read_text())
    assert summary["ok"] >= 3 and summary["all_ok"] is True
    assert (tmp_path / "j1" / "config_used.yaml").exists()
    res2 = run(files, tmp_path / "j2", "--jobs", "2")
    assert res2.exit_code == 0
    assert outputs(tmp_path / "j1") == outputs(tmp_path / "j2")


START_METHOD = """
import sys, threading, numba, numpy as np
from ndt_cli import io
from ndt_cli.pipeline.local_pool import start_method
print(start_method())
stop = threading.Event()
other = threading.Thread(target=stop.wait)
other.start()
print(start_method())
stop.set()
other.join()
import time
for _ in range(200):  # the joined thread leaves the OS's list a moment later
    if start_method() == "fork":
        break
    time.sleep(0.01)
print(start_method())
io.read(sys.argv[1])  # the LAZ decoder's thread pool runs
print(start_method())
"""


@pytest.mark.slow
def test_workers_are_forked_only_from_a_parent_with_one_thread(sequence):
    """Fork from a fresh process with Numba imported; from a fork server while another thread
    runs, and once a thread pool (here the LAZ decoder's) has run: a child forked from such a
    parent could wait forever."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, "-c", START_METHOD, str(sequence[0][0])],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    ).stdout.split()
    assert out == ["fork", "forkserver", "fork", "forkserver"]


@pytest.mark.slow
def test_workers_forked_by_the_command_or_a_fork_server_give_the_same_network(sequence, tmp_path):
    """The command forks its workers; a process whose Numba threads ran has a fork server fork
    them. The outputs are the same."""
    import numba

    from ndt_cli.pipeline.local_pool import start_method

    files, _ = sequence
    numba.njit(parallel=True)(lambda a: a.sum())(np.ones(4))  # Numba's threads run here
    assert start_method() == "forkserver"
    assert run(files, tmp_path / "served", "--jobs", "2").exit_code == 0
    cmd = [*CHAIN, *map(str, files), "--out", str(tmp_path / "forked"), "--jobs", "2"]
    forked = subprocess.run([*cmd, "--verbose"], capture_output=True, text=True)
    assert forked.returncode == 0, forked.stderr
    assert "worker process(es) by fork" in forked.stderr
    assert outputs(tmp_path / "served") == outputs(tmp_path / "forked")


@pytest.mark.slow
def test_anchor_defines_the_world(sequence, tmp_path):
    files, poses = sequence
    assert run(files, tmp_path / "a", "--anchor", "2", "--jobs", "2").exit_code == 0
    est = read_pose_list(tmp_path / "a" / "poses.txt")
    anchor = est[files[2].name]  # its own frame, tipped level about its ground point
    tilt = np.degrees(np.arccos(np.clip(anchor[2, 2], -1, 1)))
    true_tilt = np.degrees(np.arccos(np.clip(poses[2][2, 2], -1, 1)))
    assert abs(tilt - true_tilt) < 0.05 and abs(anchor[1, 0]) < 1e-3  # no turn about z
    assert np.linalg.norm(anchor[:3, 3]) < 0.1  # its coordinates kept near its scanner
    ref = np.linalg.inv(poses[2]) @ poses[0]
    rot, trans = planar_errors(np.linalg.inv(anchor) @ est[files[0].name], ref)
    assert rot < 0.5 and trans < 0.3


@pytest.mark.slow
def test_unusable_scan_in_the_middle_fails_its_link_and_the_chain_goes_on(sequence, tmp_path):
    """A scan whose file is sound but holds no usable point (every point a no-return (0,0,0)):
    what a header cannot tell (a file cut short is refused before any work)."""
    files, poses = sequence
    bad = tmp_path / "scan_1.laz"
    io.write(bad, np.zeros((1000, 3)))
    chain = [files[0], bad, files[2], files[3]]
    classic = ("--neighbours", "1", "--no-adjust")
    res = run(chain, tmp_path / "o", "--jobs", "2", *classic)
    assert res.exit_code == 1
    rows = (tmp_path / "o" / "pairs.csv").read_text().splitlines()
    assert "failed" in rows[1] and "scan_1.laz" in rows[1]
    assert rows[2].split(",")[1:3] == ["scan_0.laz", "scan_2.laz"]  # next pair it can form
    est = read_pose_list(tmp_path / "o" / "poses.txt")
    assert "scan_1.laz" not in est
    for k, name in [(2, "scan_2.laz"), (3, "scan_3.laz")]:  # posed only through ok links: right
        if name in est:
            rot, trans = planar_errors(est[name], world_gt(poses)[k])
            assert rot < 0.5 and trans < 0.3


def test_natural_sort_and_link_plan():
    names = ["b/s10.las", "a/s2.las", "S1.las", "c/s2b.las", "b/s1.las"]
    assert [str(p) for p in natural_sort(names)] == [
        "b/s1.las",
        "S1.las",
        "a/s2.las",
        "c/s2b.las",
        "b/s10.las",
    ]
    assert plan_links(5, set()) == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert plan_links(5, {2}) == [(0, 1), (1, 2), (1, 3), (3, 4)]


def test_bad_chain_input_is_exit_2(tmp_path):
    res = runner.invoke(chain_app, [str(tmp_path / "only.laz"), "--quiet"])
    assert res.exit_code == 2 and "at least two" in res.stderr


@pytest.mark.slow
def test_mulls_street_sequence_matches_icp_reference(tmp_path):
    folder = shared_data("mulls_demo_hdl64_sequence")
    refs = np.loadtxt(folder / "reference_icp_relative_4x4.txt").reshape(-1, 4, 4)
    files = sorted(folder.glob("*.pcd"))
    res = run(files, tmp_path / "m", "--jobs", "2")
    assert res.exit_code == 0, res.output
    for k in range(1, len(files)):
        T = link_T(tmp_path / "m", files[k - 1].stem, files[k].stem)
        rot, trans = planar_errors(T, refs[k - 1])
        assert rot < 0.5 and trans < 0.10, (k, rot, trans)


@pytest.mark.slow
def test_chain_registers_the_scans_inside_one_e57_file(tmp_path):
    pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli.io import e57

    _, scans, poses = sim.make_sequence(
        seed=21, n_scans=3, spacing=(13.0, 17.0), scan_kwargs={"n_azimuth": 1000}
    )
    header = [np.linalg.inv(poses[0]) @ T for T in poses]  # what a scanner might have stored
    campaign = tmp_path / "campaign.e57"
    e57.write(campaign, scans, header)
    res = runner.invoke(chain_app, [str(campaign), "--out", str(tmp_path / "o"), "--quiet"])
    assert res.exit_code == 0, res.output
    est = read_pose_list(tmp_path / "o" / "poses.txt")
    assert sorted(est) == ["campaign.e57#0", "campaign.e57#1", "campaign.e57#2"]
    for k in range(3):
        rot, trans = planar_errors(est[f"campaign.e57#{k}"], world_gt(poses)[k])
        assert rot < 0.3 and trans < 0.2
    stored = read_pose_list(tmp_path / "o" / "e57_header_poses.txt")
    np.testing.assert_allclose(stored["campaign.e57#2"], header[2], atol=1e-9)
