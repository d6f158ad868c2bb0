"""ndt-watch: scans landing one by one (renamed in, out of order, written slowly in place) are
registered as they land, one log line each, the outputs published after each; the result is
that of a batch ndt-chain of the same files; SIGTERM leaves a result a restart continues."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import street_files
from typer.testing import CliRunner

from ndt_cli.cli import chain_app, watch_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_pose_list

runner = CliRunner()
WATCH = [sys.executable, "-c", "from ndt_cli.cli import watch_app; watch_app()"]
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


@pytest.fixture(scope="module")
def street8(tmp_path_factory):
    return street_files(tmp_path_factory.mktemp("street8"), n_scans=8)


def _rename_in(src: Path, folder: Path) -> None:
    """Copy under a temporary name, then rename: the scan appears whole."""
    tmp = folder / f".{src.name}.part"
    tmp.write_bytes(src.read_bytes())
    tmp.rename(folder / src.name)


def _write_slowly(src: Path, folder: Path, pieces: int = 6, pause: float = 0.15) -> None:
    """Write the scan in place, a piece at a time (a scanner exporting it)."""
    data = src.read_bytes()
    step = len(data) // pieces + 1
    with open(folder / src.name, "wb") as fh:
        for k in range(0, len(data), step):
            fh.write(data[k : k + step])
            fh.flush()
            time.sleep(pause)


def _wait_for_lines(log: Path, n: int, proc: subprocess.Popen, limit: float = 240.0) -> None:
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline and proc.poll() is None:
        if log.exists() and len(log.read_text().splitlines()) >= n:
            return
        time.sleep(0.1)


def _watch(folder: Path, out: Path, log: Path, *extra: str) -> subprocess.Popen:
    cmd = [*WATCH, str(folder), "--out", str(out), "-j", "2", *extra]
    return subprocess.Popen(cmd, stderr=log.open("w"), env=ENV)


@pytest.mark.slow
def test_scans_landing_one_by_one_are_all_ok_and_equal_the_batch(street8, tmp_path):
    files, _ = street8
    folder, out, log = tmp_path / "card", tmp_path / "field", tmp_path / "watch.log"
    folder.mkdir()
    proc = _watch(folder, out, log, "--exit-when-idle", "4")
    landing = [0, 1, 2, 4, 3, 5, 6, 7]  # scan 4 lands before scan 3
    for n, k in enumerate(landing):
        if k == 5:
            _write_slowly(files[k], folder)
        else:
            _rename_in(files[k], folder)
        _wait_for_lines(log, n + 1, proc)
    assert proc.wait(timeout=240) == 0, log.read_text()  # every scan ok, then idle
    lines = log.read_text().splitlines()
    assert len(lines) == 8, lines
    assert [line.split(":")[0] for line in lines] == [files[k].name for k in landing]
    assert all(" ok at " in line for line in lines[1:]) and "world frame" in lines[0]
    field = read_pose_list(out / "poses.txt")
    batch = tmp_path / "batch"
    assert runner.invoke(chain_app, [*map(str, files), "-o", str(batch), "-q"]).exit_code == 0
    for name, T in read_pose_list(batch / "poses.txt").items():
        rot, trans = transform_errors(field[name], T)
        assert rot < 0.001 and trans < 0.001, (name, rot, trans)


@pytest.mark.slow
def test_sigterm_leaves_a_consistent_result_and_a_restart_continues(street8, tmp_path):
    files, _ = street8
    folder, out = tmp_path / "card", tmp_path / "field"
    folder.mkdir()
    for f in files[:3]:
        _rename_in(f, folder)
    log = tmp_path / "first.log"
    proc = _watch(folder, out, log)
    _wait_for_lines(log, 2, proc)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=120) == 130
    lines = log.read_text().splitlines()
    assert "Traceback" not in log.read_text() and "start" in lines[-1]
    summary = json.loads((out / "summary.json").read_text())  # a whole, earlier result
    assert 2 <= len(summary["scans"]) <= 3
    _rename_in(files[3], folder)
    again = tmp_path / "again.log"
    proc = _watch(folder, out, again, "--exit-when-idle", "3")
    assert proc.wait(timeout=240) == 0, again.read_text()
    assert len(read_pose_list(out / "poses.txt")) == 4
    assert json.loads((out / "summary.json").read_text())["reused"] >= 1


def test_bad_watch_options_are_one_line_and_exit_2(tmp_path):
    res = runner.invoke(watch_app, [str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "not a folder" in res.stderr
    res = runner.invoke(watch_app, [str(tmp_path), "--exit-when-idle", "-1"])
    assert res.exit_code == 2 and "--exit-when-idle" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_a_file_lands_once_it_stops_changing(tmp_path):
    from ndt_cli.pipeline.watch import FolderWatch

    watch = FolderWatch(tmp_path, (".laz",), settle_s=1.0)
    (tmp_path / "a.laz").write_bytes(b"1234")
    (tmp_path / ".b.laz").write_bytes(b"1234")  # hidden: a copy in progress
    (tmp_path / "c.laz.part").write_bytes(b"1234")
    assert watch.poll(now=0.0) == [] and watch.pending == 1
    assert watch.poll(now=0.5) == []  # not settled yet
    with open(tmp_path / "a.laz", "ab") as fh:
        fh.write(b"5678")  # still being written
    assert watch.poll(now=1.2) == []
    landed = watch.poll(now=2.3)
    assert [s.path.name for s in landed] == ["a.laz"] and watch.poll(now=9.0) == []
    assert np.isclose(landed[0].mtime, (tmp_path / "a.laz").stat().st_mtime)
