"""What every worker process of a chain shares: the task type, its failure and its thread
budget.

A task is a picklable callable without arguments (a :func:`functools.partial` of a module-level
function). An executor's ``run(tasks, then)`` yields results as tasks finish; ``then`` may add
tasks to the same run as results come in (a link starts as soon as its two scans are ready). A
task that cannot give its value (an unreadable scan; a task that raised, or whose worker died)
gives a :class:`Failure` instead.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Hashable, Iterator
from enum import StrEnum
from typing import Any

log = logging.getLogger(__name__)


class Failure(str):
    """Why a task gave no value: its one-line reason. A type of its own, so that no value a
    task returns (a text among them) is mistaken for a failure."""

    __slots__ = ()


Task = Callable[[], Any]
Then = Callable[[Hashable, Any], dict[Hashable, Task]]  # more tasks, given a finished one
Results = Iterator[tuple[Hashable, Any]]  # (key, value or Failure), as tasks finish


class ExecutorKind(StrEnum):
    """``local``: processes on this machine; ``dask``: a Dask cluster."""

    LOCAL = "local"
    DASK = "dask"


def threads_per_job(jobs: int) -> int:
    """Kernel threads for each of ``jobs`` parallel workers on this machine's cores."""
    return max(1, (os.cpu_count() or 1) // max(1, jobs))


def default_jobs(jobs: int | None) -> int:
    """``jobs``, or one per core when not given; never more than one per core (the tasks are
    bound by the processor: more processes would only take more memory)."""
    cores = os.cpu_count() or 1
    if jobs is not None and jobs > cores:
        log.info("--jobs %d: %d processes, one per core of this machine", jobs, cores)
    return max(1, min(jobs or cores, cores))


def set_threads(threads: int) -> None:
    """Bound the kernel threads of this process (:mod:`ndt_cli.core.threads`) to ``threads``,
    at most the budget it started with; BLAS gets one (its threads would spin against them)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from ndt_cli.core import threads as budget

    budget.set_threads(min(threads, budget.initial()))


def share_threads(busy: Any) -> None:
    """Let this worker share the machine's cores with the other workers of its pool: ``busy``
    (a ``multiprocessing.Value("i")``) counts those running a task; each kernel call takes
    the cores over that count (:func:`ndt_cli.core.threads.share_cores`). BLAS gets one thread."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from ndt_cli.core import threads as budget

    budget.share_cores(busy, os.cpu_count() or 1)


def worker_error(exc: BaseException) -> Failure:
    """The failure of a task that raised (a bug in it, or a worker its cluster lost)."""
    return Failure(f"worker error: {' '.join(str(exc).split())[:200]}")
