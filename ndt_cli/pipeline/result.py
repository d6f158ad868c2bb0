"""What a campaign ends with: its links and what the network made of them, as the outputs,
the report and ``ndt-watch`` read it (the campaign engine, :mod:`ndt_cli.pipeline.campaign`,
builds it)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum
from pathlib import Path

import numpy as np

from ndt_cli.pipeline.control import Station
from ndt_cli.pipeline.datum import not_georeferenced
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.network import LinkKind, Pair, kind_of, pair_of
from ndt_cli.pipeline.samples import SliceSample
from ndt_cli.pipeline.solution import NetworkSolution
from ndt_cli.pipeline.verify import EdgeState, NodeStatus


class Dropped(StrEnum):
    """Why a registration tried is not a link of the network: its gate did not pass and its
    pair is not in the network planned from where the scans are (it was tried while placing a
    scan), the same pair was registered the other way round too and that one was kept (it
    ranked better), or it was a probe whose search skipped its deeper round and the pair was
    registered again with it."""

    NOT_PLANNED = "not_planned"
    OTHER_WAY = "other_way_kept"
    SEARCHED_AGAIN = "searched_again"

    @property
    def reason(self) -> str:
        if self is Dropped.NOT_PLANNED:
            return (
                "tried while placing a scan, not ok, and not among the pairs the network was "
                "planned from"
            )
        if self is Dropped.SEARCHED_AGAIN:
            return (
                "tried while placing a scan without the search's deeper round; the pair, in "
                "the network, was registered again with it"
            )
        return "the same pair registered the other way round is the link kept (it ranked better)"


@dataclass(frozen=True)
class TriedLink:
    """A registration the campaign ran that is not a link of its network, and why."""

    link: Link
    why: Dropped


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
    radius: float = float("nan")  # m, the radius links were planned within
    crs: str = ""  # the control's coordinate system as WKT, when given (--crs)
    grid_scale: float = 1.0  # its grid distance over ground distance, applied at the scanners
    stations: tuple[Station, ...] = ()  # the control file's stations (none without control)
    hashes: tuple[str | None, ...] = ()  # SHA-256 of each scan's file when it was admitted
    # (what was registered; None: it could not be read); empty: not known
    tried: tuple[TriedLink, ...] = ()  # registrations run that are not links of the network
    samples: dict[int, SliceSample] | None = None  # two slices per scan, for the inspector

    @property
    def poses(self) -> tuple[np.ndarray | None, ...]:
        """``T_world_scan`` of every scan (None when unposed; suspect scans have one too)."""
        return self.solution.poses

    @property
    def not_georeferenced(self) -> str:
        """Why the world is not the control's coordinates although control was given ('' when
        it is, or without control)."""
        return not_georeferenced(self.solution.datum, self.stations, self.names)

    @property
    def ok(self) -> bool:
        """Every scan has a trustworthy pose in the anchor's frame (one cluster), and that
        frame is the control's when control was given."""
        return all(s.anchored for s in self.solution.scans) and not self.not_georeferenced


@dataclass(frozen=True)
class ScanReport:
    """What the campaign made of one scan: its status, where it is (world, m; None when
    unposed), the scans it is linked to by kept links, and why it is not ok."""

    index: int
    name: str
    status: NodeStatus
    position: np.ndarray | None
    linked: tuple[str, ...]
    reason: str


def scan_report(index: int, result: ChainResult) -> ScanReport:
    """What the network made of scan ``index`` in ``result``."""
    scan = result.solution.scans[index]
    kept = (EdgeState.CONFIRMED, EdgeState.USED)
    linked = sorted(
        {
            result.names[k.source if k.target == index else k.target]
            for k, fit in zip(result.links, result.solution.links, strict=True)
            if index in (k.target, k.source) and fit.state in kept
        }
    )
    T = scan.T_world_scan
    where = None if T is None else T[:3, 3].copy()
    return ScanReport(index, result.names[index], scan.status, where, tuple(linked), scan.reason)


def tried_links(
    tried: Sequence[Link], links: Sequence[Link], user: set[Pair], walk: Mapping[Pair, LinkKind]
) -> tuple[TriedLink, ...]:
    """The registrations run (``tried``) that are not ``links`` of the network, indexed after
    them, in the order of their scans: why each is left out; ``user``: the pairs given,
    ``walk``: neighbours along the walk and their kinds
    (:func:`~ndt_cli.pipeline.network.kind_of`)."""
    network = {k.key for k in links}
    ways = {pair_of(k.target, k.source): (k.target, k.source) for k in links}
    others = sorted(
        (k for k in tried if k.key not in network),
        key=lambda k: (*pair_of(k.target, k.source), k.target),
    )
    out = []
    for n, k in enumerate(others):
        pair = pair_of(k.target, k.source)
        why = _why(k, ways.get(pair))
        out.append(TriedLink(replace(k, index=len(links) + n, kind=kind_of(pair, user, walk)), why))
    return tuple(out)


def _why(link: Link, way: tuple[int, int] | None) -> Dropped:
    """Why ``link`` is not in the network, whose link of the same pair (if any) registered
    ``way`` (target, source)."""
    if way is None:
        return Dropped.NOT_PLANNED
    if way == (link.target, link.source) and link.skipped_deeper:
        return Dropped.SEARCHED_AGAIN
    return Dropped.OTHER_WAY
