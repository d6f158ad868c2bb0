"""A campaign of scans that grows a scan (or many) at a time: it owns the scans, the links and
the network, and :meth:`Campaign.add_scans` updates them in named steps:

1. **Admit**: each new scan is known by its content (file hash) and gets the next index in
   campaign order (the order scans came in: a walk, when there is one).
2. **Summarise**: each new scan is read and prepared once (its sketch and preview are kept in
   the link store, so a campaign that resumes does not read it again).
3. **Discover** (:mod:`ndt_cli.pipeline.discovery`): where each new scan is, from coarse
   global matches with the placed scans; it is registered fully to the nearest of them, and
   to the scans near it by known positions (control stations, however coarse), when given.
4. **Consolidate**: place every scan again by all its links (:func:`replace_all`), plan the
   network from where the scans are (:func:`~ndt_cli.pipeline.network.plan_near`) and
   register what is missing, until the plan holds.
5. **Solve** (:mod:`ndt_cli.pipeline.solution`): a pose and a status per scan.

Links are keyed by their inputs (:mod:`ndt_cli.pipeline.links`): a link is registered once,
whatever the order of the scans and however many scans joined since. The network depends on
where the scans are, not on their order: a campaign given in any order, or scan by scan, ends
with the same links and so the same poses. With one neighbour the campaign is the classic
chain in the order given.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from numpy.linalg import inv

from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.errors import UserInterruptError, caused_by_interrupt
from ndt_cli.ndt.overlap import COARSE_WINDOW, CoarseMatch, coarse_match
from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.control import Station, matched
from ndt_cli.pipeline.discovery import (
    HINTS,
    Placed,
    Prediction,
    agree,
    consensus,
    near_by_position,
    nearest,
    order_is_a_hint,
    predict,
)
from ndt_cli.pipeline.executors import Executor
from ndt_cli.pipeline.links import Link, LinkStore, link_key
from ndt_cli.pipeline.network import (
    LinkKind,
    Pair,
    PlannedLink,
    classic_chain,
    default_radius,
    pair_of,
    plan_near,
)
from ndt_cli.pipeline.result import ChainResult, ScanReport, scan_report
from ndt_cli.pipeline.scans import file_hash, scan_names
from ndt_cli.pipeline.solution import NetworkSolution, solve, usable
from ndt_cli.pipeline.tasks import LinkJob, ScanSummary, register_link, register_paths
from ndt_cli.pipeline.tasks import summarise_scan as _summarise
from ndt_cli.pipeline.workers import Failure

log = logging.getLogger(__name__)
progress = logging.getLogger("ndt_cli.progress")

ROUNDS = 3  # consolidation rounds: place, plan, register
BRIDGES = 2  # registrations tried between a group and the others, best coarse matches first
PROBES = 2  # placed scans nearest to a prediction that a scan is registered to, to test it
ATTEMPTS = 2  # distinct predictions of a scan's place tried by full registrations
BRIDGE_ROUNDS = 3  # rounds in a row without a join before the groups are left apart
BRIDGE_MEMBERS = 8  # scans of a group whose coarse matches with other groups are ranked
CACHED_SCANS = 48  # prepared scans the campaign keeps between steps (others are read again)


@dataclass(frozen=True)
class NetworkOptions:
    """Which links the network holds and how it is solved: each scan's ``neighbours`` nearest
    scans within ``radius`` m (None: 2.2 times the median distance between nearest scans; one
    neighbour: the classic chain in the order given), whether it is ``adjust``-ed, and the
    user's ``pairs`` (campaign indices)."""

    neighbours: int = 4
    adjust: bool = True
    radius: float | None = None
    pairs: tuple[PlannedLink, ...] = ()
    stations: tuple[Station, ...] = ()  # of known coordinates (the world: theirs); a station
    # counts once its scan is in the campaign (field mode: the control file is read first)
    crs: str = ""  # the coordinate system of the stations, as WKT ("" when not given)
    grid_scale: float = 1.0  # its grid distance over ground distance at the stations

    @property
    def classic(self) -> bool:
        return self.neighbours == 1


