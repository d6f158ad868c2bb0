"""Register a campaign of scans as a network of links and give every scan a pose and a status.

1. **Plan**: each scan against its ``neighbours`` predecessors, plus the user's pairs
   (:mod:`ndt_cli.pipeline.network`).
2. **Prepare** every scan a link needs, once, in parallel; a scan that cannot be read fails its
   links and the plan goes around it.
3. **Register** the links in parallel on an executor, each as soon as its two scans are
   prepared; each finished link is saved at once, so an interrupted run resumes where it
   stopped (``resume``).
4. **Close loops** (with the adjustment): scans that a first solution puts within the loop
   radius but that no link joins are registered too, with the network's pose as one more
   candidate of the search.
5. **Solve** (:mod:`ndt_cli.pipeline.solution`): the adjusted (or chained) ``T_world_scan``
   and status of every scan; the world is the ``anchor`` scan's frame.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.errors import UserInterruptError, caused_by_interrupt
from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.pipeline.executors import Executor
from ndt_cli.pipeline.links import Link, LinkStore, link_key
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.network import (
    LOOP_RADIUS_FACTOR,
    PlannedLink,
    median_adjacent_length,
    merge,
    plan_loops,
    plan_sequence,
)
from ndt_cli.pipeline.scans import file_hash, scan_names
from ndt_cli.pipeline.solution import NetworkSolution, solve
from ndt_cli.pipeline.tasks import LinkJob, prepare_scan, register_link, register_paths
from ndt_cli.pipeline.verify import NodeStatus
from ndt_cli.pipeline.workers import default_jobs

log = logging.getLogger(__name__)
progress = logging.getLogger("ndt_cli.progress")


@dataclass(frozen=True)
class NetworkOptions:
    """Which links the network holds and how it is solved: ``neighbours`` predecessors per
    scan, the ``adjust``-ment (and loop closures within ``loop_radius`` m, None: twice the
    median adjacent link, 0: none), the user's ``pairs``."""

    neighbours: int = 2
    adjust: bool = True
    loop_radius: float | None = None
    pairs: tuple[PlannedLink, ...] = ()


@dataclass(frozen=True)
class ChainResult:
    """The links of a campaign and what the network made of them."""

    scans: tuple[Path, ...]
    names: tuple[str, ...]  # unique scan names, as the outputs show them
    links: tuple[Link, ...]
    solution: NetworkSolution
    anchor: int
    unreadable: dict[int, str]
    previews: dict[int, np.ndarray]  # thinned slice points (x, y, z) per scan, scan frame
    reused: tuple[int, ...] = ()  # links taken from an earlier run (--resume)
    loop_radius: float = float("nan")  # m, the radius loop closures were searched within

    @property
    def poses(self) -> tuple[np.ndarray | None, ...]:
        """``T_world_scan`` of every scan (None when unposed; suspect scans have one too)."""
        return self.solution.poses

    @property
    def ok(self) -> bool:
        """Every scan has a trustworthy pose in the anchor's frame (one cluster)."""
        return all(s.anchored for s in self.solution.scans)


def plan_links(n_scans: int, unreadable: set[int]) -> list[tuple[int, int]]:
    """(target, source) pairs of the classic chain: each scan against the last readable scan
    before it (one neighbour)."""
    return [(k.target, k.source) for k in plan_sequence(n_scans, 1, unreadable)]


