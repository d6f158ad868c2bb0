"""ndt-watch: scans landing one by one (renamed in, out of order, written slowly in place) are
registered as they land, the outputs published after each; the result is that of a batch
ndt-chain of the same files; SIGTERM leaves a result a restart continues. The parts: when a
file has settled (:mod:`ndt_cli.pipeline.watch`), what a first look finds in it
(:mod:`ndt_cli.io.probe`), the events and the screen."""

from __future__ import annotations

import io
import json
import re
import signal
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import street_files
from field_tools import start_watch
from typer.testing import CliRunner

from ndt_cli.cli import chain_app, watch_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_pose_list
from ndt_cli.pipeline.closed_files import ClosedFiles
from ndt_cli.pipeline.field_events import (
    EventKind,
    FileNote,
    FolderNote,
    Landed,
    LinkNote,
    Placed,
    Revised,
    Started,
    Stopped,
    Tally,
    Verdict,
    event_dict,
)
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.pipeline.watch import FolderWatch

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def street8(tmp_path_factory):
    return street_files(tmp_path_factory.mktemp("street8"), n_scans=8)


def _rename_in(src: Path, folder: Path) -> None:
    """Copy under a temporary name, then rename: the scan appears whole."""
    tmp = folder / f".{src.name}.part"
    tmp.write_bytes(src.read_bytes())
    tmp.rename(folder / src.name)


def _write_slowly(src: Path, folder: Path, pieces: int = 6, pause: float = 0.15) -> None:
    """Write the scan in place, a piece at a time, faster than it settles."""
    data = src.read_bytes()
    step = len(data) // pieces + 1
    with open(folder / src.name, "wb") as fh:
        for k in range(0, len(data), step):
            fh.write(data[k : k + step])
            fh.flush()
            time.sleep(pause)


# ---------------------------------------------------------------- whole campaigns


@pytest.mark.slow
def test_scans_landing_one_by_one_are_all_ok_and_equal_the_batch(street8, tmp_path):
    files, _ = street8
    folder, out = tmp_path / "card", tmp_path / "field"
    folder.mkdir()
    run = start_watch(folder, out, tmp_path, "--exit-when-idle", "4", "--json")
    landing = [0, 1, 2, 4, 3, 5, 6, 7]  # scan 4 lands before scan 3
    for n, k in enumerate(landing):
        if k == 5:
            _write_slowly(files[k], folder)
        else:
            _rename_in(files[k], folder)
        run.wait_for(lambda ev, n=n: len(ev.of("placed")) >= n + 1)
    assert run.wait(240) == 0, run.stderr()
    placed = run.events.of("placed")
    assert [e["scan"] for e in placed] == [files[k].name for k in landing]
    assert all(e["status"] == "ok" and e["cluster"] == 0 for e in placed)
    assert placed[0]["anchor"] and not any(e["anchor"] for e in placed[1:])
    assert not run.events.of("unreadable", "fits_nowhere", "skipped")
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
    run = start_watch(folder, out, tmp_path)
    run.wait_for(lambda ev: "so far: 2 scans" in run.stderr())
    run.signal_group(signal.SIGTERM)  # as systemd and `timeout` do: the workers get it too
    assert run.wait(120) == 130
    text = run.stderr()
    assert "Traceback" not in text and "error:" not in text, text
    assert "stopped: " in text and "start ndt-watch again" in text.splitlines()[-1]
    summary = json.loads((out / "summary.json").read_text())  # a whole, earlier result
    assert 2 <= len(summary["scans"]) <= 3
    _rename_in(files[3], folder)
    again = start_watch(folder, out, tmp_path / "again", "--exit-when-idle", "3")
    assert again.wait(240) == 0, again.stderr()
    assert len(read_pose_list(out / "poses.txt")) == 4
    assert json.loads((out / "summary.json").read_text())["reused"] >= 1


# ---------------------------------------------------------------- options