class Campaign:
    """Scans, links and network of a campaign (see the module docstring).

    ``out``: the output folder whose ``links/`` keeps every finished link; ``resume``: links
    and scan summaries found there are reused. ``executor``: where tasks run (closed by
    :meth:`close`). ``on_link`` is called with each finished link; ``on_interrupt`` says how
    to continue after Ctrl-C.
    """

    def __init__(
        self,
        cfg: Config,
        out: str | Path,
        executor: Executor,
        *,
        network: NetworkOptions | None = None,
        resume: bool = False,
        anchor: int = 0,
        on_link: Callable[[Link], None] | None = None,
        on_interrupt: str = "run again with --resume",
    ) -> None:
        self.cfg, self.executor, self.anchor = cfg, executor, anchor
        self.on_interrupt = on_interrupt
        self.net = network or NetworkOptions()
        self.store, self.resume, self.on_link = LinkStore(Path(out)), resume, on_link
        self.store.clean_stale()
        self.cfg_text = dump(cfg)
        self.paths: list[Path] = []
        self.hashes: list[str] = []
        self.summaries: dict[int, ScanSummary] = {}
        self.prepared: OrderedDict[int, PreparedScan] = OrderedDict()
        self.unreadable: dict[int, str] = {}
        self.links: dict[Pair, Link] = {}
        self.finished: set[str] = set()  # keys of the links registered (or taken) so far
        self.reused: set[str] = set()  # keys of the links taken from the store
        self.coarse: dict[Pair, CoarseMatch] = {}
        self.plan: set[Pair] = set()
        self.where: dict[int, Placed] = {}  # where each placed scan is, roughly
        self.radius = float("nan")

    # ------------------------------------------------------------------ the entry points

    def add_scan(self, path: str | Path) -> ScanReport:
        """Add one scan, update the network, and say what became of the scan."""
        self.add_scans([path])
        return self.report(len(self.paths) - 1, self.result())

    def add_scans(self, paths: Sequence[str | Path]) -> None:
        """Add scans (in campaign order) and update the network: admit, summarise, discover,
        consolidate (the solve is :meth:`result`)."""
        with self._stopping():
            new = self._admit(paths)
            self._summarise(new)
            self._discover(new)
            self._bridge(new)
            self._consolidate()

    def result(self) -> ChainResult:
        """Solve the planned network: a pose and a status per scan."""
        links = self._network()
        names = tuple(scan_names(self.paths))
        if self.net.adjust and links:
            progress.info("adjusting the network of %d link(s)", len(links))
        solution = solve(
            len(self.paths),
            self.anchor,
            links,
            self.net.adjust,
            self.unreadable,
            matched(self.net.stations, names),
            self.net.grid_scale,
        )
        _log_controls(solution)
        return ChainResult(
            scans=tuple(self.paths),
            names=names,
            links=tuple(links),
            solution=solution,
            anchor=self.anchor,
            unreadable=dict(sorted(self.unreadable.items())),
            previews={i: s.preview for i, s in sorted(self.summaries.items())},
            reused=tuple(k for k, link in enumerate(links) if link.key in self.reused),
            radius=self.radius,
            **self._world_system(solution),
        )

    def _world_system(self, solution: NetworkSolution) -> dict[str, Any]:
        """The control's stations and coordinate system, and the grid scale when applied."""
        applied = solution.datum is not None and solution.datum.frame.from_control
        scale = self.net.grid_scale if applied else 1.0
        return {"stations": self.net.stations, "crs": self.net.crs, "grid_scale": scale}

    def report(self, index: int, result: ChainResult) -> ScanReport:
        """What the network made of scan ``index`` in ``result``."""
        return scan_report(index, result)

    def close(self) -> None:
        self.executor.close()

    # ------------------------------------------------------------------ the steps

    def _admit(self, paths: Sequence[str | Path]) -> list[int]:
        first = len(self.paths)
        for p in paths:
            self.paths.append(Path(p))
            self.hashes.append(_identity(Path(p)))
        return list(range(first, len(self.paths)))

    def _summarise(self, new: list[int]) -> None:
        """The summary of each new scan: kept from an earlier run, or prepared now."""
        todo = []
        for i in new:
            kept = self.store.load_scan(self._scan_key(i)) if self.resume else None
            if kept is None:
                todo.append(i)
            else:
                self.summaries[i] = ScanSummary(*kept)
        if todo:
            progress.info("preparing %d scan(s)", len(todo))
            self._run(todo, [])

    def _discover(self, new: list[int]) -> None:
        """Place each new scan in turn (not in the classic chain): in campaign order while the
        order is a hint (:func:`order_is_a_hint`), then the rest by their coarse matches with
        the placed scans, the best matched first (:meth:`_place_by_matches`)."""
        if self.net.classic:
            return
        todo = [s for s in new if s in self.summaries]
        hinted: list[bool] = []  # per scan placed so far: did its order hint place it?
        while todo:
            if not order_is_a_hint(hinted):
                progress.info("the campaign order is no hint: placing by coarse matches")
                self._place_by_matches(self._unplace_lonely(new) + todo)
                return
            outcome = self._place(todo.pop(0))
            if outcome is not None:
                hinted.append(outcome)

    def _unplace_lonely(self, new: list[int]) -> list[int]:
        """The new scans placed alone (a group of one, not the largest), taken out of place
        to be placed again beside the others (their links are kept)."""
        lonely = [g[0] for g in self._groups()[1:] if len(g) == 1 and g[0] in new]
        for scan in lonely:
            del self.where[scan]
        return lonely

    def _place_by_matches(self, todo: list[int]) -> None:
        """Place ``todo`` one at a time, each time the scan whose best coarse match with a
        placed scan scores highest (ties: campaign order), without order hints: so that each
        scan is placed beside scans already placed, instead of alone and bridged later."""
        best = {s: max((self._match(p, s).score for p in self.where), default=0.0) for s in todo}
        while best:
            scan = max(best, key=lambda s: (best[s], -s))
            del best[scan]
            self._place(scan, hints=False)  # placed now, in a group or alone
            for s in best:
                best[s] = max(best[s], self._match(scan, s).score)

    def _place(self, scan: int, hints: bool = True) -> bool | None:
        """Place the scan: first by its neighbours in campaign order (the scan before it, the
        best coarse match among them and those that agree with it are registered); without an
        ok link, by every placed scan: the best coarse prediction, registered to the
        :data:`PROBES` placed scans nearest to it, then the next distinct one, up to
        :data:`ATTEMPTS`. Scans near it by known positions (control stations) are registered
        in the first step too. Nothing fits: a group of its own, for now. Returns whether the
        order hint placed it (None: no hint, ``hints`` False or no neighbour placed)."""
        where = self.where
        around = [scan + d for d in HINTS] if hints else []
        hinted = consensus(predict(scan, around, where, self._match))
        missed = False if hinted else None  # what to return unless the hint places it
        known = self._near(scan, where)
        if hinted or known:
            walk = [scan - 1] if hinted and scan - 1 in where else []  # the scan before it
            targets = dict.fromkeys([*walk, *(g.via for g in hinted), *known])
            self._register([self._planned(pair_of(scan, t)) for t in targets])
            if self._settle(scan):
                return True if hinted else None
        tried: list[Prediction] = hinted[:1]
        guesses = predict(scan, sorted(where), where, self._match)
        for guess in sorted(guesses, key=lambda g: (-g.score, g.via)):
            if len(tried) > ATTEMPTS:
                break
            if any(
                g.group == guess.group and agree(g.T_group_scan, guess.T_group_scan) for g in tried
            ):
                continue
            tried.append(guess)
            xy = guess.T_group_scan[:2, 3]
            near = nearest(where, guess.group, xy, PROBES, self._placing_radius())
            targets = dict.fromkeys([guess.via, *near])
            self._register([self._planned(pair_of(scan, t)) for t in targets])
            if self._settle(scan):
                return missed
        where[scan] = Placed(scan, np.eye(4))
        return missed

    def _settle(self, scan: int) -> bool:
        """Place the scan by its ok links to placed scans (:func:`_fit`); the groups its other
        ok links reach join that one. False when it has no ok link to a placed scan."""
        mine = [(o, k) for o in self.where if (k := self.links.get(pair_of(scan, o)))]
        fit = _fit(scan, [(o, k) for o, k in mine if k.ok], self.where)
        if fit is None:
            return False
        _, other, T = fit
        group = self.where[other].group
        self.where[scan] = Placed(group, T)
        for o, link in mine:
            if link.ok and self.where[o].group != group:
                self._merge(
                    self.where[o].group, group, T @ inv(self.where[o].T_group_scan @ _T(link, o))
                )
        return True

    def _bridge(self, new: list[int]) -> None:
        """Join the groups of placed scans where they overlap: for each group but the
        largest, its :data:`BRIDGES` best coarse matches (pairs with a new scan, not tried
        yet) with scans of other groups are registered, pairs near by known positions first;
        an ok one joins the two groups. The pairs ranked: the group's edge
        (:meth:`_edge`), its neighbours in campaign order and by known positions. A round
        without a join is followed by up to :data:`BRIDGE_ROUNDS` - 1 more for the groups of
        several scans (a piece of the campaign, placed out of order, whose best coarse matches
        missed), not for a lone scan (a scan that fits nowhere stays alone)."""
        fresh = set(new)
        failed = 0
        while failed < BRIDGE_ROUNDS:
            groups = self._groups()
            pairs: list[Pair] = []
            for group in groups[1:]:
                if failed and len(group) == 1:
                    continue
                mine = set(group)
                near = {pair_of(a, b) for a in group for b in self._near(a, self.where)}
                hinted = {pair_of(a, a + d) for a in group for d in HINTS if a + d in self.where}
                edge = {pair_of(a, b) for a in self._edge(group) for b in self.where}
                cross = [
                    p
                    for p in sorted(edge | near | hinted)
                    if not set(p) <= mine
                    and (p[0] in fresh or p[1] in fresh)
                    and p not in self.links
                ]
                cross.sort(key=lambda p: (p not in near, -self._match(*p).score, p))
                pairs += [p for p in cross[:BRIDGES] if p not in pairs]
            if not pairs:
                return
            self._register([self._planned(p) for p in pairs], both_ways=True)
            joined = [self._join(p) for p in pairs]
            failed = 0 if any(joined) else failed + 1

    def _edge(self, group: list[int]) -> list[int]:
        """The :data:`BRIDGE_MEMBERS` scans of a group most likely at its edge, where another
        group may continue it: those with the fewest ok links within it (the ends of a
        street), ties by campaign order; so that bridging costs coarse matches in proportion
        to the campaign, not to the product of two groups' sizes."""
        if len(group) <= BRIDGE_MEMBERS:
            return group
        mine = set(group)
        degree = dict.fromkeys(group, 0)
        for (a, b), link in self.links.items():
            if link.ok and a in mine and b in mine:
                degree[a] += 1
                degree[b] += 1
        return sorted(group, key=lambda s: (degree[s], s))[:BRIDGE_MEMBERS]

    def _positions(self) -> dict[int, tuple[np.ndarray, float]]:
        """(x, y) m and horizontal sigma of the scans with a control station."""
        found = matched(self.net.stations, scan_names(self.paths))
        return {c.scan: (c.xyz[:2], c.sigma_xy) for c in found}

    def _near(self, scan: int, candidates: Iterable[int]) -> list[int]:
        """Candidates near ``scan`` by known positions (:func:`near_by_position`)."""
        radius = self._placing_radius()
        return near_by_position(scan, self._positions(), candidates, radius, PROBES)

    def _groups(self) -> list[list[int]]:
        """The placed scans by group, the largest first (ties: the lowest scan)."""
        groups: dict[int, list[int]] = {}
        for s, p in sorted(self.where.items()):
            groups.setdefault(p.group, []).append(s)
        return sorted(groups.values(), key=lambda g: (-len(g), g[0]))

    def _join(self, pair: Pair) -> bool:
        """Join the groups of a link's scans (the smaller into the larger) when it fits: an
        ok link, or one that another link between the two groups agrees with."""
        link = self.links.get(pair)
        a, b = pair
        if link is None or not usable(link):
            return False
        if self.where[a].group == self.where[b].group:
            return False
        big, small = (a, b) if self._size(a) >= self._size(b) else (b, a)
        g_big, g_small = self.where[big].group, self.where[small].group
        implied = []  # where each link between the two groups puts the small group's frame
        for p, k in self.links.items():
            ends = {self.where[e].group if e in self.where else None for e in p}
            if ends == {g_big, g_small} and usable(k):
                x, y = p if self.where[p[0]].group == g_big else p[::-1]
                T = self.where[x].T_group_scan @ _T(k, x) @ inv(self.where[y].T_group_scan)
                implied.append((k, x, T))
        fit = _best_fit(implied, lambda o: g_big)
        if fit is None:
            return False
        self._merge(g_small, g_big, fit[1])
        return True

    def _size(self, scan: int) -> int:
        return sum(p.group == self.where[scan].group for p in self.where.values())

    def _merge(self, old: int, new: int, T_new_old: np.ndarray) -> None:
        for s, p in list(self.where.items()):
            if p.group == old:
                self.where[s] = Placed(new, T_new_old @ p.T_group_scan)

    def _placing_radius(self) -> float:
        """The radius while placing: the option, or the default of the scans placed so far
        (the coarse match's window while there are too few)."""
        if self.net.radius is not None:
            return self.net.radius
        groups: dict[int, dict[int, np.ndarray]] = {}
        for s, p in self.where.items():
            groups.setdefault(p.group, {})[s] = p.T_group_scan[:2, 3]
        radius = default_radius(list(groups.values()))
        return radius if np.isfinite(radius) else COARSE_WINDOW

    def _consolidate(self) -> None:
        """Place every scan again by all the links there are, plan from where the scans are
        and register what is missing, until the plan holds."""
        if self.net.classic:
            bad = self.unreadable
            chain = [k for k in classic_chain(len(self.paths), bad) if k.pair not in self.links]
            self._register([*chain, *self._user_todo()])
            return
        self._register(self._user_todo())
        for _ in range(ROUNDS):
            self.where = replace_all(sorted(self.where), self.links)
            plan = self._replan(self._placed_groups())
            todo = [p for p in sorted(plan) if p not in self.links]
            self._register([self._planned(p) for p in sorted(plan)], both_ways=True)
            if not todo:
                return

    def _placed_groups(self) -> list[dict[int, np.ndarray]]:
        """Where the scans were placed, (x, y) m per scan, one dict per group."""
        groups: dict[int, dict[int, np.ndarray]] = {}
        for s, p in sorted(self.where.items()):
            groups.setdefault(p.group, {})[s] = p.T_group_scan[:2, 3]
        return [g for g in groups.values() if len(g) > 1]

    def _replan(self, where: list[dict[int, np.ndarray]]) -> set[Pair]:
        """The network's pairs from the positions of the groups of scans."""
        radius = self.net.radius if self.net.radius is not None else default_radius(where)
        self.radius = float(radius)
        failed = {p for p, k in self.links.items() if not k.ok}
        r = radius if np.isfinite(radius) else 0.0
        self.plan = plan_near(where, self.net.neighbours, r, failed) | {
            k.pair for k in self.net.pairs
        }
        return self.plan

    # ------------------------------------------------------------------ helpers

    def _network(self) -> list[Link]:
        """The links of the result: the plan, the user's pairs, and the links tried for scans
        that no ok link connects (so that the outputs say why); indexed 0, 1, ..."""
        user = {k.pair for k in self.net.pairs}
        if self.net.classic:
            chain = {k.pair for k in classic_chain(len(self.paths), self.unreadable)}
            pairs = chain | user
        else:
            lonely = {p for p in self.links if not any(self._has_ok_link(i) for i in p)}
            pairs = self.plan | user | lonely
        chosen = sorted(p for p in pairs if p in self.links)
        return [
            replace(self.links[p], index=n, kind=self._kind(p, user)) for n, p in enumerate(chosen)
        ]

    def _kind(self, pair: Pair, user: set[Pair]) -> LinkKind:
        if pair in user:
            return LinkKind.USER
        return LinkKind.ADJACENT if pair[1] - pair[0] == 1 else LinkKind.FOUND

    def _user_todo(self) -> list[PlannedLink]:
        n = len(self.paths)
        return [k for k in self.net.pairs if k.pair not in self.links and max(k.pair) < n]

    def _planned(self, pair: Pair) -> PlannedLink:
        """A found pair, its target the scan whose content sorts first (so that the link is
        the same whatever the order of the scans)."""
        a, b = pair
        if (self.hashes[b], b) < (self.hashes[a], a):
            a, b = b, a
        return PlannedLink(a, b, LinkKind.FOUND)

    def _has_ok_link(self, i: int) -> bool:
        return any(k.ok for p, k in self.links.items() if i in p)

    def _match(self, a: int, b: int) -> CoarseMatch:
        """The coarse match of scan ``b`` on scan ``a`` (cached per pair)."""
        pair = pair_of(a, b)
        if pair not in self.coarse:
            lo, hi = pair
            self.coarse[pair] = coarse_match(self.summaries[lo].sketch, self.summaries[hi].sketch)
        m = self.coarse[pair]
        return m if a == pair[0] else replace(m, T_target_source=inv(m.T_target_source))

    def _scan_key(self, i: int) -> str:
        return link_key(self.hashes[i], "", self.cfg_text)

    def _job(self, k: PlannedLink) -> LinkJob:
        key = link_key(self.hashes[k.target], self.hashes[k.source], self.cfg_text)
        return LinkJob(0, k.target, k.source, key, k.kind)

    # ------------------------------------------------------------------ running tasks

    def _register(self, planned: Sequence[PlannedLink], both_ways: bool = False) -> None:
        """Register the planned links not registered yet. With ``both_ways``, a found link
        that comes out suspect or degenerate is registered the other way round too, and the
        better of the two kept (the registration is not symmetric: a link at the margin of
        the quality gate may pass one way), so that which scan is the target never decides a
        link of the network."""
        fresh = [k for k in planned if k.pair not in self.links]
        self._register_jobs([self._job(k) for k in fresh])
        if self.net.classic or not both_ways:
            return
        marginal = (Status.SUSPECT, Status.DEGENERATE)
        again = [k for k in planned if k.kind is LinkKind.FOUND and k.pair in self.links]
        again = [k for k in again if self.links[k.pair].status in marginal]
        self._register_jobs([self._job(PlannedLink(k.source, k.target, k.kind)) for k in again])

    def _register_jobs(self, jobs: list[LinkJob]) -> None:
        """Run the jobs not finished yet (taken from the store where it has them)."""
        jobs = [j for j in jobs if j.key not in self.finished]
        if self.resume:
            for job in jobs:
                link = self.store.load(job.key)
                if link is not None:
                    self._finish(job, job.adopt(link), save=False)
                    self.reused.add(job.key)
        todo = [j for j in jobs if j.key not in self.finished]
        for job in todo:
            bad = self.unreadable.get(job.target) or self.unreadable.get(job.source)
            if bad:
                self._finish(job, job.failed(bad), save=False)
        todo = [j for j in todo if j.key not in self.finished]
        if not todo:
            return
        progress.info("registering %d link(s)", len(todo))
        ships = self.executor.ships_data
        need = {s for j in todo for s in (j.target, j.source)}
        self._run(sorted(s for s in need if ships and s not in self.prepared), todo)

    def _run(self, prepare: list[int], jobs: list[LinkJob]) -> None:
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
            else:
                job = next(j for j in jobs if j.pair == key[1:])
                if isinstance(value, Failure):  # the worker died or raised: this link fails
                    self._finish(job, job.failed(value), save=False)
                else:
                    self._finish(job, value)
        for job in waiting.values():  # a scan it needs could not be read
            bad = self.unreadable.get(job.target) or self.unreadable.get(job.source) or "?"
            self._finish(job, job.failed(bad), save=False)
        while len(self.prepared) > CACHED_SCANS:
            self.prepared.popitem(last=False)

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
        if i not in self.summaries:
            self.summaries[i] = replace(value, prepared=None)
            self.store.save_scan(self._scan_key(i), value.preview, value.sketch)

    def _finish(self, job: LinkJob, link: Link, save: bool = True) -> None:
        """Keep a finished link (the better of two ways round, see :meth:`_register`)."""
        self.finished.add(job.key)
        kept = self.links.get(job.pair)
        if kept is None or _rank(link) < _rank(kept):
            self.links[job.pair] = link
        if save:
            names = scan_names(self.paths)
            self.store.save(link, (names[link.target], names[link.source]))
        if self.on_link:
            self.on_link(link)

    @contextmanager
    def _stopping(self) -> Iterator[None]:
        """On Ctrl-C, what finished is kept: one line saying so."""
        try:
            yield
        except BaseException as exc:
            if not caused_by_interrupt(exc):
                raise
            raise UserInterruptError(
                f"interrupted: {len(self.links)} finished link(s) kept in {self.store.folder}; "
                f"{self.on_interrupt} to continue"
            ) from None


