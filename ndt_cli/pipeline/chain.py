"""Register a sequence of scans pair by pair and chain the links into one frame.

Scan i is registered against scan i-1 (the last readable scan before it). The first scan, or
``anchor``, defines the world frame: ``T_world_scan`` of every other scan is the product of the
links between them. Links are independent and run in parallel on an executor; each finished link
is written at once (see :class:`~ndt_cli.pipeline.links.LinkStore`), so an interrupted chain
resumes where it stopped and gives the same outputs.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.errors import UserInterruptError
from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.pipeline.executors import Executor
from ndt_cli.pipeline.links import Link, LinkStore, link_key
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.scans import file_hash, scan_names
from ndt_cli.pipeline.tasks import LinkJob, prepare_scan, register_link, register_paths
from ndt_cli.pipeline.workers import default_jobs

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ChainResult:
    """All links, and ``T_world_scan`` per scan (None when a failed link cuts it off)."""

    scans: tuple[Path, ...]
    names: tuple[str, ...]  # unique scan names, as the outputs show them
    links: tuple[Link, ...]
    poses: tuple[np.ndarray | None, ...]
    anchor: int
    unreadable: dict[int, str]
    previews: dict[int, np.ndarray]  # thinned slice points (x, y, z) per scan, scan frame
    reused: tuple[int, ...] = ()  # links taken from an earlier run (--resume)

    @property
    def ok(self) -> bool:
        return not self.unreadable and all(link.ok for link in self.links)


def plan_links(n_scans: int, unreadable: set[int]) -> list[tuple[int, int]]:
    """(target, source) per scan after the first: the last readable scan before it as target.

    Link ``k`` has source scan ``k + 1``; a link whose source cannot be read fails, and the next
    scan is registered against the last readable one instead.
    """
    pairs = []
    last = 0
    for j in range(1, n_scans):
        pairs.append((last, j))
        if j not in unreadable or last in unreadable:
            last = j
    return pairs


def compose_poses(n_scans: int, links: Sequence[Link], anchor: int) -> list[np.ndarray | None]:
    """``T_world_scan`` per scan from the links (world = the anchor scan's frame).

    Only ok links carry a pose: a link that failed or is not ok (suspect, degenerate, ...)
    leaves its source without one, and so are the scans registered against a scan without one.
    """
    poses: list[np.ndarray | None] = [None] * n_scans
    poses[anchor] = np.eye(4)
    with_T = [link for link in links if link.ok]
    for link in sorted(with_T, key=lambda k: k.source):  # forward: T_w_j = T_w_i @ T_i_j
        if link.source > anchor and poses[link.target] is not None:
            poses[link.source] = poses[link.target] @ link.T_target_source
    for link in sorted(with_T, key=lambda k: -k.source):  # backward: T_w_i = T_w_j @ inv(T_i_j)
        if link.source <= anchor and poses[link.source] is not None:
            poses[link.target] = poses[link.source] @ np.linalg.inv(link.T_target_source)
    return poses


class _ChainRun:
    """The state of one chain run: what is planned, finished, prepared and unreadable."""

    def __init__(
        self,
        paths: list[Path],
        cfg: Config,
        out: Path,
        executor: Executor,
        on_progress: Callable[[Link], None] | None,
    ) -> None:
        self.paths, self.cfg, self.executor = paths, cfg, executor
        self.store = LinkStore(out)
        self.cfg_text = dump(cfg)
        self.hashes = [file_hash(p) for p in paths]
        self.on_progress = on_progress
        self.unreadable: dict[int, str] = {}
        self.finished: dict[int, Link] = {}
        self.prepared: dict[int, PreparedScan] = {}
        self.previews: dict[int, np.ndarray] = {}
        self.reused: set[int] = set()

    def plan(self) -> list[LinkJob]:
        """One job per link of the plan around the scans known to be unreadable."""
        pairs = plan_links(len(self.paths), set(self.unreadable))
        return [
            LinkJob(k, i, j, link_key(self.hashes[i], self.hashes[j], self.cfg_text))
            for k, (i, j) in enumerate(pairs)
        ]

    def reuse(self, jobs: list[LinkJob]) -> None:
        """Take the links an earlier run finished with the same inputs (``--resume``)."""
        for job in jobs:
            link = self.store.load(job.index, job.key)
            if link is not None and (link.target, link.source) == (job.target, job.source):
                self.finished[job.index] = link

    def prepare(self, jobs: list[LinkJob]) -> None:
        """Read and slice, once and in parallel, each scan that an unfinished link needs."""
        todo = [j for j in jobs if j.index not in self.finished]
        needed = sorted({s for j in todo for s in (j.target, j.source)})
        task = prepare_scan if self.executor.ships_data else _preview_or_problem
        tasks = {i: partial(task, self.paths[i], self.cfg) for i in needed}
        for i, value in self.executor.run(tasks):
            if isinstance(value, str):
                self.unreadable[i] = value
                continue
            if isinstance(value, PreparedScan):
                self.prepared[i], value = value, value.preview()
            self.previews[i] = value
            self.store.save_preview(self._scan_key(i), value)

    def _scan_key(self, i: int) -> str:
        return link_key(self.hashes[i], "", self.cfg_text)

    def register(self, jobs: list[LinkJob]) -> None:
        """Register every link not finished yet; each is saved as soon as it is done."""
        self.finished = {k: v for k, v in self.finished.items() if v.key == jobs[k].key}
        self.reused = set(self.finished)
        for link in list(self.finished.values()):
            self._report(link)
        tasks = {}
        for job in jobs:
            if job.index in self.finished:
                continue
            bad = self.unreadable.get(job.source) or self.unreadable.get(job.target)
            if bad:
                self._report(job.failed(bad))
            else:
                tasks[job.index] = self._task(job)
        by_index = {job.index: job for job in jobs}
        for index, link in self.executor.run(tasks):
            if isinstance(link, str):  # the worker died or raised: this link fails, not the chain
                self._report(by_index[index].failed(link))
                continue
            self.store.save(link)
            self._report(link)

    def _task(self, job: LinkJob) -> Callable[[], Link]:
        i, j = job.target, job.source
        if self.executor.ships_data:
            return partial(register_link, job, self.prepared[i], self.prepared[j], self.cfg)
        return partial(register_paths, job, self.paths[i], self.paths[j], self.cfg)

    def _report(self, link: Link) -> None:
        self.finished[link.index] = link
        if self.on_progress:
            self.on_progress(link)

    def result(self, anchor: int) -> ChainResult:
        links = tuple(self.finished[k] for k in sorted(self.finished))
        for i in range(len(self.paths)):
            if i not in self.previews and i not in self.unreadable:
                preview = self.store.load_preview(self._scan_key(i))
                if preview is not None:
                    self.previews[i] = preview
        for reason in dict(sorted(self.unreadable.items())).values():
            log.warning("%s", reason)
        return ChainResult(
            scans=tuple(self.paths),
            names=tuple(scan_names(self.paths)),
            links=links,
            poses=tuple(compose_poses(len(self.paths), links, anchor)),
            anchor=anchor,
            unreadable=dict(sorted(self.unreadable.items())),
            previews=dict(sorted(self.previews.items())),
            reused=tuple(sorted(self.reused)),
        )


def _preview_or_problem(path: Path, cfg: Config) -> np.ndarray | str:
    """A worker task: the scan's preview points, or the one-line reason it cannot be used."""
    value = prepare_scan(path, cfg)
    return value if isinstance(value, str) else value.preview()


@contextmanager
def _stopping(run: _ChainRun) -> Iterator[None]:
    """Ctrl-C stops the workers at once and keeps what finished; the executor is closed."""
    try:
        yield
    except KeyboardInterrupt:
        run.executor.terminate()
        raise UserInterruptError(
            f"interrupted: {len(run.finished)} finished link(s) kept in {run.store.folder}; "
            "run again with --resume to continue"
        ) from None
    finally:
        run.executor.close()


def run_chain(
    scans: Sequence[str | Path],
    cfg: Config,
    out: str | Path,
    *,
    executor: Executor | None = None,
    jobs: int | None = None,
    resume: bool = False,
    anchor: int = 0,
    on_progress: Callable[[Link], None] | None = None,
) -> ChainResult:
    """Register the scans in the order given, write each link as it finishes, compose poses.

    ``executor``: where tasks run (default: ``jobs`` local worker processes); results do not
    depend on it. The executor is closed when the chain ends.
    """
    executor = executor or WorkerPool(default_jobs(jobs))
    run = _ChainRun([Path(p) for p in scans], cfg, Path(out), executor, on_progress)
    run.store.clean_stale()
    with _stopping(run):
        jobs_planned = run.plan()
        if resume:
            run.reuse(jobs_planned)
        run.prepare(jobs_planned)
        run.register(run.plan())  # re-planned around the scans that could not be read
    return run.result(anchor)