class _ChainRun:
    """The state of one run: what is planned, finished, prepared and unreadable."""

    def __init__(
        self, paths: list[Path], cfg: Config, out: Path, executor: Executor, report: Callable
    ) -> None:
        self.paths, self.cfg, self.executor = paths, cfg, executor
        self.store = LinkStore(out)
        self.cfg_text = dump(cfg)
        self._hashes: dict[int, str] = {}
        self.on_progress = report
        self.unreadable: dict[int, str] = {}
        self.finished: dict[tuple[int, int], Link] = {}
        self.prepared: dict[int, PreparedScan] = {}
        self.previews: dict[int, np.ndarray] = {}
        self.reused: set[tuple[int, int]] = set()
        self.order: list[tuple[int, int]] = []  # pairs in the order the links were planned

    def hash(self, i: int) -> str:
        """Scan ``i``'s file hash, computed when first needed: a run that does not resume
        hashes its scans while the workers prepare them."""
        if i not in self._hashes:
            self._hashes[i] = file_hash(self.paths[i])
        return self._hashes[i]

    def jobs(self, planned: Sequence[PlannedLink], guesses: dict | None = None) -> list[LinkJob]:
        """One job per planned link, keyed by its inputs (and a loop closure's guess)."""
        return [self._job(k, len(self.order) + n, guesses) for n, k in enumerate(planned)]

    def _job(self, k: PlannedLink, index: int, guesses: dict | None) -> LinkJob:
        guess = (guesses or {}).get((k.target, k.source))
        extra = "" if guess is None else " ".join(f"{v:.6f}" for v in guess.ravel())
        key = link_key(self.hash(k.target), self.hash(k.source), self.cfg_text + extra)
        return LinkJob(index, k.target, k.source, key, k.kind, guess)

    def reuse(self, jobs: list[LinkJob]) -> None:
        """Take the links an earlier run finished with the same inputs (``--resume``)."""
        for job in jobs:
            link = self.store.load(job.target, job.source, job.key)
            if link is not None:
                self.finished[(job.target, job.source)] = job.adopt(link)
                self.reused.add((job.target, job.source))

    def prepare(self, planned: Sequence[PlannedLink], guesses: dict | None = None) -> None:
        """Read and slice, once and in parallel, each scan that an unfinished link needs, and
        start each link as soon as its two scans are ready (no wait for the other scans); a
        link that finishes is saved at once. Links of a scan that cannot be read are left to
        :meth:`register`."""
        todo = [j for j in planned if (j.target, j.source) not in self.finished]
        scans = {s for j in todo for s in (j.target, j.source)}
        needed = sorted(s for s in scans if not self._ready(s) and s not in self.unreadable)
        task = prepare_scan if self.executor.ships_data else _preview_or_problem
        tasks: dict = {("scan", i): partial(task, self.paths[i], self.cfg) for i in needed}
        if tasks:
            progress.info("preparing %d scan(s)", len(tasks))
        waiting = {(k.target, k.source): (n, k) for n, k in enumerate(todo)}
        jobs: dict[tuple[int, int], LinkJob] = {}

        def then(key: tuple, value: object) -> dict:  # a scan is in: start what it completes
            return {} if key[0] != "scan" else self._start(waiting, jobs, guesses)

        tasks.update(self._start(waiting, jobs, guesses))  # links whose scans are in already
        for key, value in self.executor.run(tasks, then):
            if key[0] == "scan":
                self._prepared(key[1], value)
            else:
                self._finish(jobs[key[1:]], value)

    def _ready(self, i: int) -> bool:
        """Scan ``i`` is prepared (or, where tasks read their scans, known to be readable)."""
        return i in (self.prepared if self.executor.ships_data else self.previews)

    def _start(self, waiting: dict, jobs: dict, guesses: dict | None) -> dict:
        """The link tasks whose two scans are ready now (removed from ``waiting``)."""
        go = [p for p in waiting if self._ready(p[0]) and self._ready(p[1])]
        tasks = {}
        for pair in go:
            n, k = waiting.pop(pair)
            jobs[pair] = self._job(k, len(self.order) + n, guesses)
            tasks[("link", *pair)] = self._task(jobs[pair])
        return tasks

    def _prepared(self, i: int, value: PreparedScan | np.ndarray | str) -> None:
        if isinstance(value, str):
            self.unreadable[i] = value
            return
        if isinstance(value, PreparedScan):
            self.prepared[i], value = value, value.preview()
        self.previews[i] = value
        self.store.save_preview(self._scan_key(i), value)

    def _finish(self, job: LinkJob, link: Link | str) -> None:
        if isinstance(link, str):  # the worker died or raised: this link fails, not the run
            self._report(job.failed(link))
            return
        self.store.save(link)
        self._report(link)

    def _scan_key(self, i: int) -> str:
        return link_key(self.hash(i), "", self.cfg_text)

    def register(self, jobs: list[LinkJob]) -> None:
        """Register every link not finished yet; each is saved as soon as it is done."""
        self.order += [(j.target, j.source) for j in jobs]
        for job in jobs:
            if (job.target, job.source) in self.reused:
                self._report(self.finished[(job.target, job.source)])
        tasks = {}
        for job in jobs:
            if (job.target, job.source) in self.finished:
                continue
            bad = self.unreadable.get(job.source) or self.unreadable.get(job.target)
            if bad:
                self._report(job.failed(bad))
            else:
                tasks[job.index] = self._task(job)
        if tasks:
            progress.info("registering %d link(s)", len(tasks))
        by_index = {job.index: job for job in jobs}
        for index, link in self.executor.run(tasks):
            self._finish(by_index[index], link)

    def _task(self, job: LinkJob) -> Callable[[], Link]:
        i, j = job.target, job.source
        if self.executor.ships_data:
            return partial(register_link, job, self.prepared[i], self.prepared[j], self.cfg)
        return partial(register_paths, job, self.paths[i], self.paths[j], self.cfg)

    def _report(self, link: Link) -> None:
        self.finished[(link.target, link.source)] = link
        if self.on_progress:
            self.on_progress(link)

    def links(self) -> list[Link]:
        """The finished links in planning order, indexed 0, 1, ..."""
        return [replace(self.finished[p], index=k) for k, p in enumerate(self.order)]


