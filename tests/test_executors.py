"""Executors run tasks that other tasks' results add to the same run (``then``): a link starts as
soon as its two scans are ready, without waiting for the slowest scan."""

from __future__ import annotations

import os
from functools import partial

from conftest import added_task_order, after

from ndt_cli.pipeline.local_pool import WorkerPool


def _die() -> None:
    os._exit(3)


def test_a_task_added_by_a_result_runs_beside_the_slow_tasks_of_the_run():
    order = added_task_order(WorkerPool(2, threads=1))
    assert order == [("fast", "fast"), ("added", "added after fast"), ("slow", "slow")]


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