def _identity(path: Path) -> str:
    """What a scan is known by in link keys: the SHA-256 of its file; a file that cannot be
    read (whose links fail and are never kept) by its path."""
    return file_hash(path) or f"unreadable {path}"


def _T(link: Link, other: int) -> np.ndarray:
    """``T_other_scan`` of a link between ``other`` and a scan (4x4, scan frames)."""
    return link.T_target_source if link.target == other else inv(link.T_target_source)


def _best_fit(
    implied: list[tuple[Link, int, np.ndarray]], group_of: Callable[[int], int]
) -> tuple[int, np.ndarray] | None:
    """The pose that links put a scan at, ``(other, T)``: among the poses ``T`` that each
    link (with the placed scan ``other``) implies, the one the most links agree with, ok
    links first, then by score per point; it must have an ok link or two that agree (a scan
    shifted along a street may fit one scan well enough to pass, rarely several). None when
    no pose has that."""
    best, best_key = None, None
    for link, other, T in implied:
        mates = [k for k, o, U in implied if group_of(o) == group_of(other) and agree(U, T)]
        ok = sum(k.ok for k in mates)
        if not ok and len(mates) < 2:
            continue
        key = (-ok, -len(mates), -link.result.score_per_point, other)
        if best_key is None or key < best_key:
            best, best_key = (other, T), key
    return best


