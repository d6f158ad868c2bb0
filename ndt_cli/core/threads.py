"""This process's thread budget, and a parallel loop over independent tasks in threads.

The compiled kernels are serial Numba functions that release the GIL (``nogil=True``) and take
the range of tasks they run; :func:`parallel_for` runs contiguous blocks of the tasks in threads.
Numba's own parallel loops would do the same, but each costs one to three seconds more to
compile on an empty cache, and the first run of the command would pay for all of them.

A task writes only its own outputs, so results are bit-identical whatever the number of threads.
The budget also bounds the threads of neighbour queries. It starts at ``NUMBA_NUM_THREADS`` when
set, else the cores this process may use. A chain's worker either lowers it to a fixed share of
the cores, or shares the cores with its sibling workers (:func:`share_cores`): then each call
takes the cores divided among the workers busy at that moment, so that a link or a scan left to
run alone gets every core instead of leaving the others idle.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager
from typing import Protocol

from ndt_cli.core.signals import stop_signals_held


def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def initial() -> int:
    """The budget a process starts with: ``NUMBA_NUM_THREADS`` when set, else its cores."""
    try:
        return max(1, int(os.environ.get("NUMBA_NUM_THREADS", "")))
    except ValueError:
        return _cores()


_budget = initial()
_pool: ThreadPoolExecutor | None = None
_pool_size = 0
_busy: Counter | None = None  # workers busy now, shared by the processes of one pool
_shared_cores = 1  # the cores the processes of that pool share


class Counter(Protocol):
    """A count shared by processes (``multiprocessing.Value("i")``), changed under its lock."""

    value: int

    def get_lock(self) -> AbstractContextManager[object]: ...


def threads() -> int:
    """Threads the kernels and neighbour queries of this process may use (at least 1): the
    budget, or while sharing cores, the cores over the workers busy now (at most the budget)."""
    if _busy is None:
        return _budget
    return max(1, min(_budget, _shared_cores // max(1, _busy.value)))


def share_cores(busy: Counter | None, cores: int) -> None:
    """Share ``cores`` with the other processes that count themselves in ``busy`` while they
    run a task (None: stop sharing, back to the fixed budget)."""
    global _busy, _shared_cores
    _busy, _shared_cores = busy, max(1, int(cores))


def set_threads(n: int) -> None:
    """Set the thread budget to ``n`` (at least 1)."""
    global _budget
    _budget = max(1, int(n))


def _helpers(n: int) -> ThreadPoolExecutor:
    """The pool of helper threads, started on first use (the caller is one of the threads)."""
    global _pool, _pool_size
    if _pool is None or _pool_size < n:
        _pool, _pool_size = _started(n), n
    return _pool


def _started(n: int) -> ThreadPoolExecutor:
    """A pool of ``n`` helper threads, every one started now, with Ctrl-C and SIGTERM held
    back: a Python thread pool records a thread only after starting it, and a thread a Ctrl-C
    left unrecorded would keep the interpreter's exit waiting forever. Once started, the pool
    starts no thread again (each start here waits until all have)."""
    pool = ThreadPoolExecutor(max_workers=n, thread_name_prefix="kernel")
    all_started = threading.Barrier(n + 1)
    with stop_signals_held():
        for _ in range(n):
            pool.submit(all_started.wait)  # busy until all are: each submit starts a thread
        all_started.wait()
    return pool


def blocks(n_tasks: int, n_threads: int) -> list[tuple[int, int]]:
    """``range(n_tasks)`` cut into at most ``n_threads`` contiguous (start, stop) blocks whose
    sizes differ by at most one."""
    n = max(1, min(n_threads, n_tasks))
    edges = [(n_tasks * b) // n for b in range(n + 1)]
    return [(edges[b], edges[b + 1]) for b in range(n)]


def parallel_for(kernel: Callable[..., object], n_tasks: int, *args: object) -> None:
    """Run ``kernel(start, stop, *args)`` on blocks of ``range(n_tasks)``, one per thread of the
    budget; the calling thread runs the first block. ``kernel`` must release the GIL and write
    only its tasks' outputs. The first exception of a block is raised once all have ended."""
    parts = blocks(n_tasks, threads())
    if len(parts) == 1:
        kernel(0, n_tasks, *args)
        return
    pool = _helpers(len(parts) - 1)
    futures = [pool.submit(kernel, start, stop, *args) for start, stop in parts[1:]]
    try:
        kernel(*parts[0], *args)
    finally:
        errors = [f.exception() for f in futures]
    for error in errors:
        if error is not None:
            raise error
