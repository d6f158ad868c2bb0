"""Run chain tasks on a Dask cluster (optional extra ``[dask]``: ``dask[distributed]``).

Workers read the scans themselves from their paths, so every worker must reach the files under
the same paths (shared storage: NFS, SMB, a cluster file system). Tasks return only transforms
and metrics. A worker lost mid-task is replaced and its task rerun by Dask (up to
``allowed-failures`` times); a task that fails because of its data returns a failed link and is
not retried.
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Hashable
from typing import Any

from ndt_cli.core.logs import PROGRESS
from ndt_cli.errors import ConfigError
from ndt_cli.pipeline.workers import Results, Task, Then, set_threads, worker_error


def _in_worker(threads: int, task: Task) -> Any:
    """Run a chain task inside a Dask worker with a bounded number of Numba threads."""
    set_threads(threads)
    return task()


class DaskPool:
    """The :class:`~ndt_cli.pipeline.executors.Executor` interface on a Dask cluster.

    ``scheduler``: address of a running scheduler (``tcp://host:8786``); None starts a
    LocalCluster of ``jobs`` worker processes on this machine and prints its dashboard address.
    """

    ships_data = False  # tasks read their scans from paths; nothing large goes over the wire

    def __init__(self, scheduler: str | None, jobs: int, threads: int, retries: int = 2) -> None:
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise ConfigError(
                "--executor dask needs dask.distributed: pip install 'ndt-cli[dask]'"
            ) from None
        self.threads = threads
        self.retries = retries
        self._cluster = None
        try:
            if scheduler is None:
                self._cluster = LocalCluster(
                    n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=":0"
                )
                self.client = Client(self._cluster)
                logging.getLogger(PROGRESS).info("Dask dashboard: %s", self.client.dashboard_link)
            else:
                self.client = Client(scheduler, timeout="30s")
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None

    def start(self) -> None:
        """Nothing to do: the cluster is up once the client is connected."""

    def run(self, tasks: dict[Hashable, Task], then: Then | None = None) -> Results:
        """Yield (key, result) as tasks finish; a task that raised yields a
        :class:`~ndt_cli.pipeline.workers.Failure`.
        ``then(key, result)`` returns more tasks for this run (see the executors module)."""
        from dask.distributed import as_completed

        run_id = uuid.uuid4().hex[:8]
        futures = {self._submit(run_id, key, task): key for key, task in tasks.items()}
        finished = as_completed(list(futures))
        for fut in finished:
            key = futures[fut]
            try:
                value = fut.result()
            except Exception as exc:  # KilledWorker, or a bug in the task
                value = worker_error(exc)
            yield key, value
            for new, task in (then(key, value) if then else {}).items():
                added = self._submit(run_id, new, task)
                futures[added] = new
                finished.add(added)

    def _submit(self, run_id: str, key: Hashable, task: Task) -> Any:
        return self.client.submit(
            _in_worker,
            self.threads,
            task,
            key=f"ndt-{run_id}-{key}",
            pure=False,
            retries=self.retries,
        )

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None
