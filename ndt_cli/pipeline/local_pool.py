"""Worker processes on this machine (the local executor of a chain)."""

from __future__ import annotations

import ctypes
import logging
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable, Hashable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from ndt_cli.core.signals import STOP_SIGNALS, stop_signals_held
from ndt_cli.core.threads import Counter
from ndt_cli.pipeline.workers import (
    Failure,
    Results,
    Task,
    Then,
    set_threads,
    share_threads,
    worker_error,
)

log = logging.getLogger(__name__)


_busy: Counter | None = None  # in a worker: the pool's count of workers running a task
_PR_SET_PDEATHSIG = 1  # prctl option: the signal this process gets when its parent dies
_abandoned = threading.Event()  # set once workers were killed instead of being waited for
CLOSE_WAIT_S = 30.0  # s the workers get to finish the tasks they hold when the pool closes
FORK_SERVER_MODULE = "ndt_cli.pipeline.fork_server"  # imported once by the fork server


def _init_worker(
    parent: int | None, threads: int | None, busy: Counter | None, init: Callable[[], None] | None
) -> None:
    global _busy
    # Ctrl-C and SIGTERM (to the process group) are handled by the parent, which lets the
    # workers finish their tasks; the parent's own handlers are not the workers'
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)  # held while it started
    _die_with(parent)
    if busy is None:
        set_threads(threads or 1)
    else:
        _busy = busy
        share_threads(busy)
    if init is not None:
        init()


def _die_with(parent: int | None) -> None:
    """Have this worker killed when its parent process ends, however it ends (SIGKILL, the
    OOM killer): a worker never outlives the command that started it. Linux only. The kernel
    watches the parent's thread that started the worker: pools are driven from the main
    thread (a pool started from a thread that ends before it would lose its workers).

    A fork server is the parent of its workers, and ends when the last process that holds its
    pipe does: the command and, by default, every worker it forked. A worker lets go of that
    pipe, so that the server ends with the command and its workers with it."""
    _let_go_of_server()
    if sys.platform != "linux":
        return
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        return
    if parent is not None and os.getppid() != parent:  # it died before the request took effect
        os._exit(1)


def _let_go_of_server() -> None:
    """Close this worker's copy of the pipe that keeps the fork server alive, if it has one
    (forked by the server, or forked by a command that had started one)."""
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    fd = getattr(server, "_forkserver_alive_fd", None)
    if fd is not None:
        os.close(fd)
        server._forkserver_alive_fd = None


def _counted(task: Task) -> Any:
    """Run ``task`` in a worker, counted among the pool's busy workers while it runs."""
    if _busy is None:
        return task()
    with _busy.get_lock():
        _busy.value += 1
    try:
        return task()
    finally:
        with _busy.get_lock():
            _busy.value -= 1


def start_method() -> str:
    """How worker processes start: ``fork`` where it is safe, else from a fork server
    (``forkserver``); ``spawn`` off Linux.

    A forked worker inherits the modules its parent imported (numpy, Numba, the package: about
    a second of start-up and two of CPU per worker saved). Forking is safe only from a process
    that has one thread: a thread pool that ran in the parent (the kernels' threads, the LAZ
    decoder's threads, BLAS threads) exists in the child without its threads, and the child's
    first parallel call waits for them forever. A process that ran threads (a second chain in
    one program, a test suite) forks its workers from a fork server instead: a process it
    starts once, which has one thread, imported what workers need
    (:mod:`ndt_cli.pipeline.fork_server`) and forks each worker in milliseconds. Off Linux
    workers are spawned (macOS system libraries are not fork-safe).
    """
    if sys.platform != "linux":
        return "spawn"
    return "fork" if _one_thread() else "forkserver"


def _one_thread() -> bool:
    """Whether this process has one thread and never ran a thread pool of Numba's, and is not
    a worker still importing its program's main module (a script without the ``if __name__ ==
    "__main__":`` guard, run again in its workers: they must fail to start, with Python's
    message, rather than fork workers that run it again)."""
    if threading.active_count() > 1 or getattr(multiprocessing.current_process(), "_inheriting", 0):
        return False
    numba = sys.modules.get("numba")
    if numba is not None:
        try:
            numba.threading_layer()  # raises ValueError until a parallel kernel has run
            return False
        except ValueError:
            pass
    try:
        return len(os.listdir("/proc/self/task")) == 1
    except OSError:
        return False


def _fork_server() -> tuple[str, int | None]:
    """Start the fork server (once per process): ``("forkserver", its process id)``, the
    workers' parent (None where the standard library does not tell it); ``("spawn", this
    process's id)`` when it cannot start (no socket can be made in any temporary folder)."""
    from multiprocessing import forkserver

    multiprocessing.set_forkserver_preload([FORK_SERVER_MODULE])
    try:
        forkserver.ensure_running()
    except OSError as exc:
        log.debug("no fork server (%s): workers are spawned", exc)
        return "spawn", os.getpid()
    return "forkserver", getattr(getattr(forkserver, "_forkserver", None), "_forkserver_pid", None)


