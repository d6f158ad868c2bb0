"""ndt-watch as a field crew meets it, with real processes: scans copied slowly onto the card,
a copy cut short and completed, a scan replaced in place, files on the card that are no scan,
a broken scan, an empty file and a log that never settles, the card pulled out, Ctrl-C; what
the screen says and what the JSON events say, checked against the files the run writes and
against the sample street's ground truth."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import laspy
import numpy as np
import pytest
from field_tools import ENV, SAMPLE, WATCH, Events, start_watch, write_slowly

from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_pose_list

pytestmark = pytest.mark.slow

TRUTH = read_pose_list(SAMPLE / "poses_T_world_scan.txt")
EXPORT = [sys.executable, "-c", "from ndt_cli.cli import export_app; export_app()"]


def _truth(anchor: str, content: str) -> np.ndarray:
    """``T_anchor_scan`` of the sample scan ``content`` in the frame of ``anchor``."""
    return np.linalg.inv(TRUTH[anchor]) @ TRUTH[content]


def _card(tmp_path: Path, *scans: str) -> Path:
    card = tmp_path / "card"
    card.mkdir()
    for name in scans:
        shutil.copy(SAMPLE / name, card / name)
    return card


def _check_against_outputs(events: Events, out: Path) -> None:
    """The last verdict of each scan is its row of poses.csv; the position of the scan placed
    last is that of poses.txt, those of earlier ones within millimetres (later scans adjusted
    in move them a little)."""
    final = events.final_verdicts()
    rows = {r["file"]: r for r in csv.DictReader((out / "poses.csv").open())}
    assert set(final) == set(rows)
    poses = read_pose_list(out / "poses.txt")
    last = events.of("placed", "fits_nowhere")[-1]["scan"]
    for name, e in final.items():
        assert e["status"] == rows[name]["status"], name
        assert e["cluster"] == (int(rows[name]["cluster"]) if rows[name]["cluster"] else None)
        if e["status"] == "ok" and e["cluster"] == 0:
            tol = 1e-9 if name == last else 0.01
            np.testing.assert_allclose(e["position"], poses[name][:3, 3], atol=tol)
    tally = events.of("stopped")[-1]["tally"]
    summary = json.loads((out / "summary.json").read_text())
    assert tally["scans"] == len(summary["scans"])
    assert tally["ok"] == len(poses)


def _exported_error(out: Path, tmp_path: Path, name: str, content: str, anchor: str) -> float:
    """Median distance (m) between the exported points of scan ``name`` and where the ground
    truth puts the points of the sample scan ``content`` (the anchor's frame)."""
    cloud = tmp_path / "street.laz"
    res = subprocess.run([*EXPORT, str(out), "--out", str(cloud), "-q"], env=ENV)
    assert res.returncode == 0
    las = laspy.read(cloud)
    index = json.loads((out / "summary.json").read_text())["scans"]
    k = [Path(p).name for p in index].index(name)
    mine = np.asarray(las["scan_index"]) == k
    got = np.column_stack([las.x, las.y, las.z])[mine]
    src = laspy.read(SAMPLE / content)
    T = _truth(anchor, content)
    want = np.column_stack([src.x, src.y, src.z]) @ T[:3, :3].T + T[:3, 3]
    assert len(got) == len(want)
    return float(np.median(np.linalg.norm(got - want, axis=1)))


def test_slow_copies_cut_copies_and_replaced_scans_are_followed(tmp_path):
    """E9, E1 (field mode), E19: a LAS written in pieces with pauses longer than the settle
    time, a LAZ copy cut short then completed, a scan replaced in place by another station's
    content; the card's other files named once and left alone."""
    card = _card(tmp_path, "scan_00.laz", "scan_01.laz")
    shutil.copy(SAMPLE / "poses_T_world_scan.txt", card / "poses.txt")
    (card / "control.csv").write_text("scan,x,y,z,sigma_xy,sigma_z\nscan_00.laz,1,2,3,,\n")
    (card / "garbage.laz").write_bytes(np.random.default_rng(0).bytes(5000))
    (card / "dir.laz").mkdir()
    (card / "empty.laz").write_bytes(b"")
    out = tmp_path / "out"
    run = start_watch(card, out, tmp_path / "log", "--json", "--exit-when-idle", "6")
    run.wait_for(lambda ev: len(ev.of("placed")) == 2)

    las = tmp_path / "scan_02.las"  # uncompressed: its size tells how much is missing
    laspy.read(SAMPLE / "scan_02.laz").write(las)
    writer = write_slowly(las, card / "scan_02.las", pieces=4, pause=1.5)
    assert writer.wait(60) == 0
    run.wait_for(lambda ev: any(e["event"] == "placed" for e in ev.about("scan_02.las")))

    data = (SAMPLE / "scan_03.laz").read_bytes()
    (card / "scan_03.laz").write_bytes(data[: len(data) * 2 // 5])  # a copy cut short
    run.wait_for(lambda ev: ev.about("scan_03.laz"))
    time.sleep(1.0)
    (card / "scan_03.laz").write_bytes(data)  # copied again, whole
    run.wait_for(lambda ev: any(e["event"] == "placed" for e in ev.about("scan_03.laz")))

    shutil.copy(SAMPLE / "scan_04.laz", card / "scan_03.laz")  # another station, same name
    run.wait_for(lambda ev: len(ev.of("placed", "fits_nowhere")) == 5)
    shutil.copy(SAMPLE / "scan_03.laz", card / "scan_05.laz")  # the station between, renamed
    assert run.wait(240) == 0, run.stderr()
    ev = run.events

    skipped = sorted(e["file"] for e in ev.of("skipped"))
    assert skipped == ["control.csv", "dir.laz", "garbage.laz", "poses.txt"]
    assert not ev.about("empty.laz") and not ev.of("removed")
    waited = [e for e in ev.of("unreadable") if e["file"] == "scan_02.las"]
    assert waited and all(e["state"] == "incomplete" for e in waited)  # the pieces so far
    cut = ev.about("scan_03.laz")
    assert cut[0]["event"] == "unreadable" and cut[0]["state"] == "incomplete"
    assert cut[0]["dropped"] == []
    replaced = ev.of("replaced")
    assert [(e["file"], e["dropped"]) for e in replaced] == [("scan_03.laz", ["scan_03.laz"])]
    assert not [e for e in ev.of("fits_nowhere") if e["scan"] != "scan_03.laz"]
    final = ev.final_verdicts()
    assert sorted(final) == [
        "scan_00.laz",
        "scan_01.laz",
        "scan_02.las",
        "scan_03.laz",
        "scan_05.laz",
    ]
    assert all(e["status"] == "ok" and e["cluster"] == 0 for e in final.values())
    assert ev.of("stopped")[-1]["exit_code"] == 0 and ev.of("stopped")[-1]["waiting"] == []
    _check_against_outputs(ev, out)

    poses = read_pose_list(out / "poses.txt")
    contents = {"scan_01.laz": "scan_01.laz", "scan_02.las": "scan_02.laz"}
    contents |= {"scan_03.laz": "scan_04.laz", "scan_05.laz": "scan_03.laz"}
    for name, content in contents.items():
        rot, trans = transform_errors(poses[name], _truth("scan_00.laz", content))
        assert rot < 0.2 and trans < 0.05, (name, rot, trans)
    err = _exported_error(out, tmp_path, "scan_03.laz", "scan_04.laz", "scan_00.laz")
    assert err < 0.05, err  # the new content where it stands, not at the old one's pose


def test_a_broken_first_scan_waits_and_never_becomes_the_anchor(tmp_path):
    """A LAZ whose header and size are whole but whose points cannot be read: unreadable (not
    "fits nowhere"), dropped, waited for; the next scan is the first; fixed, it is placed."""
    card = _card(tmp_path, "scan_01.laz", "scan_02.laz")
    broken = bytearray((SAMPLE / "scan_00.laz").read_bytes())
    broken[2000:60000] = bytes(58000)  # its compressed points overwritten with zeros
    (card / "scan_00.laz").write_bytes(bytes(broken))
    os.utime(card / "scan_00.laz", (time.time() - 600, time.time() - 600))  # landed first
    out = tmp_path / "out"
    run = start_watch(card, out, tmp_path / "log", "--json", "--exit-when-idle", "4")
    run.wait_for(lambda ev: len(ev.of("placed")) == 2)
    shutil.copy(SAMPLE / "scan_00.laz", card / "scan_00.laz")
    os.utime(card / "scan_01.laz")  # touched: the same content, nothing to do
    shutil.copy(SAMPLE / "scan_02.laz", card / "scan_02.laz")  # copied again, the same
    assert run.wait(240) == 0, run.stderr()
    ev = run.events
    assert [e["event"] for e in ev.about("scan_01.laz")] == ["landed", "placed"]
    assert [e["event"] for e in ev.about("scan_02.laz")] == ["landed", "placed"]
    assert ev.of("unreadable")[0]["file"] == "scan_00.laz"
    assert ev.of("unreadable")[0]["state"] == "unreadable"
    assert not ev.of("fits_nowhere")
    placed = ev.of("placed")
    assert [e["scan"] for e in placed] == ["scan_01.laz", "scan_02.laz", "scan_00.laz"]
    assert placed[0]["anchor"] and all(e["status"] == "ok" for e in placed)
    _check_against_outputs(ev, out)


def test_a_scan_file_of_many_scans_lands_as_its_scans(tmp_path):
    """E19: an E57 holding three setups is registered as FILE.e57#0, #1, #2."""
    pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli import sim
    from ndt_cli.io import e57

    _, scans, _ = sim.make_sequence(
        seed=21, n_scans=3, spacing=(13.0, 17.0), scan_kwargs={"n_azimuth": 1000}
    )
    card = tmp_path / "card"
    card.mkdir()
    e57.write(tmp_path / "street.e57", scans, [None] * 3)
    shutil.copy(tmp_path / "street.e57", card / "street.e57")
    run = start_watch(card, tmp_path / "out", tmp_path / "log", "--json", "--exit-when-idle", "3")
    assert run.wait(240) == 0, run.stderr()
    ev = run.events
    names = ["street.e57#0", "street.e57#1", "street.e57#2"]
    assert ev.of("landed")[0]["scans"] == names
    assert ev.of("landed")[0]["points"] == sum(len(s) for s in scans)
    assert [e["scan"] for e in ev.of("placed")] == names
    _check_against_outputs(ev, tmp_path / "out")


def _since_landed(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"\(([-0-9.e+]+) s since it landed\)", text)]


@pytest.mark.parametrize("idle", ["0.001", "3"])
def test_a_short_idle_time_registers_what_is_there_and_times_are_the_watchs(tmp_path, idle):
    """E25: --exit-when-idle 0.001 registers the scans already there; E26: "since it landed"
    counts from when the watch saw the scan land, whatever the file's time stamp says."""
    card = _card(tmp_path, "scan_00.laz", "scan_01.laz")
    os.utime(card / "scan_00.laz", (1546300800, 1546300800))  # 2019-01-01, as cp -p keeps it
    later = time.time() + 7200  # a scanner whose clock is two hours ahead
    os.utime(card / "scan_01.laz", (later, later))
    run = start_watch(card, tmp_path / "out", tmp_path / "log", "--exit-when-idle", idle)
    assert run.wait(240) == 0, run.stderr()
    since = _since_landed(run.stderr())
    assert len(since) == 2 and all(0 <= s < 60 for s in since), run.stderr()


def test_quiet_prints_only_what_needs_the_operator(tmp_path):
    """E27: with -q the ok scans and the files that are no scan print nothing; a scan that
    cannot be read yet and the closing lines are printed."""
    card = _card(tmp_path, "scan_00.laz", "scan_01.laz")
    (card / "garbage.laz").write_bytes(np.random.default_rng(0).bytes(5000))
    data = (SAMPLE / "scan_02.laz").read_bytes()
    (card / "scan_02.laz").write_bytes(data[: len(data) // 2])  # cut short, never completed
    run = start_watch(card, tmp_path / "out", tmp_path / "log", "-q", "--exit-when-idle", "3")
    assert run.wait(240) == 1  # a scan waits to be read whole
    lines = run.stderr().splitlines()
    assert lines[0].startswith("scan_02.laz: incomplete"), lines
    assert lines[1].startswith("idle: 2 scans: 2 ok; 1 file waiting to be read whole"), lines
    assert lines[2].startswith("  scan_02.laz: incomplete") and lines[3].startswith("outputs in")
    assert len(lines) == 4


def test_ctrl_c_ends_with_a_summary_and_exit_130(tmp_path):
    card = _card(tmp_path, "scan_00.laz", "scan_01.laz", "scan_02.laz")
    screen = start_watch(card, tmp_path / "out", tmp_path / "log")
    screen.wait_for(lambda ev: "so far: 1 scan" in screen.stderr())
    screen.signal_group(signal.SIGINT)  # Ctrl-C on a terminal: the whole process group
    assert screen.wait(120) == 130
    lines = screen.stderr().splitlines()
    assert "error" not in screen.stderr() and "Traceback" not in screen.stderr(), lines
    assert any(line.startswith("stopped (Ctrl-C): ") for line in lines), lines
    assert lines[-1].endswith("start ndt-watch again to continue")
    run = start_watch(card, tmp_path / "out2", tmp_path / "log2", "--json")
    run.wait_for(lambda ev: len(ev.of("placed")) >= 1)
    run.signal_group(signal.SIGINT)
    assert run.wait(120) == 130
    assert "error" not in run.stderr() and "Traceback" not in run.stderr(), run.stderr()
    stopped = run.events.of("stopped")
    assert len(stopped) == 1 and stopped[0]["why"] == "interrupted"
    assert stopped[0]["exit_code"] == 130 and stopped[0]["tally"]["scans"] >= 1


def test_an_empty_file_and_a_log_that_never_settles_do_not_hold_the_idle_exit(tmp_path):
    """E10: a zero-byte scan file and a text log appended every 0.1 s: the watch still ends
    once idle (exit 1: no scan)."""
    card = tmp_path / "card"
    card.mkdir()
    (card / "empty.laz").write_bytes(b"")
    log = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nwith open(sys.argv[1], 'a') as f:\n"
            "    for k in range(600):\n        f.write(f'{k} scanning\\n'); f.flush(); "
            "time.sleep(0.1)",
            str(card / "log.txt"),
        ]
    )
    try:
        run = start_watch(card, tmp_path / "out", tmp_path / "log", "--exit-when-idle", "2")
        assert run.wait(40) == 1, run.stderr()
    finally:
        log.kill()
        log.wait()
    text = run.stderr()
    assert "idle: no scan yet" in text and "empty.laz" not in text and "log.txt" not in text


def test_the_watched_folder_gone_and_back_is_said(tmp_path):
    """E25: a card pulled out is said, and its return."""
    card = tmp_path / "card"
    card.mkdir()
    run = start_watch(card, tmp_path / "out", tmp_path / "log", "--exit-when-idle", "5")
    run.wait_for_screen("ndt-watch: watching")  # the watch began: the folder was there
    card.rmdir()
    run.wait_for_screen("cannot be read (card pulled out?)")
    card.mkdir()
    assert run.wait(60) == 1
    text = run.stderr()
    gone, back = text.find("cannot be read (card pulled out?)"), text.find("can be read again")
    assert 0 < gone < back, text


def test_a_json_reader_gone_away_is_one_line_and_exit_2(tmp_path):
    card = tmp_path / "card"
    card.mkdir()
    cmd = [*WATCH, str(card), "--out", str(tmp_path / "out"), "-j", "1", "--json"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV, text=True)
    assert json.loads(proc.stdout.readline())["event"] == "started"
    proc.stdout.close()  # the reader stops (`ndt-watch --json | head -1`)
    (card / "notes.txt").write_text("no points here\n")  # an event to write
    assert proc.wait(60) == 2
    err = proc.stderr.read().strip().splitlines()
    assert err == ["ndt-watch: error: stdout was closed: the program reading --json stopped"]


def test_a_copy_of_a_scan_on_the_card_is_registered_once(tmp_path):
    """The same content under another name (a scan exported twice): skipped as a copy naming
    the scan it repeats; the outputs hold the scan once."""
    card = _card(tmp_path, "scan_00.laz", "scan_01.laz")
    shutil.copy(SAMPLE / "scan_01.laz", card / "scan_01_again.laz")
    os.utime(card / "scan_01_again.laz", (time.time() + 60, time.time() + 60))  # lands last
    out = tmp_path / "out"
    run = start_watch(card, out, tmp_path / "log", "--json", "--exit-when-idle", "3")
    assert run.wait(240) == 0, run.stderr()
    ev = run.events
    copy = ev.about("scan_01_again.laz")
    assert [e["event"] for e in copy] == ["landed", "skipped"], copy
    assert copy[1]["state"] == "copy" and "scan_01.laz" in copy[1]["reason"]
    assert [e["scan"] for e in ev.of("placed")] == ["scan_00.laz", "scan_01.laz"]
    _check_against_outputs(ev, out)
