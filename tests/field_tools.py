"""Running ndt-watch as a field crew does: a real process in its own process group (as a
terminal starts it, so that Ctrl-C reaches its workers too), its screen and its JSON events
read as they come, and scans written into the watched folder by other processes, slowly."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
WATCH = [sys.executable, "-c", "from ndt_cli.cli import watch_app; watch_app()"]
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}

WRITER = """
import os, sys, time
src, dst, pieces, pause = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
data = open(src, "rb").read()
step = -(-len(data) // pieces)
with open(dst, "wb") as fh:
    for k in range(0, len(data), step):
        fh.write(data[k : k + step])
        fh.flush()
        os.fsync(fh.fileno())
        if k + step < len(data):
            time.sleep(pause)
"""


class Events(list):
    """The JSON events of a run, in order."""

    def of(self, *kinds: str) -> list[dict]:
        return [e for e in self if e["event"] in kinds]

    def about(self, name: str) -> list[dict]:
        """The events naming a scan or a file."""
        return [e for e in self if name in (e.get("scan"), e.get("file"))]

    def final_verdicts(self) -> dict[str, dict]:
        """The last placed, fits_nowhere or revised event of each scan still in the campaign."""
        out: dict[str, dict] = {}
        for e in self:
            if e["event"] in ("placed", "fits_nowhere", "revised"):
                out[e["scan"]] = e
            elif e["event"] in ("removed", "replaced", "unreadable", "skipped"):
                for name in e["dropped"]:
                    out.pop(name, None)
        return out


class WatchRun:
    """An ndt-watch process: its stdout (JSON events) and stderr (the screen) in files."""

    def __init__(self, cmd: list[str], logs: Path) -> None:
        logs.mkdir(parents=True, exist_ok=True)
        self.out_file, self.err_file = logs / "stdout.jsonl", logs / "stderr.txt"
        self.proc = subprocess.Popen(
            cmd,
            stdout=self.out_file.open("w"),
            stderr=self.err_file.open("w"),
            env=ENV,
            start_new_session=True,
        )

    @property
    def events(self) -> Events:
        lines = self.out_file.read_text().splitlines()
        return Events(json.loads(line) for line in lines if line.endswith("}"))

    def stderr(self) -> str:
        return self.err_file.read_text()

    def wait_for(self, done: Callable[[Events], bool], limit: float = 240.0) -> None:
        """Until ``done(events)`` holds (or the process ended, or ``limit`` s passed)."""
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline and self.proc.poll() is None:
            if done(self.events):
                return
            time.sleep(0.1)
        assert done(self.events), f"not seen within {limit} s:\n{self.stderr()}"

    def wait_for_screen(self, text: str, limit: float = 120.0) -> None:
        """Until ``text`` is on the screen (stderr), or the process ended, or ``limit`` s
        passed."""
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline and self.proc.poll() is None:
            if text in self.stderr():
                return
            time.sleep(0.1)
        assert text in self.stderr(), f"{text!r} not seen within {limit} s:\n{self.stderr()}"

    def wait(self, limit: float) -> int:
        try:
            return self.proc.wait(timeout=limit)
        except subprocess.TimeoutExpired:
            self.signal_group(signal.SIGKILL)
            self.proc.wait()
            raise AssertionError(f"ndt-watch still running after {limit} s") from None

    def signal_group(self, signum: int) -> None:
        """Send ``signum`` to the process and its workers, as a terminal's Ctrl-C does."""
        os.killpg(self.proc.pid, signum)


def start_watch(folder: Path, out: Path, logs: Path, *extra: str) -> WatchRun:
    """ndt-watch on ``folder`` into ``out`` with two workers."""
    return WatchRun([*WATCH, str(folder), "--out", str(out), "-j", "2", *extra], logs)


def write_slowly(src: Path, dst: Path, pieces: int, pause: float) -> subprocess.Popen:
    """A process writing ``src`` to ``dst`` in ``pieces``, each flushed to disk, with
    ``pause`` seconds between them (a scanner's export, a slow USB card)."""
    cmd = [sys.executable, "-c", WRITER, str(src), str(dst), str(pieces), str(pause)]
    return subprocess.Popen(cmd)