class WorkerPool:
    """Worker processes that survive a worker dying.

    Workers are forked where that is safe, else forked by a fork server (:func:`start_method`).
    When a worker dies (killed, out of memory, a crash in a library), every task in flight
    fails with BrokenProcessPool; those tasks are then rerun one at a time in a fresh
    single-worker pool, so only the task that kills its worker fails. ``init`` runs once in
    every worker process before its first task. Without ``threads``, the workers share the
    cores: each kernel call of a task takes the cores over the number of workers running a task
    at that moment.
    """

    ships_data = True

    def __init__(
        self, jobs: int, threads: int | None = None, init: Callable[[], None] | None = None
    ) -> None:
        self.jobs = jobs
        self.threads = threads  # kernel threads of each worker; None: they share the cores
        self._init = init
        self._pool: ProcessPoolExecutor | None = None

    def _new(self, workers: int) -> ProcessPoolExecutor:
        self.close()
        method, parent = start_method(), os.getpid()
        if method == "forkserver":
            method, parent = _fork_server()
        log.debug("starting %d worker process(es) by %s", workers, method)
        context = multiprocessing.get_context(method)
        busy = context.Value("i", 0) if self.threads is None else None
        self._pool = ProcessPoolExecutor(
            max_workers=workers,
            mp_context=context,
            initializer=_init_worker,
            initargs=(parent, self.threads, busy, self._init),
        )
        return self._pool

    def start(self) -> None:
        """Start the workers now rather than at the first task: a command starts them before
        it starts threads of its own (a progress display), so that they can be forked, and
        they start while it does other work."""
        if self._pool is None:
            with stop_signals_held():
                self._new(self.jobs).submit(os.getpid)

    def run(self, tasks: dict[Hashable, Task], then: Then | None = None) -> Results:
        """Yield (key, result) as tasks finish; a task that fails yields a :class:`Failure`.
        ``then(key, result)``, called once the caller has taken a result, returns more tasks
        for this run (keys not used before): they start at once and their results follow."""
        tasks = dict(tasks)
        queue = list(tasks)
        workers = self.jobs
        while queue:
            pool = self._pool if self._pool and workers == self.jobs else self._new(workers)
            broken: list[Hashable] = []
            yield from _collect(pool, tasks, queue, broken, then)
            queue = [k for k in tasks if k in broken]
            if queue and workers == 1:  # in isolation the first task in line killed its worker
                yield (
                    queue.pop(0),
                    Failure("the worker process died (killed, out of memory or crashed)"),
                )
            if queue:
                workers = 1
                self._new(1)

    def close(self) -> None:
        """Cancel the tasks that have not started and wait for the workers to finish those
        they hold and exit, with the pool's manager thread (after a run: about 15 ms).

        Workers are not killed on a first Ctrl-C (they ignore SIGINT): a worker killed while
        it sends a result leaves the manager thread waiting for the rest of the message
        forever, and so the interpreter's exit. Not waiting leaves the manager thread closing
        its wake-up pipe while the exit hook writes to it (a traceback after the last line).
        A second Ctrl-C while they finish (or a pool that a Ctrl-C broke as it started,
        whose workers would wait for work forever), or workers still busy after
        :data:`CLOSE_WAIT_S`, are killed instead, and the pool is marked abandoned: the
        command then ends at once (:func:`abandoned`), never waiting for a thread or a
        process.
        """
        pool, self._pool = self._pool, None
        if pool is None:
            return
        workers = list((getattr(pool, "_processes", None) or {}).values())  # shutdown drops it
        manager = getattr(pool, "_executor_manager_thread", None)  # and this too
        try:
            pool.shutdown(wait=False, cancel_futures=True)
            if manager is not None:
                manager.join(CLOSE_WAIT_S)
        finally:
            _kill_alive(workers)  # none is left once the pool shut down whole
            if manager is not None and manager.is_alive():  # the exit hooks would wait for it
                _abandoned.set()


def abandoned() -> bool:
    """Whether worker processes were killed rather than waited for (see
    :meth:`WorkerPool.close`): the process should end without its exit hooks, which would
    wait for the pool's manager thread."""
    return _abandoned.is_set()


def _kill_alive(workers: list[multiprocessing.process.BaseProcess]) -> None:
    """Kill the worker processes that are still alive (and reap them)."""
    alive = [p for p in workers if p.is_alive()]
    for p in alive:
        p.kill()
    for p in alive:
        p.join(timeout=5)
    if alive:
        _abandoned.set()


def _collect(
    pool: ProcessPoolExecutor,
    tasks: dict[Hashable, Task],
    keys: list[Hashable],
    broken: list[Hashable],
    then: Then | None,
) -> Results:
    """Run ``keys`` of ``tasks`` on ``pool`` and yield their results, and those of the tasks
    ``then`` adds (which join ``tasks``); keys whose worker died go to ``broken``."""
    pending: dict[Future, Hashable] = {}

    def submit(key: Hashable) -> None:
        try:
            with stop_signals_held():
                pending[pool.submit(_counted, tasks[key])] = key
        except BrokenProcessPool:
            broken.append(key)

    for key in keys:
        submit(key)
    while pending:
        done, _ = wait(pending, return_when=FIRST_COMPLETED)
        for fut in done:
            key = pending.pop(fut)
            try:
                value = fut.result()
            except BrokenProcessPool:
                broken.append(key)
                continue
            except Exception as exc:  # a bug in a task: report it for that task only
                value = worker_error(exc)
            yield key, value
            for new, task in (then(key, value) if then else {}).items():
                tasks[new] = task
                submit(new)
