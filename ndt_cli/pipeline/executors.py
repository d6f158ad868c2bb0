"""Where the tasks of a chain run: worker processes on this machine, or a Dask cluster.

An executor runs a dict of tasks (:data:`~ndt_cli.pipeline.workers.Task`) and yields
``(key, value)`` as they finish; a task that raised or whose worker died yields a
:class:`~ndt_cli.pipeline.workers.Failure` (its one-line reason) instead of its value.
``then(key, value)``, called after each result is taken, may add tasks to the run.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Protocol

from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.workers import (
    ExecutorKind,
    Results,
    Task,
    Then,
    default_jobs,
    threads_per_job,
)

__all__ = ["Executor", "ExecutorKind", "make_executor"]


class Executor(Protocol):
    """What the chain driver needs of an executor."""

    ships_data: bool  # True: tasks may take prepared scans; False: tasks read files themselves

    def start(self) -> None: ...

    def run(self, tasks: dict[Hashable, Task], then: Then | None = None) -> Results: ...

    def close(self) -> None: ...


def make_executor(kind: ExecutorKind, jobs: int | None, scheduler: str | None = None) -> Executor:
    """An executor of ``kind``: ``jobs`` local processes, or the Dask cluster at ``scheduler``
    (None: a LocalCluster of ``jobs`` workers)."""
    n = default_jobs(jobs)
    if kind is ExecutorKind.DASK:
        from ndt_cli.pipeline.dask_executor import DaskPool

        return DaskPool(scheduler, n, threads_per_job(n))
    return WorkerPool(n)
