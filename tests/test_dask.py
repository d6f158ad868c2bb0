"""ndt-chain on a Dask cluster: same results as the local executor, survives a lost worker."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

pytest.importorskip("distributed", reason="the dask extra (dask[distributed]) is not installed")

from conftest import added_task_order, street_files
from distributed import Client, LocalCluster

from ndt_cli.config import Config
from ndt_cli.pipeline.chain import NetworkOptions, run_chain
from ndt_cli.pipeline.executors import ExecutorKind, make_executor
from ndt_cli.report.chain_outputs import write_chain_outputs

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cluster():
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as c:
        yield c


def _dask(cluster):
    """An executor on the test cluster."""
    return make_executor(ExecutorKind.DASK, 2, cluster.scheduler_address)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return street_files(tmp_path_factory.mktemp("dask_seq"))[0]


@pytest.fixture(scope="module")
def local_run(files, tmp_path_factory):
    """The chain run by the local executor, and its output folder."""
    out = tmp_path_factory.mktemp("local")
    return run_chain(files, Config(), out, jobs=1), out


def _outputs(result):
    return [
        (
            link.index,
            link.status,
            None if link.T_target_source is None else link.T_target_source.tobytes(),
        )
        for link in result.links
    ] + [None if T is None else T.tobytes() for T in result.poses]


def test_dask_gives_the_same_results_as_local(cluster, files, local_run, tmp_path):
    local, _ = local_run
    cfg = Config()
    dask = run_chain(files, cfg, tmp_path / "dask", executor=_dask(cluster))
    assert dask.ok and len(dask.links) == 5  # each scan to its nearest (0-1, 1-2, 2-3, 0-2, 1-3)
    assert _outputs(dask) == _outputs(local)
    write_chain_outputs(tmp_path / "dask", dask, cfg, 0.0)
    write_chain_outputs(tmp_path / "local", local, cfg, 0.0)  # same outputs, same bytes
    for name in ["poses.txt", "poses.csv"]:
        assert (tmp_path / "dask" / name).read_bytes() == (tmp_path / "local" / name).read_bytes()


def test_resume_skips_finished_links_before_submission(cluster, files, local_run, tmp_path):
    local, local_out = local_run
    import shutil

    cfg = Config()
    out = tmp_path / "o"
    shutil.copytree(local_out / "links", out / "links")  # the finished links of the local run
    again = run_chain(files, cfg, out, resume=True, executor=_dask(cluster))
    assert again.reused == tuple(range(len(local.links)))
    assert _outputs(again) == _outputs(local)


def test_a_worker_killed_mid_run_does_not_stop_the_chain(cluster, tmp_path):
    files = street_files(tmp_path / "street", n_scans=6)[0]  # six scans: tasks to spare
    cfg = Config()
    with Client(cluster.scheduler_address) as client:
        pids = list(client.run(os.getpid).values())
    killed = []

    def kill_one(link):  # after the first finished link, kill a worker process
        if not killed:
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])

    result = run_chain(
        files,
        cfg,
        tmp_path / "o",
        executor=_dask(cluster),
        network=NetworkOptions(neighbours=1, adjust=False),
        on_progress=kill_one,
    )
    assert killed and len(result.links) == 5
    assert all(link.status in ("ok", "suspect", "degenerate") for link in result.links)
    classic = NetworkOptions(neighbours=1, adjust=False)
    reference = run_chain(files[:4], cfg, tmp_path / "ref", jobs=1, network=classic)
    same = {(k.target, k.source): k for k in reference.links}
    for a in result.links[:3]:  # the links of the first four scans, as the local run has them
        assert np.array_equal(a.T_target_source, same[(a.target, a.source)].T_target_source)


def test_a_scan_that_cannot_be_read_fails_its_link_once(cluster, files, tmp_path):
    bad = tmp_path / "scan_1.laz"
    bad.write_bytes(files[1].read_bytes()[:4000])  # truncated: fails for its data
    result = run_chain(
        [files[0], bad, files[2]],
        Config(),
        tmp_path / "o",
        executor=_dask(cluster),
        network=NetworkOptions(neighbours=1, adjust=False),
    )
    assert result.links[0].status == "failed" and "scan_1.laz" in result.links[0].reason
    assert (result.links[1].target, result.links[1].source) == (0, 2)
    assert result.unreadable and 1 in result.unreadable


def test_dask_runs_the_tasks_that_results_add(cluster):
    order = added_task_order(_dask(cluster))
    assert order == [("fast", "fast"), ("added", "added after fast"), ("slow", "slow")]
