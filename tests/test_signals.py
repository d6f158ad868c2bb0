"""Signals to the commands of many processes: Ctrl-C twice (or ``timeout -s INT``, which signals
the command and then its process group), SIGTERM to the process group, and SIGKILL to the
main process. None hangs, none prints a worker's traceback, and no worker process outlives
the command. The commands run in a process group of their own, as a terminal starts them."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import street_files

ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
CHAIN = [sys.executable, "-c", "from ndt_cli.cli import chain_app; chain_app()"]
WATCH = [sys.executable, "-c", "from ndt_cli.cli import watch_app; watch_app()"]
HANG = 90  # s: a command still running this long after its signals is hung

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def street(tmp_path_factory) -> list[Path]:
    return street_files(tmp_path_factory.mktemp("street"), n_scans=4)[0]


def _start(cmd: list[str], log: Path) -> subprocess.Popen:
    """The command in a process group of its own (its id is the command's pid)."""
    return subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=log.open("w"), env=ENV, start_new_session=True
    )


def _workers(pid: int) -> list[int]:
    """The child processes of ``pid`` (its worker processes)."""
    children: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        with contextlib.suppress(OSError):
            children += [int(c) for c in (task / "children").read_text().split()]
    return children


def _wait_for_workers(
    proc: subprocess.Popen, n: int = 1, find: Callable[[int], list[int]] = _workers
) -> list[int]:
    """The processes ``find`` sees below the command (its workers), once there are ``n``."""
    deadline = time.monotonic() + HANG
    while time.monotonic() < deadline and proc.poll() is None:
        found = find(proc.pid)
        if len(found) >= n:
            return found
        time.sleep(0.05)
    raise AssertionError("the command started no worker process")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (dead, its parent not told yet) is not alive
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def _gone(pids: list[int], limit: float = 20.0) -> bool:
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        if not any(_alive(p) for p in pids):
            return True
        time.sleep(0.1)
    return False


def _assert_gone(pids: list[int]) -> None:
    """Every one of ``pids`` ends (those left are killed, and the test fails)."""
    try:
        assert _gone(pids), "processes outlived the command"
    finally:
        for pid in pids:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def _ended(proc: subprocess.Popen, log: Path) -> int:
    """The exit code; a command that does not end is killed, with its group, and fails."""
    try:
        return proc.wait(timeout=HANG)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        pytest.fail(f"hung after its signals: {log.read_text()[-300:]}")


def _interrupt_twice(proc: subprocess.Popen, gap: float = 0.05) -> None:
    """Ctrl-C pressed twice, ``gap`` seconds apart (as ``timeout -s INT`` sends it)."""
    os.killpg(proc.pid, signal.SIGINT)
    time.sleep(gap)
    os.killpg(proc.pid, signal.SIGINT)


@pytest.mark.parametrize("when", [0.0, 1.0, 3.0])
def test_ctrl_c_twice_never_hangs_the_chain(when, street, tmp_path):
    log = tmp_path / "log"
    proc = _start([*CHAIN, *map(str, street), "-o", str(tmp_path / "o"), "-j", "1", "-q"], log)
    workers = _wait_for_workers(proc)
    time.sleep(when)
    _interrupt_twice(proc)
    assert _ended(proc, log) == 130, log.read_text()
    text = log.read_text()
    assert "Traceback" not in text and len(text.strip().splitlines()) == 1, text
    assert _gone(workers)


@pytest.mark.parametrize("when", [0.5, 3.0])
def test_ctrl_c_twice_never_hangs_field_mode(when, street, tmp_path):
    card = tmp_path / "card"
    card.mkdir()
    for f in street:
        os.link(f, card / f.name)
    log = tmp_path / "log"
    proc = _start([*WATCH, str(card), "-o", str(tmp_path / "o"), "-j", "2"], log)
    workers = _wait_for_workers(proc, 2)
    time.sleep(when)
    _interrupt_twice(proc)
    assert _ended(proc, log) == 130, log.read_text()
    text = log.read_text()
    # field mode ends with its summary, whose last line says how to continue
    last = text.strip().splitlines()[-1]
    assert "Traceback" not in text and last.endswith("start ndt-watch again to continue"), text
    assert _gone(workers)


def _command(command: str, street: list[Path], tmp_path: Path) -> list[str]:
    """``ndt-chain`` of the street, or ``ndt-watch`` of a folder it has landed in."""
    out = str(tmp_path / "o")
    if command == "chain":
        return [*CHAIN, *map(str, street), "-o", out, "-j", "2", "-q"]
    card = tmp_path / "card"
    card.mkdir()
    for f in street:
        os.link(f, card / f.name)
    return [*WATCH, str(card), "-o", out, "-j", "2"]


@pytest.mark.parametrize("command", ["chain", "watch"])
def test_sigterm_to_the_group_is_one_line_and_exit_130(command, street, tmp_path):
    """What systemd, ``timeout`` and session managers send: the workers, which get it too,
    finish their tasks; only the command speaks."""
    log = tmp_path / "log"
    proc = _start(_command(command, street, tmp_path), log)
    workers = _wait_for_workers(proc, 2)
    time.sleep(2.0)
    os.killpg(proc.pid, signal.SIGTERM)
    assert _ended(proc, log) == 130, log.read_text()
    text = log.read_text()
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    last = text.strip().splitlines()[-1]
    if command == "chain":
        assert last.startswith("ndt-chain: error:"), text
    else:  # field mode ends with its summary, whose last line says how to continue
        assert last.endswith("start ndt-watch again to continue"), text
    assert _gone(workers)


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
@pytest.mark.parametrize("command", ["chain", "watch"])
def test_workers_never_outlive_the_main_process(command, sig, street, tmp_path):
    """The main process alone killed (the OOM killer, ``kill PID``): its workers end too."""
    log = tmp_path / "log"
    proc = _start(_command(command, street, tmp_path), log)
    workers = _wait_for_workers(proc, 2)
    time.sleep(1.0)
    proc.send_signal(sig)
    _ended(proc, log)
    _assert_gone(workers)


LIBRARY = """
import sys, numba, numpy as np
from ndt_cli.config import Config
from ndt_cli.pipeline.chain import run_chain
numba.njit(parallel=True)(lambda a: a.sum())(np.ones(4))  # its workers come from a fork server
run_chain(sys.argv[2:], Config(), sys.argv[1], jobs=2)
"""


def _descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (a fork server and the workers it forked)."""
    found, todo = [], [pid]
    while todo:
        children = _workers(todo.pop())
        found += children
        todo += children
    return found


@pytest.mark.parametrize("group", [False, True])
def test_a_fork_servers_workers_never_outlive_the_program(group, street, tmp_path):
    """A program whose Numba threads ran has its workers forked by a fork server. SIGKILL to
    the program, or SIGTERM to its process group: the server and the workers end too."""
    log = tmp_path / "log"
    cmd = [sys.executable, "-c", LIBRARY, str(tmp_path / "o"), *map(str, street)]
    proc = _start(cmd, log)
    below = _wait_for_workers(proc, 3, _descendants)  # the server, its two workers (a tracker)
    time.sleep(1.0)
    if group:
        os.killpg(proc.pid, signal.SIGTERM)
    else:
        proc.kill()
    _ended(proc, log)
    _assert_gone(below)