def test_bad_watch_options_are_one_line_and_exit_2(tmp_path):
    res = runner.invoke(watch_app, [str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "not a folder" in res.stderr
    for value, bound in (("-1", "above 0"), ("1e7", "at most 1e+06 s")):
        res = runner.invoke(watch_app, [str(tmp_path), "--exit-when-idle", value])
        assert res.exit_code == 2 and "--exit-when-idle" in res.stderr and bound in res.stderr
        assert len(res.stderr.strip().splitlines()) == 1


def test_the_help_says_what_quiet_keeps_and_what_json_prints():
    res = runner.invoke(watch_app, ["--help"], terminal_width=100)
    text = " ".join(res.output.split())
    assert "-q, --quiet Print only what needs you: scans that are not ok" in text
    assert "--json Print one JSON object per line and event" in text


# ---------------------------------------------------------------- when a file has settled


def _touch(path: Path, data: bytes) -> None:
    path.write_bytes(data)


def test_a_file_lands_once_it_stops_changing(tmp_path):
    watch = FolderWatch(tmp_path, (".laz",), settle_s=1.0)
    _touch(tmp_path / "a.laz", b"1234")
    _touch(tmp_path / ".b.laz", b"1234")  # hidden: a copy in progress
    _touch(tmp_path / "c.laz.part", b"1234")
    first = watch.look(now=0.0)
    assert first.settled == () and first.busy and watch.writing() == [tmp_path / "a.laz"]
    assert watch.look(now=0.5).settled == ()  # not settled yet
    with open(tmp_path / "a.laz", "ab") as fh:
        fh.write(b"5678")  # still being written: open
        fh.flush()
        assert watch.look(now=1.2).settled == ()
    landed = watch.look(now=2.3).settled
    assert [s.path.name for s in landed] == ["a.laz"]
    assert np.isclose(landed[0].mtime, (tmp_path / "a.laz").stat().st_mtime)
    later = watch.look(now=9.0)
    assert later.settled == () and not later.busy and watch.writing() == []


def test_a_file_that_changes_after_landing_is_handed_out_again(tmp_path):
    watch = FolderWatch(tmp_path, (".laz",), settle_s=0.5)
    _touch(tmp_path / "a.laz", b"12")
    watch.look(now=0.0)
    assert len(watch.look(now=1.0).settled) == 1
    assert watch.look(now=2.0).settled == ()
    with open(tmp_path / "a.laz", "wb") as fh:  # a copy over it, in progress
        fh.write(b"a whole new")
        fh.flush()
        assert watch.look(now=3.0).settled == ()
        fh.write(b" content")
    assert [s.path.name for s in watch.look(now=4.0).settled] == ["a.laz"]


needs_inotify = pytest.mark.skipif(
    not ClosedFiles(Path(__file__).parent).active, reason="no inotify on this system"
)


@needs_inotify
def test_a_file_its_writer_closed_is_handed_out_at_the_next_look(tmp_path):
    watch = FolderWatch(tmp_path, (".laz",), settle_s=100.0)  # never settled by time here
    watch.look(now=0.0)  # the watch begins
    with open(tmp_path / "a.laz", "wb") as fh:
        fh.write(b"1234")
        fh.flush()
        assert watch.look(now=0.1).settled == ()  # open: still being written
    assert [s.path.name for s in watch.look(now=0.2).settled] == ["a.laz"]
    with open(tmp_path / "a.laz", "ab") as fh:  # written again after its close: not finished
        fh.write(b"5678")
        fh.flush()
        assert watch.look(now=0.3).settled == ()
    assert [s.path.name for s in watch.look(now=0.4).settled] == ["a.laz"]  # closed again


@needs_inotify
def test_a_file_renamed_in_whole_is_handed_out_at_the_next_look(tmp_path):
    watch = FolderWatch(tmp_path, (".laz",), settle_s=100.0)
    watch.look(now=0.0)
    part = tmp_path / "b.laz.part"
    _touch(part, b"whole")  # a temporary name: never looked at
    assert watch.look(now=0.1).settled == ()
    part.rename(tmp_path / "b.laz")
    assert [s.path.name for s in watch.look(now=0.2).settled] == ["b.laz"]


@needs_inotify
def test_a_file_changed_after_its_close_waits_for_the_settle_time(tmp_path):
    watch = FolderWatch(tmp_path, (".laz",), settle_s=0.5)
    watch.look(now=0.0)
    _touch(tmp_path / "c.laz", b"1234")  # closed ...
    with open(tmp_path / "c.laz", "ab") as fh:  # ... and opened again by another writer
        fh.write(b"56")
        fh.flush()
        assert watch.look(now=0.1).settled == ()  # the state after the close is not finished
        assert watch.look(now=0.4).settled == ()
        assert [s.path.name for s in watch.look(now=0.7).settled] == ["c.laz"]  # by time


@needs_inotify
def test_a_finished_file_never_overtakes_one_that_landed_before_it(tmp_path):
    _touch(tmp_path / "a.laz", b"1234")  # on the card before the watch began: no event
    watch = FolderWatch(tmp_path, (".laz",), settle_s=0.5)
    assert watch.look(now=0.0).settled == ()
    _touch(tmp_path / "b.laz.part", b"5678")
    (tmp_path / "b.laz.part").rename(tmp_path / "b.laz")
    assert watch.look(now=0.1).settled == ()  # b is finished, but a is still settling
    assert [s.path.name for s in watch.look(now=0.7).settled] == ["a.laz", "b.laz"]


@needs_inotify
def test_a_folder_made_again_is_watched_again(tmp_path):
    folder = tmp_path / "card"
    folder.mkdir()
    watch = FolderWatch(folder, (".laz",), settle_s=100.0)
    watch.look(now=0.0)
    folder.rmdir()  # the card taken out ...
    assert not watch.look(now=0.1).present
    folder.mkdir()  # ... and in again
    watch.look(now=0.2)
    _touch(folder / "a.laz", b"1234")
    assert [s.path.name for s in watch.look(now=0.3).settled] == ["a.laz"]


def test_without_inotify_a_closed_file_waits_for_the_settle_time(tmp_path, monkeypatch):
    from ndt_cli.pipeline import closed_files

    monkeypatch.setattr(closed_files, "_libc", lambda: None)
    watch = FolderWatch(tmp_path, (".laz",), settle_s=0.5)
    watch.look(now=0.0)
    _touch(tmp_path / "a.laz", b"1234")  # closed, renamed or not: the system tells nothing
    _touch(tmp_path / "b.laz.part", b"5678")
    (tmp_path / "b.laz.part").rename(tmp_path / "b.laz")
    assert watch.look(now=0.1).settled == ()
    assert watch.look(now=0.4).settled == ()
    names = [s.path.name for s in watch.look(now=0.7).settled]
    assert sorted(names) == ["a.laz", "b.laz"]


def test_finished_names_come_from_the_last_event_a_writer_caused():
    from ndt_cli.pipeline.closed_files import (
        IN_CLOSE_WRITE,
        IN_IGNORED,
        IN_MODIFY,
        IN_MOVED_TO,
        IN_Q_OVERFLOW,
        _parse,
    )

    def event(mask: int, name: bytes) -> bytes:
        padded = name + b"\0" * (16 - len(name) % 16) if name else b""
        return struct.pack("iIII", 1, mask, 0, len(padded)) + padded

    def finished(*events: bytes) -> set[str]:
        last: dict[str, bool] = {}
        overflow = _parse(b"".join(events), last)
        return {"overflow"} if overflow else {n for n, done in last.items() if done}

    closed, moved = event(IN_CLOSE_WRITE, b"a.laz"), event(IN_MOVED_TO, b"b.las")
    assert finished(event(IN_MODIFY, b"a.laz"), closed, moved) == {"a.laz", "b.las"}
    assert finished(closed, event(IN_MODIFY, b"a.laz")) == set()  # written again since
    assert finished(event(0x100, b"new.laz")) == set()  # IN_CREATE: not finished
    assert finished(event(IN_CLOSE_WRITE, "é.laz".encode())) == {"é.laz"}
    assert finished(closed, event(IN_Q_OVERFLOW, b"")) == {"overflow"}
    assert finished(closed, event(IN_IGNORED, b"")) == {"overflow"}  # the folder went
    assert not ClosedFiles(Path("/no/such/folder")).active
    assert ClosedFiles(Path("/no/such/folder")).events() == {}


def test_a_file_asked_again_is_handed_out_once_more_only(tmp_path):
    watch = FolderWatch(tmp_path, (".laz",), settle_s=0.5)
    _touch(tmp_path / "a.laz", b"12")
    watch.look(now=0.0)
    assert len(watch.look(now=1.0).settled) == 1
    watch.again(tmp_path / "a.laz", now=1.0)
    assert watch.look(now=1.2).settled == () and watch.look(now=1.2).busy
    assert len(watch.look(now=1.6).settled) == 1  # once more, unchanged
    watch.again(tmp_path / "a.laz", now=1.6)
    assert watch.look(now=5.0).settled == ()  # not twice in the same state


def test_a_handed_out_file_is_gone_after_two_looks_without_it(tmp_path):
    watch = FolderWatch(tmp_path, (".laz",), settle_s=0.5)
    _touch(tmp_path / "a.laz", b"12")
    _touch(tmp_path / "b.laz", b"12")
    watch.look(now=0.0)
    watch.look(now=1.0)
    (tmp_path / "a.laz").unlink()
    assert watch.look(now=1.2).gone == ()
    assert watch.look(now=1.4).gone == (tmp_path / "a.laz",)
    assert watch.look(now=1.6).gone == ()


def test_empty_files_and_files_that_never_settle_hold_no_idle_watch(tmp_path):
    watch = FolderWatch(tmp_path, (".laz", ".txt"), settle_s=0.5, hold_s=3.0)
    _touch(tmp_path / "empty.laz", b"")
    assert not watch.look(now=0.0).busy  # an empty file is not looked at
    busy = []
    with open(tmp_path / "log.txt", "a") as log:  # a log kept open and appended every 0.2 s
        for k in range(40):  # never settled: busy for hold_s only
            log.write(f"line {k}\n")
            log.flush()
            busy.append(watch.look(now=0.2 * k + 0.01).busy)
    assert all(busy[:15]) and not any(busy[16:])


def test_a_file_left_alone_keeps_nobody_busy(tmp_path):
    watch = FolderWatch(tmp_path, (".txt",), settle_s=0.5)
    _touch(tmp_path / "notes.txt", b"hello")
    watch.look(now=0.0)
    assert len(watch.look(now=1.0).settled) == 1
    watch.leave_alone(tmp_path / "notes.txt")
    _touch(tmp_path / "notes.txt", b"hello again")
    second = watch.look(now=2.0)  # settled now where the system tells that it was closed
    assert not second.busy
    assert len(second.settled + watch.look(now=3.0).settled) == 1  # still looked at


def test_a_folder_that_cannot_be_read_is_told_apart_from_an_empty_one(tmp_path):
    folder = tmp_path / "card"
    folder.mkdir()
    watch = FolderWatch(folder, (".laz",))
    assert watch.look(now=0.0).present
    folder.rmdir()
    assert not watch.look(now=1.0).present


def test_the_control_file_in_the_watched_folder_is_never_looked_at(tmp_path):
    (tmp_path / "control.csv").write_text("scan,x,y,z\n")
    watch = FolderWatch(tmp_path, (".csv",), settle_s=0.1, skip=(tmp_path / "control.csv",))
    watch.look(now=0.0)
    assert watch.look(now=1.0).settled == () and watch.files == {}


# ---------------------------------------------------------------- events and the screen

LONG = "Station_2024-05-12_north_side_of_the_market_square_0013.laz"


def _verdict(name: str, status: NodeStatus = NodeStatus.OK, cluster: int | None = 0) -> Verdict:
    links = (
        LinkNote(LONG, EdgeState.CONFIRMED, "ok", 0.62, 0.84),
        LinkNote("scan_007.las", EdgeState.USED, "ok", 0.41, None),
        LinkNote("scan_003.las", EdgeState.UNUSED, "suspect", 0.12, None, "free space: 21%"),
    )
    where = None if status is NodeStatus.UNPOSED else (-10.85, 59.15, -0.01)
    return Verdict(name, status, cluster, where, links if where else (), "no link", False)


def _all_events() -> list:
    tally = Tally(10, 8, 0, 1, 1, 1)
    return [
        Started("/media/usb/" + LONG, "street/", "default", 2, 0.5, 600.0, None, None),
        Landed(LONG, (LONG,), 205_000),
        Placed(EventKind.PLACED, _verdict(LONG), 2.7, 3.4, tally),
        Placed(EventKind.FITS_NOWHERE, _verdict("scan_009.las", NodeStatus.UNPOSED), 3, 4, tally),
        Revised(_verdict("scan_002.las"), "fits nowhere", tally),
        FileNote(EventKind.UNREADABLE, LONG, "incomplete", "its header announces 5 points"),
        FileNote(EventKind.SKIPPED, "poses.txt", "not_a_scan", "no row of x y z numbers"),
        FileNote(EventKind.REPLACED, LONG, "", "new content", (LONG,)),
        FileNote(EventKind.REMOVED, LONG, "", "gone from the folder", (LONG,)),
        FolderNote("/media/usb/scans", False),
        Stopped("interrupted", 130, "street/", tally, (("scan_009.las", "fits nowhere"),)),
    ]


@pytest.mark.parametrize("width", [80, 120])
def test_the_screen_fits_the_terminal_and_never_cuts_a_name(width):
    from rich.console import Console

    from ndt_cli.cli.watch_screen import Screen

    buf = io.StringIO()
    screen = Screen(console=Console(file=buf, width=width, force_terminal=False))
    for event in _all_events():
        screen.show(event)
    text = buf.getvalue()
    assert max(len(line) for line in text.splitlines()) <= width
    assert text.count(LONG) >= 6  # every mention whole, on one line
    flat = " ".join(text.split())
    assert "FITS NOWHERE" in flat and "now ok (was fits nowhere)" in flat
    assert "checked, residual 0.8 cm" in flat and "not checked" in flat


@pytest.mark.parametrize("terminal", [True, False])
def test_the_summary_after_ctrl_c_starts_below_the_terminals_echo(terminal):
    from rich.console import Console

    from ndt_cli.cli.watch_screen import Screen

    buf = io.StringIO()
    screen = Screen(console=Console(file=buf, width=80, force_terminal=terminal))
    screen.show(_all_events()[-1])
    first = buf.getvalue().split("\n")[0]
    # on a terminal "^C" was echoed where the cursor stood: the summary starts a line below it
    assert (first == "") is terminal
    assert "stopped (Ctrl-C)" in buf.getvalue()


def test_quiet_shows_only_what_needs_the_operator():
    from rich.console import Console

    from ndt_cli.cli.watch_screen import Screen

    buf = io.StringIO()
    screen = Screen(quiet=True, console=Console(file=buf, width=120))
    for event in _all_events():
        screen.show(event)
    heads = [line.split(":")[0] for line in buf.getvalue().splitlines() if line[:1] != " "]
    folder = "the watched folder /media/usb/scans cannot be read (card pulled out?)"
    assert heads[:4] == ["scan_009.las", LONG, folder, "stopped (Ctrl-C)"]
    assert len(heads) == 5 and heads[4].startswith("the outputs in street/ hold every scan")


def _documented_events() -> dict[str, list[str]]:
    """The events and their fields as docs/deliverables.md lists them."""
    text = (ROOT / "docs" / "deliverables.md").read_text()
    rows = re.findall(r"^\| `(\w+)` \| (.+?) \|$", text, flags=re.MULTILINE)
    return {k: re.findall(r"`(\w+)`", fields) for k, fields in rows if k in set(EventKind)}


def test_every_event_has_the_fields_the_docs_list():
    documented = _documented_events()
    assert set(documented) == set(EventKind)
    seen = set()
    for event in _all_events():
        data = json.loads(json.dumps(event_dict(event)))
        assert list(data) == ["event", "time", *documented[data["event"]]], data["event"]
        seen.add(data["event"])
    assert seen == set(EventKind)
