"""The prepared scans a campaign keeps between steps: what they hold is measured, what is kept
fits its budget, and a link whose scans were forgotten reads them again."""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pytest

from ndt_cli.config import Config
from ndt_cli.config.loading import dump
from ndt_cli.core.arrays import array_bytes
from ndt_cli.pipeline import link_runner
from ndt_cli.pipeline.link_runner import LinkRunner
from ndt_cli.pipeline.links import LinkStore
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.network import LinkKind, PlannedLink
from ndt_cli.pipeline.scans import identity
from ndt_cli.pipeline.tasks import summarise_scan

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data"


@dataclass
class _Holder:
    a: np.ndarray
    views: tuple
    nested: dict

    @cached_property
    def later(self) -> np.ndarray:
        return np.zeros(7, np.int64)


def test_array_bytes_counts_every_array_once_views_by_their_base():
    a = np.zeros(1000)  # 8000 bytes
    b = np.zeros((10, 10), np.float32)  # 400
    h = _Holder(a, (a[::2], b, "text", 3), {"x": b.T, "y": [np.ones(5, np.int16)]})  # + 10
    assert array_bytes(h) == 8000 + 400 + 10
    _ = h.later  # a cached property, once built, is held too
    assert array_bytes(h) == 8000 + 400 + 10 + 56
    assert array_bytes(a[100:200]) == 8000  # a slice keeps its whole base alive


def test_a_prepared_scan_measures_about_what_it_pickles_to():
    prepared = summarise_scan(SAMPLE / "scan_00.laz", Config(), True).prepared
    held, pickled = array_bytes(prepared), len(pickle.dumps(prepared))
    assert 0.8 * pickled <= held <= 1.3 * pickled, (held, pickled)


def _runner(tmp_path: Path, files: list[Path]) -> LinkRunner:
    cfg = Config()
    hashes = [identity(f) for f in files]
    store = LinkStore(tmp_path / "out")
    return LinkRunner(cfg, dump(cfg), WorkerPool(1), store, list(files), hashes)


@pytest.mark.parametrize("scans_kept", [0, 2])
@pytest.mark.slow
def test_kept_scans_fit_the_budget_and_links_read_forgotten_scans_again(
    tmp_path, monkeypatch, scans_kept
):
    """A budget of no scan or about two of the sample's: what is kept never exceeds it, the
    scans used last stay, and every link still registers, its scans read again."""
    files = sorted(SAMPLE.glob("scan_0*.laz"))[:4]
    one = array_bytes(summarise_scan(files[0], Config(), True).prepared)
    budget = int(scans_kept * one * 1.2)
    monkeypatch.setattr(link_runner, "PREPARED_BYTES", budget)
    runner = _runner(tmp_path, files)
    try:
        runner.summarise([0, 1, 2, 3])
        kept = sum(array_bytes(p) for p in runner.prepared.values())
        assert kept <= budget and len(runner.prepared) == scans_kept
        assert list(runner.prepared) == [0, 1, 2, 3][4 - scans_kept :]  # the last prepared
        runner.register([PlannedLink(0, 1, LinkKind.FOUND), PlannedLink(1, 2, LinkKind.FOUND)])
    finally:
        runner.executor.close()
    assert sum(array_bytes(p) for p in runner.prepared.values()) <= budget
    for pair in [(0, 1), (1, 2)]:
        link = runner.links[pair]
        assert link.result is not None and link.ok, (pair, link.status)
