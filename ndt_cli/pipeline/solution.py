"""From a campaign's links to a pose and a status per scan.

With the adjustment (the default), every link with a transform becomes an edge of the pose
graph, and the links that agree with each other are kept whatever their own gates said
(:mod:`ndt_cli.pipeline.verify`); each scan is ``ok`` when kept links tie it to its cluster
and pin its pose down, ``suspect`` when only unchecked links reach it or its pose is free
along some direction, ``unposed`` otherwise. Without it, poses are the products of ok links
along the fewest links from the anchor (one neighbour: the classic chain), and a scan reached
through anything but ok links is not ``ok``.

Frames: the world is the anchor scan's own frame; the scans of another cluster (no kept link
ties them to the anchor's) are in the frame of that cluster's root: its first scan that kept
links tie in. The graph works between the scans' reduced frames (each scan minus its
reduction point), so that georeferenced coordinates never enter it:
``T_world_scan = T(r_root) X_scan T(-r_scan)``.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.adjust import Solver
from ndt_cli.pipeline.control import Control
from ndt_cli.pipeline.covariance import ndt_covariance
from ndt_cli.pipeline.datum import Cluster, Datum, datum
from ndt_cli.pipeline.graph import Edge, EdgeResidual
from ndt_cli.pipeline.hypotheses import Choice, Hypothesis, choose
from ndt_cli.pipeline.link_use import firm, link_covariance, usable
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.network import Bridges, LinkKind
from ndt_cli.pipeline.verify import (
    WALKS_WORD,
    EdgeState,
    EdgeVerdict,
    NodeStatus,
    NodeVerdict,
    Verification,
    verify,
)


@dataclass(frozen=True)
class ScanPose:
    """A scan's status, ``T_world_scan`` (None when unposed), 1-sigma uncertainty (world axes:
    x, y, z in m and yaw in degrees; None without an adjustment) and the reason when not ok."""

    status: NodeStatus
    T_world_scan: np.ndarray | None
    sigma: np.ndarray | None = None  # (4,): x, y, z (m), yaw (deg)
    reason: str = ""
    cluster: int | None = None  # 0: the anchor's; the others in their root scan's frame

    @property
    def anchored(self) -> bool:
        """Ok in the anchor's frame (cluster 0): what poses.txt and the export give."""
        return self.status is NodeStatus.OK and self.cluster == 0


@dataclass(frozen=True)
class LinkFit:
    """What the network made of a link: its state and its residual after the adjustment."""

    state: EdgeState
    residual: EdgeResidual | None = None
    reason: str = ""


@dataclass(frozen=True)
class NetworkSolution:
    """Per scan a :class:`ScanPose`, per link (by position) a :class:`LinkFit`, the poses of
    the plain chain of adjacent ok links, and whether the network was adjusted."""

    scans: tuple[ScanPose, ...]
    links: tuple[LinkFit, ...]
    chained: tuple[np.ndarray | None, ...]
    adjusted: bool
    timings: dict[str, float] = field(default_factory=dict)
    datum: Datum | None = None  # the anchor's cluster's world (None: the anchor's own frame)
    roots: dict[int, int] = field(default_factory=dict)  # cluster -> the scan of its frame

    @property
    def poses(self) -> tuple[np.ndarray | None, ...]:
        return tuple(s.T_world_scan for s in self.scans)


