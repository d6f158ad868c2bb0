"""Shared test helpers: the real-data folder beside the project (``../shared/data``)."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from hypothesis import settings

# CI runs the same examples every time (a failure there can be run again); a run by hand explores
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI") == "true":
    settings.load_profile("ci")

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"

# The tests that press Ctrl-C on a command need it to arrive as on a terminal. A suite started
# in the background (`nohup`, `cmd &` in a script) inherits SIGINT ignored, and every command
# it starts would too (an ignored signal stays ignored across exec, by the commands' design):
# the session takes SIGINT as Python does by default, so the commands it starts do as well.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _signal_handlers_restored():
    """A command run in this process sets how it takes SIGINT and SIGTERM (ignored once it
    has stopped, SIGTERM as Ctrl-C): the test session's own handlers come back after it."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def shared_data(name: str) -> Path:
    """Folder ``name`` of the shared real data; skip the test if absent (fail if CI is "true")."""
    folder = SHARED_DATA / name
    if not folder.is_dir():
        message = f"shared data folder not found: {folder}"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)
    return folder


@pytest.fixture
def shared_data_dir() -> Path:
    """Root of the shared real data (may not exist; use :func:`shared_data` for a folder)."""
    return SHARED_DATA


def street_files(folder: Path, n_scans: int = 4, seed: int = 21) -> tuple[list[Path], list]:
    """A short simulated street written as LAZ files ``scan_K.laz``; returns (files, poses)."""
    from ndt_cli import io, sim

    _, scans, poses = sim.make_sequence(
        seed=seed, n_scans=n_scans, spacing=(13.0, 17.0), scan_kwargs={"n_azimuth": 1000}
    )
    files = []
    for k, pts in enumerate(scans):
        files.append(folder / f"scan_{k}.laz")
        io.write(files[-1], pts)
    return files, poses


def unmatched_pair(folder: Path) -> tuple[Path, Path]:
    """Two xyz scans of one flat ground, one with a layer of points at 1 m, the other at 8 m:
    nothing in any slice of one matches the other, so registering them fails (exit 1)."""
    import numpy as np

    from ndt_cli import io

    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(-20, 20, (20000, 2)), rng.normal(0, 0.01, 20000)])
    low = np.column_stack([rng.uniform(-10, 10, (3000, 2)), np.full(3000, 1.0)])
    high = np.column_stack([rng.uniform(-10, 10, (3000, 2)), np.full(3000, 8.0)])
    a, b = folder / "a.xyz", folder / "b.xyz"
    io.write(a, np.vstack([ground, low]))
    io.write(b, np.vstack([ground, high]))
    return a, b


def during_ctrl_c(error: BaseException, direct: bool = True) -> BaseException:
    """``error`` as Ctrl-C leaves it: caused by a KeyboardInterrupt (``direct``: a compiled
    module interrupted in its import fails with ImportError from it), or raised while one was
    handled."""
    if direct:
        error.__cause__ = KeyboardInterrupt()
    else:
        error.__context__ = KeyboardInterrupt()
    return error


def after(name: str, seconds: float) -> str:
    """A task for executors: ``name`` after ``seconds`` of sleep."""
    import time

    time.sleep(seconds)
    return name


def added_task_order(pool) -> list:
    """The results, in order, of a run of a slow and a fast task on ``pool`` in which the fast
    task's result adds a third task (the executors' ``then``); the pool is closed."""
    from functools import partial

    tasks = {"slow": partial(after, "slow", 3.0), "fast": partial(after, "fast", 0.0)}

    def then(key, value):
        return {"added": partial(after, f"added after {value}", 0.0)} if key == "fast" else {}

    try:
        return list(pool.run(tasks, then))
    finally:
        pool.close()