def _preview_or_problem(path: Path, cfg: Config) -> np.ndarray | str:
    """A worker task: the scan's preview points, or the one-line reason it cannot be used."""
    value = prepare_scan(path, cfg)
    return value if isinstance(value, str) else value.preview()


@contextmanager
def _stopping(run: _ChainRun) -> Iterator[None]:
    """The executor is closed however the run ends. On Ctrl-C, what finished is kept; tasks
    that have not started are cancelled, those running finish first (seconds)."""
    try:
        yield
    except BaseException as exc:
        if not caused_by_interrupt(exc):
            raise
        raise UserInterruptError(
            f"interrupted: {len(run.finished)} finished link(s) kept in {run.store.folder}; "
            "run again with --resume to continue"
        ) from None
    finally:
        run.executor.close()


@dataclass
class _Step:
    """One round of links: plan, reuse, prepare, register."""

    run: _ChainRun
    resume: bool
    planned: list[PlannedLink] = field(default_factory=list)

    def __call__(self, planned: Sequence[PlannedLink], guesses: dict | None = None) -> None:
        if self.resume:
            self.run.reuse(self.run.jobs(planned, guesses))
        self.run.prepare(planned, guesses)
        self.planned += list(planned)


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
    """Register the scans as a network (see the module docstring) and solve it.

    ``executor``: where tasks run (default: ``jobs`` local worker processes); results do not
    depend on it. The executor is closed when the run ends.
    """
    net = network or NetworkOptions()
    executor = executor or WorkerPool(default_jobs(jobs))
    paths = [Path(p) for p in scans]
    run = _ChainRun(paths, cfg, Path(out), executor, on_progress)
    run.store.clean_stale()
    step = _Step(run, resume)
    with _stopping(run):
        _first_round(run, step, net)
        radius = _close_loops(run, step, net, anchor)
    return _result(run, anchor, net, radius)


def _first_round(run: _ChainRun, step: _Step, net: NetworkOptions) -> None:
    """Plan, prepare and register the sequence and user links (re-planned around the scans
    that cannot be read)."""
    n = len(run.paths)
    step(merge([*plan_sequence(n, net.neighbours), *net.pairs]))
    planned = merge([*plan_sequence(n, net.neighbours, run.unreadable), *net.pairs])
    new = [k for k in planned if k not in step.planned]
    if new:
        step(new)
    run.register(run.jobs(planned))


def _close_loops(run: _ChainRun, step: _Step, net: NetworkOptions, anchor: int) -> float:
    """With the adjustment: a first solution, then the loop closures it suggests. Returns the
    loop radius used (m; NaN when there was none)."""
    if not net.adjust or net.loop_radius == 0:
        return float("nan")
    links = run.links()
    first = solve(len(run.paths), anchor, links, True, run.unreadable)
    radius = net.loop_radius
    if radius is None:
        radius = LOOP_RADIUS_FACTOR * median_adjacent_length(step.planned, first.poses)
    if not np.isfinite(radius):
        return float("nan")
    ok = [  # positions in the anchor's frame: the scans of its cluster only
        s.T_world_scan if s.status is NodeStatus.OK and s.cluster == 0 else None
        for s in first.scans
    ]
    loops = plan_loops(ok, step.planned, radius)
    if loops:
        guesses = {(k.target, k.source): _guess(first, k) for k in loops}
        step(loops, guesses)
        run.register(run.jobs(loops, guesses))
    return float(radius)


def _guess(solution: NetworkSolution, k: PlannedLink) -> np.ndarray:
    """T_target_source that the network gives a loop candidate (scan frames)."""
    T_t, T_s = solution.poses[k.target], solution.poses[k.source]
    return np.linalg.inv(T_t) @ T_s


def _result(run: _ChainRun, anchor: int, net: NetworkOptions, radius: float) -> ChainResult:
    links = tuple(run.links())
    for reason in dict(sorted(run.unreadable.items())).values():
        log.warning("%s", reason)
    if net.adjust:
        progress.info("adjusting the network of %d link(s)", len(links))
    solution = solve(len(run.paths), anchor, links, net.adjust, run.unreadable)
    for i in range(len(run.paths)):
        if i not in run.previews and i not in run.unreadable:
            preview = run.store.load_preview(run._scan_key(i))
            if preview is not None:
                run.previews[i] = preview
    reused = tuple(k for k, link in enumerate(links) if (link.target, link.source) in run.reused)
    return ChainResult(
        scans=tuple(run.paths),
        names=tuple(scan_names(run.paths)),
        links=links,
        solution=solution,
        anchor=anchor,
        unreadable=dict(sorted(run.unreadable.items())),
        previews=dict(sorted(run.previews.items())),
        reused=reused,
        loop_radius=radius,
    )