def _translation(v: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = v
    return T


def reductions(n_scans: int, links: Sequence[Link]) -> list[np.ndarray | None]:
    """Each scan's reduction point (scan frame, m), from any link that registered it."""
    out: list[np.ndarray | None] = [None] * n_scans
    for link in links:
        if link.result is not None:
            out[link.target] = link.result.reduction_target
            out[link.source] = link.result.reduction_source
    return out


def chained(n_scans: int, links: Sequence[Link], anchor: int, kinds: set) -> list:
    """``T_world_scan`` per scan: products of the ok links of ``kinds`` along the fewest
    links from the anchor, in the scans' own frames (the classic chain)."""
    poses: list[np.ndarray | None] = [None] * n_scans
    poses[anchor] = np.eye(4)
    usable = sorted(
        (k for k in links if k.ok and k.kind in kinds), key=lambda k: (k.source - k.target, k.index)
    )
    changed = True
    while changed:
        changed = False
        for link in usable:
            i, j, T = link.target, link.source, link.T_target_source
            if poses[i] is not None and poses[j] is None:
                poses[j], changed = poses[i] @ T, True
            elif poses[j] is not None and poses[i] is None:
                poses[i], changed = poses[j] @ np.linalg.inv(T), True
    return poses


def solve(
    n_scans: int,
    anchor: int,
    links: Sequence[Link],
    adjust: bool,
    unreadable: dict[int, str],
    controls: Sequence[Control] = (),
    grid_scale: float = 1.0,
    ambiguity: float = 0.95,
    bridges: Bridges = Bridges.ALL,
    checked_only: Collection[int] = frozenset(),
) -> NetworkSolution:
    """The pose and status of every scan, and the state of every link; with the adjustment,
    the anchor's cluster in the world of :mod:`ndt_cli.pipeline.datum` (levelled, or the
    coordinate system of the ``controls``, whose grid distance over ground is ``grid_scale``).
    ``ambiguity``: the share of evidence that makes a second placement of two groups a rival
    of the first (``quality.max_ambiguity``; :mod:`ndt_cli.pipeline.hypotheses`);
    ``bridges``: which links on no cycle may tie a scan in (:class:`~ndt_cli.pipeline.network.
    Bridges`: ``quality.trust_bridges``, ``quality.trust_walk_bridges``);
    ``checked_only``: the ambiguous links (by index) that may only be chosen where firm links
    tie their scans together (:mod:`ndt_cli.pipeline.members`)."""
    plain = tuple(chained(n_scans, links, anchor, {LinkKind.ADJACENT, LinkKind.PAST}))
    if adjust:
        judging = (ambiguity, bridges, frozenset(checked_only))
        return _adjusted(n_scans, anchor, links, unreadable, plain, controls, grid_scale, judging)
    poses = chained(n_scans, links, anchor, set(LinkKind))
    scans = tuple(
        ScanPose(NodeStatus.OK, T, cluster=0)
        if T is not None
        else ScanPose(NodeStatus.UNPOSED, None, reason=_why_unposed(k, links, unreadable))
        for k, T in enumerate(poses)
    )
    fits = tuple(
        LinkFit(EdgeState.USED if k.ok else EdgeState.UNUSED, reason=k.reason) for k in links
    )
    return NetworkSolution(scans, fits, plain, adjusted=False, roots={0: anchor})


def _why_unposed(k: int, links: Sequence[Link], unreadable: dict[int, str]) -> str:
    if k in unreadable:
        return f"unreadable: {unreadable[k]}"
    mine = [x for x in links if k in (x.target, x.source)]
    if not mine:
        return "no link"
    return "no ok link connects it to the anchor: " + "; ".join(
        f"link {x.target}-{x.source} {x.status.value}" for x in mine
    )


def _adjusted(
    n_scans: int,
    anchor: int,
    links: Sequence[Link],
    unreadable: dict[int, str],
    plain: tuple[np.ndarray | None, ...],
    controls: Sequence[Control] = (),
    grid_scale: float = 1.0,
    judging: tuple[float, Bridges, frozenset[int]] = (0.95, Bridges.ALL, frozenset()),
) -> NetworkSolution:
    """Verify and adjust the network of usable links, set it in the world; map nodes and edges
    back. Links with rivals stay out of the consensus: the poses chosen among theirs join the
    firm links (:mod:`ndt_cli.pipeline.hypotheses`). ``judging``: the evidence share that
    makes a rival placement, whether bridges are trusted and the links only checked (see
    :func:`solve`)."""
    net = _network(n_scans, anchor, links, *judging)
    red = reductions(n_scans, links)
    nodes = _ambiguous_nodes(net.v, net.left, net.texts)
    scans = [_scan_pose(node, red, net.v.roots, unreadable, links) for node in nodes]
    world = _datum(net.v, net.edges, links, red, controls, grid_scale)
    if world is not None:
        scans = _in_world(scans, world, net.v, red, anchor)
    return NetworkSolution(
        tuple(scans),
        _fits(links, net),
        plain,
        adjusted=True,
        timings=dict(net.v.timings),
        datum=world,
        roots=dict(net.v.roots),
    )


@dataclass(frozen=True)
class _Network:
    """The verified network: its verification, edges and the links they come from (``used``,
    by position), the choice made for each link judged as hypotheses, and the links left
    unchosen with the text that says why (by link)."""

    v: Verification
    edges: list[Edge]
    used: list[int]
    choices: dict[int, Choice]
    left: dict[int, Hypothesis]
    texts: dict[int, str]


def _network(
    n_scans: int,
    anchor: int,
    links: Sequence[Link],
    ambiguity: float,
    bridges: Bridges,
    checked_only: frozenset[int],
) -> _Network:
    """Verify the firm links (usable, without rivals), choose among the poses of the links
    with rivals, of the firm links that only bridges would keep and of the weak ones (firm
    but only checked: they place no scan in a group), against them
    (:mod:`ndt_cli.pipeline.hypotheses`), and verify the firm and chosen links together. The
    walk's bridges (``bridges`` WALK) count in that last verification only (trust.md §6)."""
    usable_ids = [k for k, link in enumerate(links) if usable(link)]
    # a degenerate link says nothing of where its scans are horizontally: it decides nothing
    decided = [k for k in usable_ids if links[k].status is not Status.DEGENERATE]
    weak = {k for k in decided if k in checked_only and firm(links[k])}
    firm_ids = [k for k in usable_ids if firm(links[k]) and k not in weak]
    walk, trust_bridges = bridges is Bridges.WALK, bridges is Bridges.ALL
    edges = [_edge(links[k]) for k in firm_ids]
    v = verify(n_scans, anchor, edges, trust_bridges=trust_bridges)
    loose = {firm_ids[i] for i, e in enumerate(v.edges) if _unchecked(e)}
    hyps = {k: _hypotheses(links[k], k) for k in decided if links[k].result.rivals}
    single = (loose & set(decided)) | weak
    hyps.update({k: [Hypothesis(k, 0, _edge(links[k]), 1.0)] for k in single})
    groups, poses = [n.cluster for n in v.nodes], [n.pose for n in v.nodes]
    choices = choose(groups, poses, hyps, v.threshold, ambiguity, checked_only)
    chosen = sorted(k for k, c in choices.items() if c.chosen is not None)
    if chosen or walk:
        kept = firm_ids if walk else [k for k in firm_ids if k not in loose]
        used = kept + [k for k in chosen if k not in kept]
        firm_set = set(firm_ids)
        edges = [_edge(links[k], walk) if k in firm_set else choices[k].chosen.edge for k in used]
        v = verify(n_scans, anchor, edges, trust_bridges=trust_bridges)
    else:
        used = firm_ids
    left = {k: hyps[k][0] for k in choices if k not in chosen and not choices[k].rejected}
    texts = {k: _why_left(links[k]) for k in left}
    return _Network(v, edges, used, choices, left, texts)


def _unchecked(verdict: EdgeVerdict) -> bool:
    """A link its gate passed, left out all the same: a bridge, and no bridge is trusted (a
    gate-ok link is unused for no other reason)."""
    return verdict.trusted and verdict.state is EdgeState.UNUSED


def _why_left(link: Link) -> str:
    """Why a link left unchosen cannot tie a scan in: its rivals, or no cycle checks it."""
    rivals = link.result.rivals
    if rivals:
        return "rival " + "; ".join(r.text for r in rivals) + "; the network could not choose"
    return "no cycle of links checks it, and such a bridge is not trusted here"


def _fits(links: Sequence[Link], net: _Network) -> tuple[LinkFit, ...]:
    """What the network made of each link."""
    fits = [LinkFit(EdgeState.UNUSED, reason=_left_out(k)) for k in links]
    for k, c in net.choices.items():
        state = EdgeState.REJECTED if c.rejected else EdgeState.UNUSED
        fits[k] = LinkFit(state, reason=c.reason)
    for verdict, k in zip(net.v.edges, net.used, strict=True):
        reason = verdict.reason
        if k in net.choices and net.choices[k].chosen is not None:  # else used as a walk bridge
            reason = f"{net.choices[k].reason}; {reason}"
        if links[k].status is Status.DEGENERATE and verdict.state is not EdgeState.REJECTED:
            reason += "; degenerate: only its rotation and height count"
        if links[k].vouched and verdict.state is not EdgeState.USED:  # used: the walk's word
            reason += f"; {WALKS_WORD}"
        fits[k] = LinkFit(verdict.state, verdict.residual, reason)
    return tuple(fits)


def _edge(link: Link, walk: bool = False) -> Edge:
    """A link's kept pose as an edge (reduced frames), ``walk``: marked if a walk's link."""
    r = link.result
    flat = link.status is Status.DEGENERATE  # where its scans are horizontally: unknown
    T, cov = r.T_reduced, link_covariance(r)
    walked = walk and link.kind.walked
    trusted = link.ok or link.vouched  # a vouched link is a suspect one (its gate doubted it)
    return Edge(link.target, link.source, T, cov, trusted, not flat, walked, link.vouched)


def _hypotheses(link: Link, k: int) -> list[Hypothesis]:
    """The kept pose and every rival of an ambiguous link as hypotheses (rivals' covariances
    from their NDT Hessians, as an NDT-only link's)."""
    r = link.result
    out = [Hypothesis(k, 0, replace(_edge(link), trusted=True), 1.0)]
    A, B = np.eye(4), np.eye(4)
    A[:3, 3], B[:3, 3] = -r.reduction_target, r.reduction_source
    for n, rival in enumerate(r.rivals, start=1):
        T = A @ rival.T_target_source @ B
        cov = ndt_covariance(
            rival.hessian, T, level_target=r.level_target, level_source=r.level_source
        )
        out.append(Hypothesis(k, n, Edge(link.target, link.source, T, cov), rival.evidence))
    return out


def _ambiguous_nodes(
    v: Verification, left: dict[int, Hypothesis], texts: dict[int, str]
) -> tuple[NodeVerdict, ...]:
    """The verdicts, with scans that no kept link reaches but an ambiguous link left unchosen
    does made suspect: posed by its kept pose, the reason naming the link and its rivals
    (``texts``, by link)."""
    nodes = list(v.nodes)
    changed = True
    while changed:
        changed = False
        for k, h in sorted(left.items()):
            e = h.edge
            for near, far in ((e.target, e.source), (e.source, e.target)):
                if nodes[near].pose is None or nodes[far].status is not NodeStatus.UNPOSED:
                    continue
                step = e.T_target_source if near == e.target else np.linalg.inv(e.T_target_source)
                why = f"reached only through link {k} (T_{e.target}_{e.source}): {texts[k]}"
                nodes[far] = NodeVerdict(
                    far,
                    NodeStatus.SUSPECT,
                    nodes[near].pose @ step,
                    None,
                    why,
                    None,
                    nodes[near].cluster,
                )
                changed = True
    return tuple(nodes)


def _verticals(links: Sequence[Link]) -> tuple[dict[int, np.ndarray], dict[int, str]]:
    """Each scan's vertical (unit, scan axes) and how it was found, from the links that
    prepared it."""
    ups: dict[int, np.ndarray] = {}
    sources: dict[int, str] = {}
    for link in links:
        r = link.result
        if r is not None:
            ups[link.target], sources[link.target] = r.level_target[2].copy(), r.vertical_target
            ups[link.source], sources[link.source] = r.level_source[2].copy(), r.vertical_source
    return ups, sources


def _datum(
    v: Verification,
    edges: Sequence[Edge],
    links: Sequence[Link],
    red: Sequence[np.ndarray | None],
    controls: Sequence[Control],
    grid_scale: float,
) -> Datum | None:
    """The world frame of the anchor's cluster (:mod:`ndt_cli.pipeline.datum`); None when the
    anchor has no link (it is the world, as it stands)."""
    anchor = v.adjustment.anchor
    if red[anchor] is None:
        return None
    nodes = [n for n in v.nodes if n.cluster == 0 and v.adjustment.poses[n.index] is not None]
    ups, sources = _verticals(links)
    cluster = Cluster(
        {n.index: _translation(red[anchor]) @ n.pose for n in nodes},
        {n.index: red[n.index] for n in nodes},
        {n.index: ups[n.index] for n in nodes if n.index in ups},
        {n.index: sources[n.index] for n in nodes if n.index in sources},
        anchor,
    )
    members = {n.index for n in nodes}
    kept = [
        k
        for k, e in enumerate(v.edges)
        if e.state in (EdgeState.CONFIRMED, EdgeState.USED) and {e.target, e.source} <= members
    ]
    solver = Solver(len(red), anchor, edges, None, "huber", float(np.sqrt(v.threshold)), 100)
    return datum(cluster, controls, solver, kept, grid_scale)


def _in_world(
    scans: list[ScanPose],
    world: Datum,
    v: Verification,
    red: Sequence[np.ndarray | None],
    anchor: int,
) -> list[ScanPose]:
    """The scans of the anchor's cluster in the world of ``world`` (the others unchanged)."""
    W = world.poses[anchor] @ np.linalg.inv(_translation(red[anchor]) @ v.nodes[anchor].pose)
    out = []
    for k, scan in enumerate(scans):
        if scan.cluster != 0 or scan.T_world_scan is None:
            out.append(scan)
            continue
        T = world.poses[k] @ _translation(-red[k]) if k in world.poses else W @ scan.T_world_scan
        sigma = scan.sigma
        if k in world.covariances:
            sigma = _sigmas(world.poses[k][:3, :3], world.covariances[k])
        out.append(replace(scan, T_world_scan=T, sigma=sigma))
    return out


def _sigmas(R: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """1-sigma of a node's position (x, y, z in m, world axes) and heading (deg) from its 6x6
    covariance (body frame) and its rotation ``R`` in the world."""
    cov_t = R @ covariance[3:, 3:] @ R.T
    cov_r = R @ covariance[:3, :3] @ R.T
    return np.array([*np.sqrt(np.diag(cov_t)), np.degrees(np.sqrt(cov_r[2, 2]))])


def _left_out(link: Link) -> str:
    """Why a link is not in the network."""
    if link.result is not None and link.result.refuted:
        return "refuted by its data, left out: " + link.reason
    return link.reason or link.status.value


def _scan_pose(
    node: NodeVerdict,
    red: Sequence[np.ndarray | None],
    roots: dict[int, int],
    unreadable: dict[int, str],
    links: Sequence[Link],
) -> ScanPose:
    """A node's verdict as a scan's pose in its cluster's world (its root scan's own frame)."""
    k = node.index
    if k in unreadable or node.pose is None or node.cluster is None:
        reason = _why_unposed(k, links, unreadable) if k in unreadable else node.reason
        return ScanPose(NodeStatus.UNPOSED, None, reason=reason)
    root = roots[node.cluster]
    if red[k] is None or red[root] is None:  # a lone anchor: no link gave its reduction
        T = np.eye(4)
    else:
        T = _translation(red[root]) @ node.pose @ _translation(-red[k])
    sigma = None if node.covariance is None else _sigmas(node.pose[:3, :3], node.covariance)
    reason = "" if node.status is NodeStatus.OK else node.reason
    return ScanPose(node.status, T, sigma, reason, node.cluster)