def _rank(link: Link) -> tuple[int, float]:
    """Which of two registrations of a pair is better: ok, then usable, then by score."""
    rank = 0 if link.ok else 1 if usable(link) else 2
    score = link.result.score_per_point if link.result is not None else 0.0
    return rank, -score


def _log_controls(solution: NetworkSolution) -> None:
    """A warning per control station the adjustment did not use, with its misfit."""
    for fit in () if solution.datum is None else solution.datum.controls:
        if not fit.used:
            r = fit.residual
            misfit = (
                ""
                if r is None
                else " (adjusted - given: {:+.1f} {:+.1f} {:+.1f} cm)".format(*(100 * r))
            )
            log.warning("control station %s not used: %s%s", fit.control.name, fit.reason, misfit)


def replace_all(scans: Sequence[int], links: dict[Pair, Link]) -> dict[int, Placed]:
    """Every scan placed again from scratch by the links: from the lowest scan, the unplaced
    scan whose links to placed scans agree best (:func:`_fit_key`) is placed next, until
    none fits; then a new group from the lowest scan left. The result depends on the links,
    not on the order the scans came in (a scan that one wrong link would put elsewhere is
    placed where two right ones agree)."""
    by_scan: dict[int, list[tuple[int, Link]]] = {s: [] for s in scans}
    for (a, b), link in links.items():
        if usable(link) and a in by_scan and b in by_scan:
            by_scan[a].append((b, link))
            by_scan[b].append((a, link))
    where: dict[int, Placed] = {}
    left = set(scans)
    while left:
        seed = min(left)
        where[seed] = Placed(seed, np.eye(4))
        left.discard(seed)
        while True:
            fits = [(f, u) for u in sorted(left) if (f := _fit(u, by_scan[u], where, ok=True))]
            fits = fits or [(f, u) for u in sorted(left) if (f := _fit(u, by_scan[u], where))]
            if not fits:
                break
            (_, other, T), u = min(fits, key=lambda f: (f[0][0], f[1]))
            where[u] = Placed(where[other].group, T)
            left.discard(u)
    return where


def _fit(
    scan: int, mine: list[tuple[int, Link]], where: dict[int, Placed], ok: bool = False
) -> tuple[tuple, int, np.ndarray] | None:
    """The best pose the scan's links to placed scans imply (``ok``: its ok links only):
    (its key, the other scan, T)."""
    implied = [
        (k, o, where[o].T_group_scan @ _T(k, o)) for o, k in mine if o in where and k.ok >= ok
    ]
    best = None
    for link, other, T in implied:
        key = _fit_key(link, other, T, implied, where)
        if key is not None and (best is None or key < best[0]):
            best = (key, other, T)
    return best


def _fit_key(
    link: Link, other: int, T: np.ndarray, implied: list, where: dict[int, Placed]
) -> tuple | None:
    """How well links agree on pose ``T``: the most agreeing ok links, then links, then the
    score per point; None unless an ok link or two links agree on it."""
    g = where[other].group
    mates = [k for k, o, U in implied if where[o].group == g and agree(U, T)]
    ok = sum(k.ok for k in mates)
    if not ok and len(mates) < 2:
        return None
    return (-ok, -len(mates), -link.result.score_per_point, other)
