"""Executors run tasks that other tasks' results add to the same run (``then``): a link starts as
soon as its two scans are ready, without waiting for the slowest scan."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from concurrent.futures.process import _ExecutorManagerThread
from functools import partial
from pathlib import Path

import pytest
from conftest import added_task_order, after

from ndt_cli.pipeline.executors import make_executor
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.workers import ExecutorKind, Failure


def _die() -> None:
    os._exit(3)


@pytest.mark.slow
def test_a_task_added_by_a_result_runs_beside_the_slow_tasks_of_the_run():
    order = added_task_order(WorkerPool(2, threads=1))
    assert order == [("fast", "fast"), ("added", "added after fast"), ("slow", "slow")]


@pytest.mark.slow
def test_an_added_task_whose_worker_dies_fails_alone():
    pool = WorkerPool(2, threads=1)
    tasks = {"a": partial(after, "a", 0.0), "b": partial(after, "b", 1.0)}

    def then(key, value):
        return {"dies": _die, "after": partial(after, "after", 0.0)} if key == "a" else {}

    try:
        results = dict(pool.run(tasks, then))
    finally:
        pool.close()
    assert results["a"] == "a" and results["b"] == "b" and results["after"] == "after"
    assert "worker process died" in results["dies"]


def _raise() -> None:
    raise ValueError("a bug\nin a task")


def test_a_failure_is_typed_and_no_value_a_task_returns_is_taken_for_one(tmp_path):
    """A task that raises, or cannot read its scan, gives a Failure (its one-line reason);
    a task whose value is a text gives that text, which is no Failure."""
    from ndt_cli.config import Config
    from ndt_cli.pipeline.tasks import prepare_scan

    pool = WorkerPool(1, threads=1)
    missing = tmp_path / "gone.laz"
    tasks = {"text": partial(after, "text", 0.0), "raises": _raise}
    tasks["unreadable"] = partial(prepare_scan, missing, Config())
    try:
        results = dict(pool.run(tasks))
    finally:
        pool.close()
    assert results["text"] == "text" and not isinstance(results["text"], Failure)
    assert isinstance(results["raises"], Failure)
    assert results["raises"] == "worker error: a bug in a task"
    assert isinstance(results["unreadable"], Failure) and "gone.laz" in results["unreadable"]


def _manager_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if isinstance(t, _ExecutorManagerThread)]


def _touch_after(path: Path, seconds: float) -> str:
    time.sleep(seconds)
    path.touch()
    return path.name


@pytest.mark.slow
def test_closing_waits_for_the_tasks_held_and_cancels_the_rest(tmp_path):
    """Python 3.11's exit hook writes to each pool's wake-up pipe while the pool's manager
    thread may be closing it (a traceback after the command's last line), and a worker killed
    while it sends a result hangs that thread: closing, after a run or in the middle of one,
    waits for the workers and that thread instead of killing them."""
    assert not _manager_threads()
    done = WorkerPool(2, threads=1)
    assert dict(done.run({"a": partial(after, "a", 0.0)})) == {"a": "a"}
    assert _manager_threads()
    done.close()
    assert not _manager_threads()
    busy = WorkerPool(1, threads=1)
    tasks = {k: partial(_touch_after, tmp_path / str(k), 0.2) for k in range(12)}
    running = busy.run(tasks)
    assert next(running) == (0, "0")
    busy.close()
    assert not _manager_threads()
    ran = len(list(tmp_path.iterdir()))
    assert 2 <= ran < 6  # the tasks in the worker's hands finished, the others never started


def test_the_local_pool_never_starts_more_processes_than_cores():
    cores = os.cpu_count() or 1
    pool = make_executor(ExecutorKind.LOCAL, 100_000)
    try:
        assert pool.jobs == cores
        assert list(pool.run({"a": partial(after, "a", 0.0)})) == [("a", "a")]
    finally:
        pool.close()
    assert make_executor(ExecutorKind.LOCAL, 1).jobs == 1


def _threads_after(barrier) -> int:
    """This worker's kernel threads while the other party of ``barrier`` (None: alone) runs."""
    from ndt_cli.core import threads

    if barrier is None:
        return threads.threads()
    barrier.wait(timeout=30)  # both tasks are running
    n = threads.threads()
    barrier.wait(timeout=30)  # neither has finished before both have looked
    return n


def test_workers_share_the_cores_among_those_running_a_task():
    """A task that runs alone takes every core; two tasks at once take half each. (Results
    do not depend on the number of threads, so only the time changes.)"""
    import multiprocessing

    from ndt_cli.core import threads

    cores = min(os.cpu_count() or 1, threads.initial())
    pool = WorkerPool(2)
    with multiprocessing.Manager() as manager:
        together = manager.Barrier(2)
        try:
            alone = dict(pool.run({"alone": partial(_threads_after, None)}))
            both = dict(pool.run({k: partial(_threads_after, together) for k in "ab"}))
            after_both = dict(pool.run({"alone again": partial(_threads_after, None)}))
        finally:
            pool.close()
    assert alone["alone"] == cores
    assert both == {"a": max(1, cores // 2), "b": max(1, cores // 2)}
    assert after_both["alone again"] == cores


def test_a_pool_given_threads_keeps_them_whatever_runs_beside():
    pool = WorkerPool(2, threads=1)
    try:
        alone = dict(pool.run({"alone": partial(_threads_after, None)}))
    finally:
        pool.close()
    assert alone == {"alone": 1}


def test_a_process_whose_fork_server_cannot_start_spawns_its_workers(monkeypatch):
    """No socket for a fork server (no temporary folder can hold one): the workers are
    spawned, children of this process, and run their tasks."""
    import multiprocessing.forkserver

    from ndt_cli.pipeline import local_pool

    def no_socket() -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(local_pool, "start_method", lambda: "forkserver")
    monkeypatch.setattr(multiprocessing.forkserver, "ensure_running", no_socket)
    pool = WorkerPool(2, threads=1)
    try:
        parents = dict(pool.run({k: os.getppid for k in range(2)}))
    finally:
        pool.close()
    assert parents == {0: os.getpid(), 1: os.getpid()}


def test_a_fork_servers_workers_are_its_children_not_this_process():
    """From a process that ran threads, the workers are forked by the fork server."""
    from ndt_cli.pipeline.local_pool import start_method

    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert start_method() == "forkserver"
        pool = WorkerPool(2, threads=1)
        try:
            parents = set(dict(pool.run({k: os.getppid for k in range(2)})).values())
        finally:
            pool.close()
    finally:
        stop.set()
        other.join()
    assert len(parents) == 1 and os.getpid() not in parents


UNGUARDED = """
import os, threading
from ndt_cli.pipeline.local_pool import WorkerPool
if __name__ == "__main__":  # in the program (not in a worker): a thread runs, no fork is safe
    threading.Thread(target=threading.Event().wait, daemon=True).start()
pool = WorkerPool(1, threads=1)
print("RAN", os.getpid(), flush=True)
print(dict(pool.run({0: os.getpid})), flush=True)
pool.close()
"""


@pytest.mark.slow
def test_a_script_without_the_main_guard_is_not_run_again_by_workers_of_its_workers(tmp_path):
    """A worker of a program that could not fork imports the program's main module. Without the
    ``if __name__ == "__main__":`` guard that runs the script again; it must not start workers
    of its own there (forked, they would run it again, and so on), but fail as Python says."""
    script = tmp_path / "unguarded.py"
    script.write_text(UNGUARDED)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.stdout.count("RAN") == 2, done.stdout  # the program, and its worker's import
    assert done.stdout.count("{0:") == 1, done.stdout  # only the program's pool ran its task
    assert "if __name__ == '__main__'" in done.stderr, done.stderr[-2000:]
