"""Which links of a network to believe, and a trustworthy status per scan: trust that follows
the evidence.

A link's own quality gate is one piece of evidence; agreement with other links is another, and
a strong one: independent wrong registrations do not agree around a cycle to within their
uncertainties by chance. So every usable link, ok or not, takes part in the adjustment, and the
links that disagree are found as a surveyor's network adjustment finds blunders (Baarda's data
snooping): solve (Huber's kernel, then Cauchy's from there: a blunder pulls with a bounded,
then a vanishing force), test every link's misfit against the chi-square threshold, give up
the link whose removal leaves the least disagreement (tried with Huber's convex kernel) and
solve again, until every link that lies on a cycle passes in both solutions; the kept links
are then adjusted with Huber's kernel. Between a link its gate passed and one it doubted, the
doubted one goes first: a gate-ok link's chi-square counts :data:`TRUST` times smaller in the
ranking and its removal costs that much more (never in the test).

- A kept link on a cycle of kept links is **confirmed**, whatever its gate said: the cycle
  checked it.
- A kept link on no cycle (a bridge) cannot be checked: it is **used** when its own gate passed,
  and **unused** otherwise; scans behind an unused link are suspect, never ok. A link that fixes
  where its scans are horizontally and lies only on cycles that a degenerate link closes is
  such a bridge too (:func:`~ndt_cli.pipeline.graph.uncheckable`).
- A link that disagrees is **rejected**.

A scan is **ok** when kept links tie it to its cluster's first scan and the adjustment pins
its pose down: a cycle of links that are all weak along one direction (a corridor's, which can
agree on a wrong slide) leaves the pose free along it, and a scan whose horizontal position or
heading has a standard deviation above :data:`MAX_SIGMA_M` / :data:`MAX_SIGMA_DEG` is suspect.
Kept links split the scans into **clusters**: 0 holds the anchor, then 1, 2, ... by size; each
is adjusted in the frame of its lowest-numbered scan.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum

import numpy as np

from ndt_cli.pipeline.adjust import Adjustment, Solution, Solver, adjustment_of
from ndt_cli.pipeline.graph import (
    CHI2_6_999,
    Edge,
    EdgeResidual,
    bridges,
    components,
    compose,
    residuals,
    uncheckable,
)
from ndt_cli.pipeline.marginals import UNDETERMINED_VAR

MAX_SIGMA_M = 0.2  # m: a scan whose adjusted horizontal position is less certain is suspect
MAX_SIGMA_DEG = 0.2  # degrees: likewise for its heading

GATES_WORD = "its gate's word"
"""Why a kept link no cycle checks is used: its gate passed it (see :func:`states`)."""
WALKS_WORD = "vouched for by the walk (its gate doubted it for its evidence alone)"
"""Why such a link is used when the walk vouched for it (:attr:`Edge.vouched`)."""
BORN_BRIDGE = "a bridge (on no cycle that checks it): "
LEFT_BRIDGE = "a bridge once links of its cycles were rejected: which was wrong is ambiguous; "


class EdgeState(StrEnum):
    """What :func:`verify` made of a link.

    ``confirmed``: on a cycle of kept links, within the threshold; ``used``: kept on its own
    gate's word (a bridge: no cycle of kept links checks it); ``rejected``: it
    disagrees with the links kept; ``unused``: neither checkable nor ok by its gate (a bridge
    whose gate failed, or its scans are not posed together), left out.
    """

    CONFIRMED = "confirmed"
    USED = "used"
    REJECTED = "rejected"
    UNUSED = "unused"


class NodeStatus(StrEnum):
    """``ok``: posed by the adjustment of kept links, its pose pinned down; ``suspect``: posed
    only through an unused link, or its pose free along some direction; ``unposed``."""

    OK = "ok"
    SUSPECT = "suspect"
    UNPOSED = "unposed"


@dataclass(frozen=True, repr=False)
class EdgeVerdict:
    """One link after :func:`verify`: its state, why, and its residual against the final
    poses (None unless both nodes are posed in one cluster)."""

    index: int
    target: int
    source: int
    trusted: bool
    state: EdgeState
    reason: str
    residual: EdgeResidual | None

    def __repr__(self) -> str:
        r = self.residual
        fit = "" if r is None else f", chi2 {r.chi2:.3g}, {r.rotation_deg:.4f} deg, "
        fit += "" if r is None else f"{r.translation_m:.4f} m"
        trust = "trusted" if self.trusted else "untrusted"
        return (
            f"EdgeVerdict({self.index}: T_{self.target}_{self.source} {trust} "
            f"{self.state.value}{fit}; {self.reason})"
        )


@dataclass(frozen=True, repr=False)
class NodeVerdict:
    """One node after :func:`verify`: status, ``T_root_node`` in its cluster's frame (None when
    unposed), its 6x6 covariance (nodes the adjustment posed), ``via`` (suspect through an
    unused edge: that edge), and its ``cluster`` (None when unposed)."""

    index: int
    status: NodeStatus
    pose: np.ndarray | None
    covariance: np.ndarray | None
    reason: str
    via: int | None = None
    cluster: int | None = None

    def __repr__(self) -> str:
        where = (
            "" if self.pose is None else " at ({:.3f}, {:.3f}, {:.3f}) m".format(*self.pose[:3, 3])
        )
        return (
            f"NodeVerdict({self.index}: {self.status.value}, cluster {self.cluster}{where}; "
            f"{self.reason})"
        )


@dataclass(frozen=True, repr=False)
class Verification:
    """Result of :func:`verify`: a verdict per edge and per node (input order), the final
    :class:`Adjustment` of the kept links (every cluster), the chi-square threshold, the
    number of solves and the times (s): all, the consensus, the solves, the marginals."""

    edges: tuple[EdgeVerdict, ...]
    nodes: tuple[NodeVerdict, ...]
    adjustment: Adjustment
    threshold: float
    solves: int
    time_s: float
    timings: dict[str, float] = field(default_factory=dict)
    roots: dict[int, int] = field(default_factory=dict)  # cluster -> the node of its frame

    @property
    def poses(self) -> tuple[np.ndarray | None, ...]:
        """``T_root_node`` of ok and suspect nodes (their cluster's frame), None for unposed."""
        return tuple(n.pose for n in self.nodes)

    def states(self) -> tuple[EdgeState, ...]:
        return tuple(e.state for e in self.edges)

    def statuses(self) -> tuple[NodeStatus, ...]:
        return tuple(n.status for n in self.nodes)

    def clusters(self) -> tuple[int | None, ...]:
        return tuple(n.cluster for n in self.nodes)

    def __repr__(self) -> str:
        edges = ", ".join(f"{s.value} {sum(e.state is s for e in self.edges)}" for s in EdgeState)
        nodes = ", ".join(f"{s.value} {sum(n.status is s for n in self.nodes)}" for s in NodeStatus)
        n_clusters = len({c for c in self.clusters() if c is not None})
        return (
            f"Verification(edges: {edges}; nodes: {nodes}; {n_clusters} cluster(s); threshold "
            f"{self.threshold:.2f}, {self.solves} solves, {self.time_s:.3f} s)"
        )


def _trusted_first(solver: Solver) -> list[np.ndarray | None]:
    """Initial poses composed breadth-first from each component's root, through the gate-ok
    links before any other: a wrong untrusted link starts far from agreeing."""
    edges, guess = solver.edges, list(solver.guess)
    trusted = [k for k, e in enumerate(edges) if e.trusted]
    labels = components(solver.n, [(edges[k].target, edges[k].source) for k in range(len(edges))])
    roots: dict[int, int] = {}
    for v in range(solver.n):
        roots.setdefault(int(labels[v]), v)
    roots[int(labels[solver.anchor])] = solver.anchor
    posed = {r: np.eye(4) if guess[r] is None else guess[r] for r in roots.values()}
    posed.update({v: p for v, p in enumerate(guess) if p is not None})
    first, _ = compose(edges, trusted, posed)
    every, _ = compose(edges, range(len(edges)), first)
    return [every.get(v) for v in range(solver.n)]


TRUST = 4.0  # between links that misfit, a gate-ok link is given up only when its chi-square
# is this many times that of the worst doubted one: of two links of which one must go (a cut of
# two), the one its own gate doubted goes
LOOKAHEAD = 3  # links tried at each step: masking by several blunders next to each other


class _Verifier:
    """State of one :func:`verify` run: which edges are kept, and why the others are not."""

    def __init__(self, solver: Solver, trial: Solver, threshold: float) -> None:
        self.solver, self.trial, self.edges = solver, trial, solver.edges
        self.threshold = threshold
        self.kept: set[int] = set()
        self.born_bridges = uncheckable(solver.n, self.edges, range(len(self.edges)))
        self.rejected: dict[int, str] = {}
        self.last: dict[int, EdgeResidual] = {}  # the Cauchy solution's residuals
        self.convex: dict[int, EdgeResidual] = {}  # the Huber solution's

    def agree(self) -> Solution:
        """Solve all links, then, while a kept link that lies on a cycle fails the chi-square
        test in the Huber or the Cauchy solution, give up the one whose removal leaves the
        least disagreement (among the :data:`LOOKAHEAD` worst, a gate-ok link's chi-square
        counted :data:`TRUST` times smaller) and solve again; returns the last solution."""
        self.kept = set(range(len(self.edges)))
        sol = self._solve(_trusted_first(self.solver))
        while True:
            over = self._over()
            if not over:
                return sol
            trials = {}
            for k in sorted(over, key=self._rank, reverse=True)[:LOOKAHEAD]:
                self.kept.discard(k)
                trials[k] = self._cost(self._trial(sol.poses), k)
                self.kept.add(k)
            worst = min(trials, key=lambda k: (trials[k], -self._rank(k)))
            self.kept.discard(worst)
            self.rejected[worst] = (
                f"chi2 {self._chi2(worst):.4g} > {self.threshold:.2f}: of the {len(over)} "
                f"link(s) over the threshold, the one whose removal leaves the least disagreement"
            )
            sol = self._solve(sol.poses)

    def _solve(self, guess: Sequence[np.ndarray | None]) -> Solution:
        """Solve the kept edges (every component) with both kernels and record their
        residuals; returns the Huber solution."""
        ids = sorted(self.kept)
        redescending = self.solver.solve(ids, guess, every_component=True)
        self.last = residuals(self.edges, ids, redescending.poses, self.solver.sqrt_info)
        sol = self.trial.solve(ids, redescending.poses, every_component=True)
        self.convex = residuals(self.edges, ids, sol.poses, self.solver.sqrt_info)
        return sol

    def _chi2(self, k: int) -> float:
        """Link ``k``'s chi-square: the larger of the two solutions'."""
        return max(self.last[k].chi2, self.convex[k].chi2)

    def _trial(self, guess: Sequence[np.ndarray | None]) -> dict[int, EdgeResidual]:
        """Residuals of the kept edges solved with the convex (Huber) kernel: what a removal
        leaves, whatever pose the redescending kernel was caught in."""
        ids = sorted(self.kept)
        sol = self.trial.solve(ids, guess, every_component=True)
        return residuals(self.edges, ids, sol.poses, self.solver.sqrt_info)

    def _over(self) -> list[int]:
        """Kept edges on a cycle of kept edges whose chi-square exceeds the threshold."""
        ids = sorted(self.kept)
        free = bridges(self.solver.n, self.edges, ids)
        return [k for k in ids if k not in free and self._chi2(k) > self.threshold]

    def _cost(self, found: dict[int, EdgeResidual], removed: int) -> float:
        """Truncated least squares of the edges kept with ``removed`` given up: each edge's
        chi-square, at most the threshold (a gate-ok edge's given up costs :data:`TRUST`)."""
        cost = sum(min(r.chi2, self.threshold) for k, r in found.items() if k != removed)
        return cost + self.threshold * (TRUST if self.edges[removed].trusted else 1.0)

    def _rank(self, k: int) -> float:
        """How strongly link ``k`` is to be given up: its chi-square, a gate-ok link's divided
        by :data:`TRUST`."""
        return self._chi2(k) / (TRUST if self.edges[k].trusted else 1.0)

    def drop_untrusted_bridges(self, trust_bridges: bool = True) -> set[int]:
        """Kept bridges whose own gate failed (every bridge, unless ``trust_bridges`` or it
        joins neighbours along the walk: :attr:`Edge.walked`) leave the kept set (they cannot
        be checked); returns them."""
        free = uncheckable(self.solver.n, self.edges, sorted(self.kept))
        edges = self.edges
        out = {k for k in free if not (edges[k].trusted and (trust_bridges or edges[k].walked))}
        self.kept -= out
        return out

    def _untrusted(self) -> str:
        """Why a bridge its gate passed is not kept: no bridge is trusted, or (where some
        link joins neighbours along the walk) only those that do."""
        if any(e.walked for e in self.edges):
            return "only a bridge between neighbours along the walk is trusted"
        return "no bridge is trusted"

    def states(self, unchecked: set[int]) -> list[tuple[EdgeState, str]]:
        """Final state and reason of every edge."""
        free = uncheckable(self.solver.n, self.edges, sorted(self.kept))
        untrusted = self._untrusted()
        out = []
        for k in range(len(self.edges)):
            if k in self.rejected:
                out.append((EdgeState.REJECTED, self.rejected[k]))
            elif k in unchecked:
                why = "its own gate failed" if not self.edges[k].trusted else untrusted
                text = (
                    f"a bridge (on no cycle of kept links that checks it) and {why}: not checkable"
                )
                out.append((EdgeState.UNUSED, text))
            elif k in free:
                word = WALKS_WORD if self.edges[k].vouched else GATES_WORD
                text = BORN_BRIDGE if k in self.born_bridges else LEFT_BRIDGE
                out.append((EdgeState.USED, text + word))
            else:
                chi2 = self.last[k].chi2 if k in self.last else float("nan")
                text = f"on a cycle of kept links, chi2 {chi2:.4g} <= {self.threshold:.2f}"
                out.append((EdgeState.CONFIRMED, text))
        return out


def _clusters(n: int, edges: Sequence[Edge], kept: Sequence[int], anchor: int) -> list[int | None]:
    """Cluster of every node: components of the kept edges (the anchor's is 0, then by size,
    ties by lowest node); a node on no kept edge is in none (except the anchor)."""
    labels = components(n, [(edges[k].target, edges[k].source) for k in kept])
    touched = {edges[k].target for k in kept} | {edges[k].source for k in kept} | {anchor}
    groups: dict[int, list[int]] = {}
    for v in sorted(touched):
        groups.setdefault(int(labels[v]), []).append(v)
    order = sorted(groups, key=lambda c: (c != labels[anchor], -len(groups[c]), groups[c][0]))
    number = {c: k for k, c in enumerate(order)}
    return [number[int(labels[v])] if v in touched else None for v in range(n)]


def _roots(clusters: Sequence[int | None], anchor: int) -> dict[int, int]:
    """Each cluster's root: the anchor for cluster 0, the lowest node for the others."""
    roots = {0: anchor} if clusters[anchor] == 0 else {}
    for v, c in enumerate(clusters):
        if c is not None:
            roots.setdefault(c, v)
    return roots


def _rooted(
    adjustment: Adjustment, clusters: Sequence[int | None], roots: dict[int, int]
) -> Adjustment:
    """The adjustment with every cluster's poses in the frame of its root (cluster 0 stays in
    the anchor's; covariances, in the nodes' body frames, do not change)."""
    poses = list(adjustment.poses)
    for v, c in enumerate(clusters):
        if c is not None and c != 0 and poses[v] is not None:
            poses[v] = np.linalg.inv(adjustment.poses[roots[c]]) @ adjustment.poses[v]
    return replace(adjustment, poses=tuple(poses))


def _pinned(pose: np.ndarray, cov: np.ndarray | None) -> str:
    """'' when the node's horizontal position and heading are known within the bounds, else
    why not (a 6x6 covariance, right perturbation in the node's body frame)."""
    if cov is None:
        return ""
    R = pose[:3, :3]
    pos = R @ cov[3:, 3:] @ R.T
    w, V = np.linalg.eigh(pos[:2, :2])
    heading = float(np.degrees(np.sqrt(max((R @ cov[:3, :3] @ R.T)[2, 2], 0.0))))
    d = V[:, 1]
    if w[1] >= UNDETERMINED_VAR / 100:
        return f"position along ({d[0]:.2f}, {d[1]:.2f}) not determined by its links"
    if np.sqrt(max(w[1], 0.0)) > MAX_SIGMA_M:
        return (
            f"position along ({d[0]:.2f}, {d[1]:.2f}) not pinned down by its links "
            f"(sigma {np.sqrt(w[1]):.3g} m > {MAX_SIGMA_M} m)"
        )
    if heading > np.degrees(np.sqrt(UNDETERMINED_VAR / 100)):
        return "heading not determined by its links"
    if heading > MAX_SIGMA_DEG:
        return f"heading not pinned down by its links (sigma {heading:.3g} deg > {MAX_SIGMA_DEG})"
    return ""


def _node_verdicts(
    edges: Sequence[Edge],
    states: Sequence[EdgeState],
    adjustment: Adjustment,
    clusters: Sequence[int | None],
) -> tuple[NodeVerdict, ...]:
    """Ok: posed by the adjustment and pinned down. Suspect: posed but not pinned down, or
    reached from a posed node breadth-first through kept and unused edges (posed by composing
    them; ``via``: the first unused edge on the path). Unposed: the rest."""
    posed = {v: p for v, p in enumerate(adjustment.poses) if p is not None}
    unused = [k for k, s in enumerate(states) if s is EdgeState.UNUSED]
    kept = [k for k, s in enumerate(states) if s in (EdgeState.CONFIRMED, EdgeState.USED)]
    reached, via = compose(edges, kept + unused, posed, set(unused))
    cluster = list(clusters)
    for v in reached:  # a node reached through unused links belongs to where it was reached from
        if cluster[v] is None and via[v] is not None:
            e = edges[via[v]]
            cluster[v] = cluster[e.target] if cluster[e.target] is not None else cluster[e.source]
    out = []
    for v in range(len(adjustment.poses)):
        cov = adjustment.covariances[v]
        if v in posed:
            why = _pinned(posed[v], cov)
            status = NodeStatus.SUSPECT if why else NodeStatus.OK
            out.append(NodeVerdict(v, status, posed[v], cov, why or "adjusted", None, cluster[v]))
        elif v in reached:
            e = edges[via[v]]
            text = f"posed only through unused link {via[v]} (T_{e.target}_{e.source})"
            out.append(
                NodeVerdict(v, NodeStatus.SUSPECT, reached[v], None, text, via[v], cluster[v])
            )
        else:
            why = _unposed(edges, states, v)
            out.append(NodeVerdict(v, NodeStatus.UNPOSED, None, None, why))
    return tuple(out)


def _unposed(edges: Sequence[Edge], states: Sequence[EdgeState], v: int) -> str:
    """Why node ``v`` has no pose."""
    touching = [k for k, e in enumerate(edges) if v in (e.target, e.source)]
    if not touching:
        return "no link"
    if all(states[k] is EdgeState.REJECTED for k in touching):
        return "only rejected links: " + ", ".join(map(str, touching))
    return "no kept link ties it to another scan"


def verify(
    n_nodes: int,
    anchor: int,
    edges: Sequence[Edge],
    initial_poses: Sequence[np.ndarray | None] | None = None,
    *,
    threshold: float = CHI2_6_999,
    max_iterations: int = 100,
    trust_bridges: bool = True,
) -> Verification:
    """Decide which links to keep by their agreement and their gates, adjust every cluster,
    and judge every node (see the module docstring).

    ``threshold``: chi-square of a link's whitened 6-DOF misfit (default p = 0.999), both the
    consensus's inlier bound and the safety net's test; the final adjustment uses a Huber
    kernel of width its square root. ``initial_poses``: optional ``T_world_node`` guesses
    (None entries: composed through the links, gate-ok ones first). Poses are in each
    cluster's frame: the anchor's for cluster 0, the lowest node's for the others.
    ``trust_bridges`` false: a bridge is never kept on its gate's word, so that every kept
    link lies on a cycle of kept links.
    """
    t0 = time.perf_counter()
    width = float(np.sqrt(threshold))
    detect = Solver(n_nodes, anchor, edges, initial_poses, "cauchy", width, max_iterations)
    solver = Solver(n_nodes, anchor, edges, initial_poses, "huber", width, max_iterations)
    run = _Verifier(detect, solver, threshold)
    found = run.agree()
    unchecked = run.drop_untrusted_bridges(trust_bridges)
    sol = solver.solve(sorted(run.kept), found.poses, every_component=True)
    adjustment = adjustment_of(solver, sol, True, t0, every_component=True)
    states = run.states(unchecked)
    clusters = _clusters(n_nodes, edges, sorted(run.kept), anchor)
    roots = _roots(clusters, anchor)
    adjustment = _rooted(adjustment, clusters, roots)
    nodes = _node_verdicts(edges, [s for s, _ in states], adjustment, clusters)
    found = residuals(edges, range(len(edges)), [n.pose for n in nodes], solver.sqrt_info)
    same = {k for k, e in enumerate(edges) if nodes[e.target].cluster == nodes[e.source].cluster}
    verdicts = tuple(
        EdgeVerdict(
            k, e.target, e.source, e.trusted, state, reason, found.get(k) if k in same else None
        )
        for k, (e, (state, reason)) in enumerate(zip(edges, states, strict=True))
    )
    timings = {
        "solve_s": detect.solve_s + solver.solve_s,
        "marginals_s": adjustment.marginals_s,
    }
    return Verification(
        verdicts,
        nodes,
        adjustment,
        threshold,
        detect.solves + solver.solves,
        time.perf_counter() - t0,
        timings,
        roots,
    )
