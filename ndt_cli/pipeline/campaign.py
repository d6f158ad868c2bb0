"""A campaign of scans that grows a scan (or many) at a time: it owns the scans, the links and
the network, and :meth:`Campaign.add_scans` updates them in named steps:

1. **Admit**: each new scan is known by its content (file hash) and gets the next index in
   campaign order (the order scans came in); the walk is their time order when every scan
   says when it was taken, else that order (:mod:`ndt_cli.pipeline.walk`).
2. **Summarise**: each new scan is read and prepared once (its sketch and preview are kept in
   the link store, so a campaign that resumes does not read it again).
3. **Discover** (:mod:`ndt_cli.pipeline.discovery`): each new scan registered to its neighbours
   along the walk or to its best coarse matches (out of order), and to the scans near it by
   known positions (control stations, however coarse), when given.
4. **Consolidate**: place every scan again by all its links
   (:func:`~ndt_cli.pipeline.placement.replace_all`), plan the network from where the scans
   are (:func:`~ndt_cli.pipeline.network.plan_near`) and register what is missing, until the
   plan holds.
5. **Solve** (:mod:`ndt_cli.pipeline.solution`): a pose and a status per scan.

Links are keyed by their inputs (:mod:`ndt_cli.pipeline.links`): a link is registered once,
whatever the order of the scans and however many scans joined since. The network depends on
where the scans are, not on their order: a campaign given in any order, or scan by scan, ends
with the same links and so the same poses. With one neighbour the campaign is the classic
chain in the order given.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli import io
from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.errors import interrupt_as
from ndt_cli.ndt.overlap import CoarseMatch, coarse_match
from ndt_cli.pipeline import placement
from ndt_cli.pipeline.by_control import frame_of, home_group, station_links
from ndt_cli.pipeline.candidates import LandmarkIndex, next_tier, shortlists
from ndt_cli.pipeline.coarse import keyed, match_pairs, partners, seen_from
from ndt_cli.pipeline.control import matched
from ndt_cli.pipeline.datum import log_unused_controls
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
from ndt_cli.pipeline.guesses import relative
from ndt_cli.pipeline.link_runner import LinkRunner
from ndt_cli.pipeline.links import Link, LinkStore
from ndt_cli.pipeline.members import Members, network_links, walk_pairs
from ndt_cli.pipeline.network import (
    Bridges,
    LinkKind,
    Pair,
    PlannedLink,
    classic_chain,
    default_radius,
    pair_of,
    plan_near,
)
from ndt_cli.pipeline.options import NetworkOptions
from ndt_cli.pipeline.result import ChainResult, ScanReport, scan_report, tried_links
from ndt_cli.pipeline.scans import (
    UNREADABLE,
    DuplicateScanError,
    identity,
    readable_anchor,
    scan_names,
)
from ndt_cli.pipeline.solution import NetworkSolution, solve
from ndt_cli.pipeline.walk import Walk

progress = logging.getLogger("ndt_cli.progress")
Lists = dict[int, list[int]]  # per scan, scans

ROUNDS = 3  # consolidation rounds: place, plan, register
BRIDGES = 2  # registrations tried between a group and the others, best coarse matches first
PROBES = 2  # placed scans nearest to a prediction that a scan is registered to, to test it
ATTEMPTS = 2  # distinct predictions of a scan's place tried by full registrations
BRIDGE_ROUNDS = 3  # rounds without a join before a group of several scans is left apart


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
        self.store = LinkStore(Path(out))
        self.store.clean_stale()
        self.paths: list[Path] = []
        self.hashes: list[str] = []
        self.tasks = LinkRunner(
            cfg,
            dump(cfg),
            executor,
            self.store,
            self.paths,
            self.hashes,
            resume=resume,
            on_link=on_link,
        )
        # what the tasks gave (owned by the runner): summaries, unreadable scans, links
        self.summaries, self.unreadable = self.tasks.summaries, self.tasks.unreadable
        self.links = self.tasks.links
        self.finished = self.tasks.finished
        self.reused = self.tasks.reused
        self.coarse: dict[Pair, CoarseMatch] = {}
        self.index = LandmarkIndex()  # the scans' landmarks, for placing them out of order
        self.by_station: set[Pair] = set()  # pairs registered from a station's position once
        self.plan: set[Pair] = set()
        self.where: dict[int, Placed] = {}  # where each placed scan is, roughly
        self.walk = Walk(by_time=not self.net.classic)  # the order the scans were taken in
        self.walked = True  # the walk proved a hint (see :meth:`_discover`)
        self.radius = float("nan")

    # ------------------------------------------------------------------ the entry points

    def add_scan(self, path: str | Path) -> ScanReport:
        """Add one scan, update the network, and say what became of the scan."""
        self.add_scans([path])
        return self.report(len(self.paths) - 1, self.result())

    def add_scans(self, paths: Sequence[str | Path]) -> None:
        """Add scans (in campaign order): admit, summarise, discover, bridge, consolidate."""
        with self._stopping():
            new = self._admit(paths)
            self.tasks.summarise(new)
            self._discover(new)
            self._bridge(new)
            self._consolidate()
            if self._place_by_stations():
                self._consolidate()

    def result(self) -> ChainResult:
        """Solve the planned network: a pose and a status per scan."""
        members = self._network()
        links = members.links
        names = tuple(scan_names(self.paths))
        anchor = readable_anchor(self.anchor, self.unreadable, names)
        if self.net.adjust and links:
            progress.info("adjusting the network of %d link(s)", len(links))
        solution = solve(
            len(self.paths),
            anchor,
            links,
            self.net.adjust,
            self.unreadable,
            matched(self.net.stations, names),
            self.net.grid_scale,
            self.cfg.quality.max_ambiguity,
            self.bridges,
            members.checked_only,
        )
        log_unused_controls(solution.datum)
        return ChainResult(
            scans=tuple(self.paths),
            names=names,
            links=tuple(links),
            solution=solution,
            anchor=anchor,
            unreadable=dict(sorted(self.unreadable.items())),
            previews={i: s.preview for i, s in sorted(self.summaries.items())},
            reused=tuple(k for k, link in enumerate(links) if link.key in self.reused),
            radius=self.radius,
            hashes=tuple(None if h.startswith(UNREADABLE) else h for h in self.hashes),
            **self._world_system(solution),
            tried=tried_links(self.tasks.tried, links, self.net.given, members.walk),
            samples={i: s.sample for i, s in sorted(self.summaries.items()) if s.sample},
        )

    @property
    def bridges(self) -> Bridges:
        """Which links on no cycle may tie a scan in (:meth:`Bridges.of`)."""
        q = self.cfg.quality
        return Bridges.of(q.trust_bridges, q.trust_walk_bridges, self.walked)

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
        """Give each new scan the next index, known by its content; a scan whose content
        the campaign has already (a copy under another name) raises
        :class:`~ndt_cli.pipeline.scans.DuplicateScanError` and none is admitted."""
        files = [Path(p) for p in paths]
        ids = [identity(p) for p in files]
        known = dict(zip(self.hashes, self.paths, strict=True))
        for p, h in zip(files, ids, strict=True):
            if h in known:
                raise DuplicateScanError(known[h], p)
            known[h] = p
        first = len(self.paths)
        self.paths.extend(files)
        self.hashes.extend(ids)
        was = self.walk.reordered
        self.walk.add([io.acquired(p) for p in files])
        if self.walk.reordered and not was:
            progress.info("the scans' acquisition times give the walk")
        return list(range(first, len(self.paths)))

    def _discover(self, new: list[int]) -> None:
        """Place each new scan (not in the classic chain): along the walk while it is a hint
        (:func:`order_is_a_hint`); once it is not, every new scan together by its best
        coarse matches (:meth:`_place_by_matches`), and no bridge of the network is trusted: a
        pair proposed by a coarse match and passed by its gate alone may be a street beside
        itself shifted by a few blocks (a walk's order vouches for its neighbours)."""
        if self.net.classic:
            return
        todo = self.walk.sort(s for s in new if s in self.summaries)
        hinted: list[bool] = []  # per scan placed so far: did its order hint place it?
        while todo:
            if not order_is_a_hint(hinted):
                progress.info("the walk is no hint: placing by coarse matches")
                self.walked = False
                self._place_by_matches([s for s in new if s in self.summaries])
                return
            outcome = self._place(todo.pop(0))
            if outcome is not None:
                hinted.append(outcome)

    def _place_by_matches(self, todo: list[int]) -> None:
        """Place ``todo`` in one batch: each scan registered to the scans near it by known
        positions, or without any, to its best coarse matches among those its landmarks rank
        first; one left alone, among the next by rank (:func:`next_tier`). Not one at a time:
        a scan whose neighbours were not placed yet fits a street shifted along itself."""
        every = sorted(set(self.where) | set(todo))
        near = {scan: self._near(scan, [o for o in every if o != scan]) for scan in todo}
        self.index.update({k: self.summaries[k].sketch.keys for k in every})
        blind = [scan for scan in todo if not near[scan]]
        tried: dict[int, list[int]] = {}
        lists = next_tier(self.index, blind, every, tried)
        while True:
            self._register_to_matches(every, near, lists)
            near = {}
            tried = {s: [*tried.get(s, []), *others] for s, others in lists.items()}
            left = [s for s in lists if placement.alone(s, self.where)]
            lists = next_tier(self.index, left, every, tried)
            if not lists:
                return
            progress.info("%d scan(s) alone: matched with the next by rank", len(lists))

    def _register_to_matches(self, every: list[int], near: Lists, candidates: Lists) -> None:
        """Register each scan to those ``near`` it and to its best coarse matches among its
        ``candidates`` (:func:`partners`); then place ``every`` scan again by the links."""
        wanted = {pair_of(a, b) for a, bs in candidates.items() for b in bs} - self.coarse.keys()
        sketches = {k: self.summaries[k].sketch for k in every}
        self.coarse |= match_pairs(self.executor, sketches, map(self._ordered, wanted))
        pairs = {pair_of(scan, o) for scan, found in near.items() for o in found}
        for scan, others in candidates.items():
            pairs |= {pair_of(scan, o) for o in partners(self.coarse, scan, others)}
        self._register([self._planned(p, deep=False) for p in sorted(pairs)])
        self.where = placement.replace_all(every, self.links)

    def _place(self, scan: int) -> bool | None:
        """Place the scan: first by its neighbours along the walk (the scan before it, the
        best coarse match among them and those that agree with it are registered) and the
        scans near it by known positions (control stations); without an ok link, by every placed
        scan: the best coarse prediction, registered to the :data:`PROBES` placed scans nearest
        to it, then the next distinct one, up to :data:`ATTEMPTS`. Nothing fits: a group of its
        own, for now. Returns whether the order hint placed it (None: no hint, no neighbour
        placed, or nothing fits and ``scene.unplaced_doubt_walk`` is false)."""
        where = self.where
        around = self.walk.beside(scan, HINTS)
        hinted = consensus(predict(scan, around, where, self._match))
        missed = False if hinted else None  # what to return unless the hint places it
        known = self._near(scan, where)
        if hinted or known:
            before = [b for b in self.walk.beside(scan, (-1,)) if hinted and b in where]
            targets = dict.fromkeys([*before, *(g.via for g in hinted), *known])
            self._register([self._planned(pair_of(scan, t), deep=False) for t in targets])
            if placement.settle(scan, self.links, self.where):
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
            near = nearest(
                where,
                guess.group,
                xy,
                PROBES,
                placement.placing_radius(self.where, self.net.radius),
            )
            targets = dict.fromkeys([guess.via, *near])
            self._register([self._planned(pair_of(scan, t), deep=False) for t in targets])
            if placement.settle(scan, self.links, self.where):
                return missed
        where[scan] = Placed(scan, np.eye(4))
        return missed if self.cfg.scene.unplaced_doubt_walk else None

    def _bridge(self, new: list[int]) -> None:
        """Join the groups of placed scans where they overlap: for each group but the
        largest, its :data:`BRIDGES` best coarse matches (pairs with a new scan, not tried
        yet) with scans of other groups are registered, pairs near by known positions first;
        an ok one joins the two groups. Only where every bridge is trusted is a marginal one
        (or one tried while placing) registered the other way round too: elsewhere such a
        link ties no scan in alone (out of order, half the bridges' registrations), and
        indoors the extra registrations swayed the choice among rivals. The pairs ranked: the
        group's edge (:func:`~ndt_cli.pipeline.placement.edge`) with the scans of other groups
        (out of order, those its landmarks rank first: :func:`shortlists`), its walk and
        position neighbours. A group of several scans has :data:`BRIDGE_ROUNDS` rounds
        without a join, a lone scan one; a group that joins another is a new group (a join
        elsewhere changes none of a group's candidates)."""
        fresh, turn = set(new), self.bridges is Bridges.ALL
        failed: Counter[frozenset[int]] = Counter()  # rounds each group had without a join
        while True:
            pairs: list[Pair] = []
            for group in placement.groups(self.where)[1:]:
                mine = frozenset(group)
                if failed[mine] >= (1 if len(group) == 1 else BRIDGE_ROUNDS):
                    continue
                failed[mine] += 1  # a group that joins is another group: rounds of its own
                near = {pair_of(a, b) for a in group for b in self._near(a, self.where)}
                walk = {pair_of(a, b) for a in group for b in self.walk.beside(a, HINTS)}
                hinted = {p for p in walk if p[0] in self.where and p[1] in self.where}
                outside = [s for s in self.where if s not in mine]
                ends = shortlists(self.index, placement.edge(group, self.links), outside)
                edge = {pair_of(a, b) for a, bs in ends.items() for b in bs}
                cross = [
                    p
                    for p in sorted(edge | near | hinted)
                    if not set(p) <= mine
                    and (p[0] in fresh or p[1] in fresh)
                    and (p not in self.links or (turn and self.tasks.may_turn(p)))
                ]
                cross.sort(key=lambda p: (p not in near, -self._match(*p).score, p))
                pairs += [p for p in cross[:BRIDGES] if p not in pairs]
            if not pairs:
                return
            self._register([self._planned(p, deep=False) for p in pairs], both_ways=turn)
            for p in pairs:
                placement.join(p, self.links, self.where)

    def _place_by_stations(self) -> bool:
        """Scans with a station outside the group of most stations, registered from where
        their station puts them (:mod:`~ndt_cli.pipeline.by_control`), each pair once (a frame
        refitted as scans land gives another guess); whether one was placed."""
        found = {c.scan: c.xyz for c in matched(self.net.stations, scan_names(self.paths))}
        home = home_group(placement.groups(self.where), found, self.anchor)
        frame = frame_of({s: found[s] for s in home if s in found}, self.where)
        lone = [s for s in sorted(found) if s not in home and s not in self.unreadable]
        if frame is None or not lone:
            return False
        placed = False
        for s in lone:
            planned = station_links(s, found[s], frame, self.where, home, PROBES)
            new = [k for k in planned if k.pair not in self.by_station]
            self.by_station |= {k.pair for k in new}
            self.tasks.register_anew(new)
            placed |= bool(new) and placement.settle(s, self.links, self.where)
        return placed

    def _positions(self) -> dict[int, tuple[np.ndarray, float]]:
        """(x, y) m and horizontal sigma of the scans with a control station; without
        control, of those with an approximate pose (in a frame of its own)."""
        if self.net.stations:
            found = matched(self.net.stations, scan_names(self.paths))
            return {c.scan: (c.xyz[:2], c.sigma_xy) for c in found}
        n, sigma = len(self.paths), self.net.init_sigma[0]
        return {k: (T[:2, 3], sigma) for k, T in self.net.init_poses.items() if k < n}

    def _near(self, scan: int, candidates: Iterable[int]) -> list[int]:
        """Candidates near ``scan`` by known positions (:func:`near_by_position`)."""
        radius = placement.placing_radius(self.where, self.net.radius)
        return near_by_position(scan, self._positions(), candidates, radius, PROBES)

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
            self.where = placement.replace_all(sorted(self.where), self.links)
            plan = self._replan(placement.placed_groups(self.where))
            todo = [p for p in sorted(plan) if p not in self.links]
            self._register([self._planned(p) for p in sorted(plan)], both_ways=True)
            if not self._deepen(plan) and not todo:
                return

    def _deepen(self, pairs: Iterable[Pair]) -> bool:
        """Register again, letting the search look deeper, the pairs whose probe is not ok
        and was doubted by the free space (:class:`~ndt_cli.ndt.result.Deeper`): placement's
        probes leave that to the pairs of the plan. Whether one of them became ok."""
        links = self.links
        again = [p for p in sorted(pairs) if (k := links.get(p)) and k.skipped_deeper and not k.ok]
        self.tasks.register_anew([self._planned(p) for p in again])
        return any(self.links[p].ok for p in again)

    def _replan(self, where: list[dict[int, np.ndarray]]) -> set[Pair]:
        """The network's pairs from the positions of the groups of scans."""
        factor = self.cfg.scene.radius_factor
        radius = self.net.radius if self.net.radius is not None else default_radius(where, factor)
        self.radius = float(radius)
        failed = {p for p, k in self.links.items() if not k.ok}
        r = radius if np.isfinite(radius) else 0.0
        self.plan = plan_near(where, self.net.neighbours, r, failed) | self.net.given
        return self.plan

    # ------------------------------------------------------------------ helpers

    def _network(self) -> Members:
        """The links of the result (:func:`~ndt_cli.pipeline.members.network_links`)."""
        classic = (len(self.paths), self.unreadable) if self.net.classic else None
        q, walk = self.cfg.quality, walk_pairs(self.walk, self.links, len(self.paths))
        weak = 0.0 if q.weak_links_join else q.min_kept_evidence
        vouch = (q.min_kept_evidence, q.walk_vouch_free_space if self.walked else 0.0)
        return network_links(self.links, self.plan, self.net.given, walk, classic, weak, vouch)

    def _user_todo(self) -> list[PlannedLink]:
        n = len(self.paths)
        return [k for k in self.net.pairs if k.pair not in self.links and max(k.pair) < n]

    def _ordered(self, pair: Pair) -> tuple[int, int]:
        """(target, source): the target the scan whose content sorts first, so that what is
        computed of a pair is the same whatever the order of the scans."""
        a, b = pair
        return (b, a) if (self.hashes[b], b) < (self.hashes[a], a) else (a, b)

    def _planned(self, pair: Pair, deep: bool = True) -> PlannedLink:
        """A found pair, its target the scan whose content sorts first (:meth:`_ordered`);
        ``deep`` False for a probe."""
        a, b = self._ordered(pair)
        guess = relative(self.net.init_poses, a, b, self.net.init_sigma)
        return PlannedLink(a, b, LinkKind.FOUND, guess, deep)

    def _register(self, planned: Sequence[PlannedLink], both_ways: bool = False) -> None:
        """Register the planned links not registered yet (see :meth:`LinkRunner.register`)."""
        self.tasks.register(planned, both_ways, classic=self.net.classic)

    def _match(self, a: int, b: int) -> CoarseMatch:
        """The coarse match of scan ``b`` on scan ``a`` (computed once per pair, on the
        target :meth:`_ordered` gives)."""
        t, s = self._ordered(pair_of(a, b))
        if pair_of(t, s) not in self.coarse:
            m = coarse_match(self.summaries[t].sketch, self.summaries[s].sketch)
            self.coarse.update([keyed(m, t, s)])
        return seen_from(self.coarse, a, b)

    def _stopping(self) -> AbstractContextManager[None]:
        """On Ctrl-C, what finished is kept: one line saying so."""
        return interrupt_as(
            lambda: (
                f"interrupted: {len(self.links)} finished link(s) kept in "
                f"{self.store.folder}; {self.on_interrupt} to continue"
            )
        )
