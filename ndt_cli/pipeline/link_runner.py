"""The tasks of a campaign on its executor: scans prepared, links registered, each kept at once.

A :class:`LinkRunner` owns what the tasks give: each scan's summary (and, for an executor
that ships data, its prepared scan, those used last up to :data:`PREPARED_BYTES`), the scans
that could not be read, and the links, each finished link saved in the link store
(:mod:`ndt_cli.pipeline.links`) as soon as it comes. Links are keyed by their inputs (the
scans' content and the configuration), so a link is registered once and, with ``resume``,
taken from the store of an earlier run.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import replace
from functools import partial
from pathlib import Path

from ndt_cli.config.schema import Config
from ndt_cli.core.arrays import array_bytes
from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.ndt.result import Deeper, Status
from ndt_cli.pipeline.executors import Executor
from ndt_cli.pipeline.guesses import guess_text, turned_round
from ndt_cli.pipeline.link_use import usable
from ndt_cli.pipeline.links import Link, LinkStore, link_key, skipped_key
from ndt_cli.pipeline.network import LinkKind, Pair, PlannedLink
from ndt_cli.pipeline.scans import scan_names
from ndt_cli.pipeline.tasks import LinkJob, ScanSummary, register_link, register_paths
from ndt_cli.pipeline.tasks import summarise_scan as _summarise
from ndt_cli.pipeline.workers import Failure

progress = logging.getLogger("ndt_cli.progress")

# Bytes of prepared scans kept in memory between steps (others are read again): a sparse scan
# prepared holds about 4 MB, a 2 M-point one 12 MB. A count of scans would be too few for a
# campaign of hundreds of sparse scans, where a walk's consolidation, which goes through the
# pairs in order, read every scan twice with 48 kept, and too many for dense ones.
PREPARED_BYTES = 2 * 1024**3


class LinkRunner:
    """Prepares scans and registers links on ``executor`` (see the module docstring).

    ``paths`` and ``hashes`` are the campaign's scans (files and content identities, in
    campaign order): the runner reads them as they grow. ``cfg_text``: the configuration as
    text, part of every key. ``on_link`` is called with each finished link.
    """

    def __init__(
        self,
        cfg: Config,
        cfg_text: str,
        executor: Executor,
        store: LinkStore,
        paths: list[Path],
        hashes: list[str],
        *,
        resume: bool = False,
        on_link: Callable[[Link], None] | None = None,
    ) -> None:
        self.cfg, self.cfg_text, self.executor, self.store = cfg, cfg_text, executor, store
        self.paths, self.hashes = paths, hashes
        self.resume, self.on_link = resume, on_link
        self.summaries: dict[int, ScanSummary] = {}
        self.prepared: OrderedDict[int, PreparedScan] = OrderedDict()  # least recently used first
        self._sizes: dict[int, int] = {}  # bytes of each prepared scan kept
        self.unreadable: dict[int, str] = {}
        self.links: dict[Pair, Link] = {}
        self.tried: list[Link] = []  # every finished registration, the better way round or not
        self.finished: set[str] = set()  # keys of the links registered (or taken) so far
        self.reused: set[str] = set()  # keys of the links taken from the store
        self.turned: set[Pair] = set()  # pairs registered the other way round too

    def scan_key(self, i: int) -> str:
        """The key of scan ``i``'s summary in the store."""
        return link_key(self.hashes[i], "", self.cfg_text)

    def summarise(self, new: list[int]) -> None:
        """The summary of each new scan: kept from an earlier run, or prepared now."""
        todo = []
        for i in new:
            kept = self.store.load_scan(self.scan_key(i)) if self.resume else None
            if kept is None:
                todo.append(i)
            else:
                self.summaries[i] = ScanSummary(*kept)
        if todo:
            progress.info("preparing %d scan(s)", len(todo))
            self.run(todo, [])

    def register(
        self, planned: Sequence[PlannedLink], both_ways: bool = False, classic: bool = False
    ) -> None:
        """Register the planned links not registered yet. With ``both_ways`` (never in the
        ``classic`` chain), a found link that comes out suspect or degenerate is registered
        the other way round too, and the better of the two kept (the registration is not
        symmetric: a link at the margin of the quality gate may pass one way), so that which
        scan is the target never decides a link of the network; with its guess turned round."""
        fresh = [k for k in planned if k.pair not in self.links]
        self.register_jobs([self._job(k) for k in fresh])
        if classic or not both_ways:
            return
        again = [k for k in planned if k.kind is LinkKind.FOUND and self.may_turn(k.pair)]
        self.turned |= {k.pair for k in again}
        self.register_jobs(
            [
                self._job(PlannedLink(k.source, k.target, k.kind, turned_round(k.guess), k.deep))
                for k in again
            ]
        )

    def may_turn(self, pair: Pair) -> bool:
        """Whether the pair's link is marginal (suspect or degenerate) and was registered one
        way round only: the other way round may pass the gate."""
        link = self.links.get(pair)
        marginal = link is not None and link.status in (Status.SUSPECT, Status.DEGENERATE)
        return marginal and pair not in self.turned

    def register_anew(self, planned: Sequence[PlannedLink]) -> None:
        """Register planned links even when their pair was registered already: with what they
        add (a guess), the better of the two registrations kept."""
        self.register_jobs([self._job(k) for k in planned])

    def register_jobs(self, jobs: list[LinkJob]) -> None:
        """Run the jobs not finished yet (taken from the store where it has them)."""
        jobs = [j for j in jobs if not self._done(j)]
        if self.resume:
            for job in jobs:
                link = self._stored(job)
                if link is not None:
                    self._finish(job, job.adopt(link), save=False)
                    self.reused.add(link.key)
        todo = [j for j in jobs if not self._done(j)]
        for job in todo:
            bad = self.unreadable.get(job.target) or self.unreadable.get(job.source)
            if bad:
                self._finish(job, job.failed(bad), save=False)
        todo = [j for j in todo if not self._done(j)]
        if not todo:
            return
        # the pairs ride on the record, for a display that names the links at work
        pairs = tuple((j.target, j.source) for j in todo)
        progress.info("registering %d link(s)", len(todo), extra={"links": pairs})
        ships = self.executor.ships_data
        need = {s for j in todo for s in (j.target, j.source)}
        self.run(sorted(s for s in need if ships and s not in self.prepared), todo)

    def _done(self, job: LinkJob) -> bool:
        """The job's link is registered: in full, or (a probe) as a probe."""
        return job.key in self.finished or (not job.deep and skipped_key(job.key) in self.finished)

    def _stored(self, job: LinkJob) -> Link | None:
        """The job's link from the store: in full, or (a probe) as a probe, or in full where its
        search did not look deeper (what the probe gives)."""
        if job.deep:
            return self.store.load(job.key)
        link = self.store.load(skipped_key(job.key)) or self.store.load(job.key)
        if link is not None and link.result is not None and link.result.deeper is Deeper.DONE:
            return None
        return link

    def run(self, prepare: list[int], jobs: list[LinkJob]) -> None:
        """Prepare scans and register links on the executor, each link as soon as its two
        scans are ready; a link that finishes is kept at once."""
        ships = self.executor.ships_data
        waiting = {job.pair: job for job in jobs}
        tasks: dict = {
            ("scan", i): partial(_summarise, self.paths[i], self.cfg, ships) for i in prepare
        }

        def ready(i: int) -> bool:
            return i in self.prepared if ships else i in self.summaries

        def start(*_: object) -> dict:
            go = [p for p, j in waiting.items() if ready(j.target) and ready(j.source)]
            return {("link", *p): self._task(waiting.pop(p)) for p in go}

        tasks.update(start())
        for key, value in self.executor.run(tasks, start):
            if key[0] == "scan":
                self._summarised(key[1], value)
                self._trim({s for j in waiting.values() for s in (j.target, j.source)})
            else:
                job = next(j for j in jobs if j.pair == key[1:])
                if isinstance(value, Failure):  # the worker died or raised: this link fails
                    self._finish(job, job.failed(value), save=False)
                else:
                    self._finish(job, value)
        for job in waiting.values():  # a scan it needs could not be read
            bad = self.unreadable.get(job.target) or self.unreadable.get(job.source) or "?"
            self._finish(job, job.failed(bad), save=False)
        self._trim(set())

    def _trim(self, keep: set[int]) -> None:
        """Forget the least recently used prepared scans, but those in ``keep`` (links waiting
        for them), until those kept hold :data:`PREPARED_BYTES` or less."""
        total = sum(self._sizes.values())
        for i in [i for i in self.prepared if i not in keep]:
            if total <= PREPARED_BYTES:
                return
            del self.prepared[i]
            total -= self._sizes.pop(i)

    def _job(self, k: PlannedLink) -> LinkJob:
        inputs = self.cfg_text + guess_text(k.guess)
        key = link_key(self.hashes[k.target], self.hashes[k.source], inputs)
        return LinkJob(0, k.target, k.source, key, k.kind, k.guess, k.deep)

    def _task(self, job: LinkJob) -> Callable[[], Link]:
        i, j = job.target, job.source
        if self.executor.ships_data:
            self.prepared.move_to_end(i)
            self.prepared.move_to_end(j)
            return partial(register_link, job, self.prepared[i], self.prepared[j], self.cfg)
        return partial(register_paths, job, self.paths[i], self.paths[j], self.cfg)

    def _summarised(self, i: int, value: ScanSummary | Failure) -> None:
        if isinstance(value, Failure):
            self.unreadable[i] = value
            return
        if value.prepared is not None:
            self.prepared[i] = value.prepared
            self._sizes[i] = array_bytes(value.prepared)
        if i not in self.summaries:
            self.summaries[i] = replace(value, prepared=None)
            self.store.save_scan(self.scan_key(i), value.preview, value.sketch, value.sample)

    def _finish(self, job: LinkJob, link: Link, save: bool = True) -> None:
        """Keep a finished link (the better of two ways round, see :meth:`register`)."""
        self.finished.add(link.key)
        self.tried.append(link)
        kept = self.links.get(job.pair)
        if kept is None or _rank(link) < _rank(kept):
            self.links[job.pair] = link
        if save:
            names = scan_names(self.paths)
            self.store.save(link, (names[link.target], names[link.source]))
        if self.on_link:
            self.on_link(link)


def _rank(link: Link) -> tuple[int, float]:
    """Which of two registrations of a pair is better: ok, then usable, then by score."""
    rank = 0 if link.ok else 1 if usable(link) else 2
    score = link.result.score_per_point if link.result is not None else 0.0
    return rank, -score
