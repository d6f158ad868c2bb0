"""Register a campaign given all at once (``ndt-chain``): the campaign engine
(:mod:`ndt_cli.pipeline.campaign`) fed every scan in one step, then solved."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path

from ndt_cli.config.schema import Config
from ndt_cli.errors import InputError, NdtError
from ndt_cli.ndt.prepare import look, settle_scene
from ndt_cli.pipeline.campaign import Campaign, NetworkOptions
from ndt_cli.pipeline.executors import Executor
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.network import classic_chain
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.scans import file_hash
from ndt_cli.pipeline.workers import default_jobs

__all__ = ["ChainResult", "NetworkOptions", "plan_links", "run_chain", "scene_of"]

progress = logging.getLogger("ndt_cli.progress")  # a stage line, shown as it happens
LOOKS = 3  # scans looked at in turn for the scene when the first cannot be read


def plan_links(n_scans: int, unreadable: set[int]) -> list[tuple[int, int]]:
    """(target, source) pairs of the classic chain: each scan against the last readable scan
    before it."""
    return [(k.target, k.source) for k in classic_chain(n_scans, unreadable)]


def scene_of(cfg: Config, scans: Sequence[str | Path], level: int = logging.INFO) -> Config:
    """``cfg`` for the scene of the campaign (``scene.kind`` auto: what the first readable of
    ``scans`` sees above it, :func:`~ndt_cli.ndt.prepare.settle_scene`); logged at ``level``."""
    if cfg.scene.kind != "auto":
        return cfg
    view = None
    for path in list(scans)[:LOOKS]:
        try:
            view = look(path, cfg)
            break
        except NdtError:
            continue
    settled, why = settle_scene(cfg, view)
    progress.log(level, "scene %s", why)
    return settled


def run_chain(
    scans: Sequence[str | Path],
    cfg: Config,
    out: str | Path,
    *,
    executor: Executor | None = None,
    jobs: int | None = None,
    resume: bool = False,
    anchor: int = 0,
    network: NetworkOptions | None = None,
    on_progress: Callable[[Link], None] | None = None,
) -> ChainResult:
    """Register the scans (in campaign order) as a network and solve it.

    ``executor``: where tasks run (default: ``jobs`` local worker processes); results do not
    depend on it. The executor is closed when the run ends.
    """
    cfg = scene_of(cfg, [scans[anchor], *scans])
    pool = executor or WorkerPool(default_jobs(jobs))
    campaign = Campaign(
        cfg, out, pool, network=network, resume=resume, anchor=anchor, on_link=on_progress
    )
    try:
        campaign.add_scans(list(scans))
        result = campaign.result()
    finally:
        campaign.close()
    refuse_changed(result)
    return result


def refuse_changed(result: ChainResult) -> None:
    """Raise :class:`InputError` when a scan's file is not the one registered: its content
    changed since the campaign took it (a file still being copied or synced when the run
    started). Its poses would be exported onto other points."""
    for path, registered in zip(result.scans, result.hashes, strict=False):
        if registered is not None and file_hash(path, reuse=False) != registered:
            raise InputError(
                "changed while the campaign was registered (still being copied?): run again "
                "once it is complete (--resume keeps the finished links)",
                path,
            )
