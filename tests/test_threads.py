"""The thread budget and the parallel loop that runs the compiled kernels."""

from __future__ import annotations

import itertools
import os
import threading

import pytest

from ndt_cli.core import threads
from ndt_cli.pipeline.workers import set_threads


@pytest.fixture
def budget():
    before = threads.threads()
    yield
    threads.set_threads(before)


@pytest.mark.parametrize("n_tasks", [0, 1, 2, 5, 16, 17])
@pytest.mark.parametrize("n_threads", [1, 2, 3, 8])
def test_blocks_cover_the_tasks_once_in_order_and_evenly(n_tasks, n_threads):
    parts = threads.blocks(n_tasks, n_threads)
    assert 1 <= len(parts) <= max(1, n_threads)
    assert parts[0][0] == 0 and parts[-1][1] == n_tasks
    assert all(a[1] == b[0] for a, b in itertools.pairwise(parts))
    sizes = [stop - start for start, stop in parts]
    assert max(sizes) - min(sizes) <= 1
    assert n_tasks == 0 or min(sizes) >= 1


def test_each_task_runs_once_the_blocks_at_once_the_caller_first(budget):
    threads.set_threads(3)
    ran: list[tuple[int, int, str]] = []
    lock = threading.Lock()
    together = threading.Barrier(3, timeout=10)  # broken unless three blocks run at once

    def kernel(start: int, stop: int, out: list[int]) -> None:
        with lock:
            ran.append((start, stop, threading.current_thread().name))
        together.wait()
        for t in range(start, stop):
            out[t] += 1

    out = [0] * 10
    threads.parallel_for(kernel, 10, out)
    assert out == [1] * 10
    assert sorted(r[:2] for r in ran) == [(0, 3), (3, 6), (6, 10)]
    by_block = {r[:2]: r[2] for r in ran}
    assert by_block[(0, 3)] == threading.current_thread().name
    assert len(set(by_block.values())) == 3


def test_a_failing_block_raises_after_every_block_has_ended(budget):
    threads.set_threads(2)
    ended = []

    def kernel(start: int, stop: int) -> None:
        if start > 0:
            raise ValueError(f"block {start}")
        threading.Event().wait(0.05)  # the caller's block ends after the helper's failure
        ended.append(start)

    with pytest.raises(ValueError, match="block 2"):
        threads.parallel_for(kernel, 4)
    assert ended == [0]


def test_budget_is_at_least_one_and_starts_from_the_environment(monkeypatch, budget):
    threads.set_threads(0)
    assert threads.threads() == 1
    monkeypatch.setenv("NUMBA_NUM_THREADS", "3")
    assert threads.initial() == 3
    monkeypatch.delenv("NUMBA_NUM_THREADS")
    assert threads.initial() == len(os.sched_getaffinity(0))


def test_a_worker_gets_its_share_never_more_than_the_start(monkeypatch, budget):
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    set_threads(1)
    assert threads.threads() == 1
    set_threads(8)
    assert threads.threads() == 2


_PESTERED = """
import os, signal, threading, time
from ndt_cli.core import threads

threads.set_threads(3)
pools = []
end = time.monotonic() + {seconds}
stop, started = threading.Event(), threading.Event()


def pester():
    started.wait()
    while not stop.is_set():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.0003)


pesterer = threading.Thread(target=pester, daemon=True)
pesterer.start()
started.set()
interrupted = 0
while True:
    try:
        if time.monotonic() > end:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            break
        pools.append(threads._pool)  # kept alive, as the process's one pool is
        threads._pool = None  # a fresh pool, whose helper threads start in this call
        threads.parallel_for(lambda start, stop: None, 3)
    except KeyboardInterrupt:
        interrupted += 1
stop.set()
pesterer.join()
print(interrupted)
"""


@pytest.mark.slow
def test_ctrl_c_while_helper_threads_start_never_holds_up_the_exit():
    """Ctrl-C lands again and again while the loop's helper threads start: the process is
    interrupted, and it ends (a thread started but not recorded by its pool, as a Ctrl-C
    inside the thread's start left it, would keep the interpreter's exit waiting forever)."""
    import subprocess
    import sys

    code = _PESTERED.format(seconds=3.0)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60
    )
    assert proc.returncode == 0, proc.stderr[-500:]
    assert int(proc.stdout) > 0  # the signals did land
