"""Verification of a network's links by consistency, and a trustworthy status per scan.

Accepted links start as the trusted ones (their own quality gate said ok); the worst accepted
link whose residual exceeds the chi-square threshold is rejected and the network solved again,
until none does. Untrusted links whose scans are both posed are then tested against the
adjustment: consistent ones are confirmed and used, the others rejected. A scan is ok when
accepted links connect it to the anchor; a link that is a bridge cannot be checked (used, not
confirmed); a scan reachable only through untested links is suspect; others are unposed.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from ndt_cli.pipeline.adjust import Adjustment, Solution, Solver, adjustment_of
from ndt_cli.pipeline.covariance import relative_covariance, se3_log
from ndt_cli.pipeline.graph import (
    CHI2_6_999,
    Edge,
    EdgeResidual,
    bridges,
    components,
    compose,
    residuals,
)


class EdgeState(StrEnum):
    """What :func:`verify` made of a link.

    ``confirmed``: checked by consistency and kept (on a cycle of kept links within the
    threshold, or an untrusted link that agreed with the adjustment); ``used``: kept but not
    checkable (a bridge: no cycle of kept links passes through it); ``rejected``: inconsistent;
    ``unused``: untrusted and not testable (its nodes are not posed together), left out.
    """

    CONFIRMED = "confirmed"
    USED = "used"
    REJECTED = "rejected"
    UNUSED = "unused"


class NodeStatus(StrEnum):
    """``ok``: posed by the adjustment (connected to the anchor through kept links);
    ``suspect``: posed only through an unused (untrusted, untested) link; ``unposed``."""

    OK = "ok"
    SUSPECT = "suspect"
    UNPOSED = "unposed"


@dataclass(frozen=True, repr=False)
class EdgeVerdict:
    """One link after :func:`verify`: its state, why, and its residual against the final
    poses (None unless both nodes are posed, ok or suspect)."""

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
    """One node after :func:`verify`: status, ``T_world_node`` (None when unposed), its 6x6
    covariance (ok nodes only), ``via`` (suspect: the unused edge its pose goes through)."""

    index: int
    status: NodeStatus
    pose: np.ndarray | None
    covariance: np.ndarray | None
    reason: str
    via: int | None = None

    def __repr__(self) -> str:
        where = (
            "" if self.pose is None else " at ({:.3f}, {:.3f}, {:.3f}) m".format(*self.pose[:3, 3])
        )
        return f"NodeVerdict({self.index}: {self.status.value}{where}; {self.reason})"


@dataclass(frozen=True, repr=False)
class Verification:
    """Result of :func:`verify`: a verdict per edge and per node (input order), the final
    :class:`Adjustment` of the kept links, the chi-square threshold, the number of solves and
    the times (s): all, the solves, the tests of untrusted links, the final marginals."""

    edges: tuple[EdgeVerdict, ...]
    nodes: tuple[NodeVerdict, ...]
    adjustment: Adjustment
    threshold: float
    solves: int
    time_s: float
    timings: dict[str, float] = field(default_factory=dict)  # s: solve_s, test_s, marginals_s

    @property
    def poses(self) -> tuple[np.ndarray | None, ...]:
        """``T_world_node`` of ok and suspect nodes, None for unposed ones."""
        return tuple(n.pose for n in self.nodes)

    def states(self) -> tuple[EdgeState, ...]:
        return tuple(e.state for e in self.edges)

    def statuses(self) -> tuple[NodeStatus, ...]:
        return tuple(n.status for n in self.nodes)

    def __repr__(self) -> str:
        edges = ", ".join(f"{s.value} {sum(e.state is s for e in self.edges)}" for s in EdgeState)
        nodes = ", ".join(f"{s.value} {sum(n.status is s for n in self.nodes)}" for s in NodeStatus)
        return (
            f"Verification(edges: {edges}; nodes: {nodes}; threshold {self.threshold:.2f}, "
            f"{self.solves} solves, {self.time_s:.3f} s)"
        )


class _Verifier:
    """State of one :func:`verify` run: which edges are accepted, rejected (with the reason)
    and, among the untrusted ones, confirmed by their test (with the reason)."""

    def __init__(self, solver: Solver, threshold: float, batch: bool) -> None:
        self.solver, self.edges, self.threshold, self.batch = solver, solver.edges, threshold, batch
        self.accepted = {k for k, e in enumerate(self.edges) if e.trusted}
        self.rejected: dict[int, str] = {}
        self.tested: dict[int, str] = {}
        self.last: dict[int, EdgeResidual] = {}
        self.born_bridges = bridges(solver.n, self.edges, sorted(self.accepted))
        self.test_s = 0.0

    def reject_until_consistent(self, guess: Sequence[np.ndarray | None]) -> Solution:
        """Solve the accepted edges; while the worst of them that is not a bridge has a chi2
        over the threshold, reject it and solve again (from the last poses). In batch mode,
        each round rejects every edge over the threshold that is the worst near it."""
        while True:
            ids = sorted(self.accepted)
            sol = self.solver.solve(ids, guess, every_component=True)
            self.last = residuals(self.edges, ids, sol.poses, self.solver.sqrt_info)
            free = bridges(self.solver.n, self.edges, ids)
            over = [k for k in ids if k not in free and self.last[k].chi2 > self.threshold]
            if not over:
                return sol
            worst_first = sorted(over, key=lambda k: -self.last[k].chi2)
            picked = self._local_worst(worst_first) if self.batch else worst_first[:1]
            for k in picked:
                self.accepted.discard(k)
                self.tested.pop(k, None)
                self.rejected[k] = (
                    f"chi2 {self.last[k].chi2:.4g} > {self.threshold:.2f}, the worst "
                    f"{'near it ' if self.batch else ''}of {len(over)} link(s) over the "
                    f"threshold (solve {self.solver.solves})"
                )
            guess = sol.poses

    def _local_worst(self, worst_first: list[int]) -> list[int]:
        """Batch mode: the edges of ``worst_first`` (over the threshold, worst first) with no
        worse one touching their nodes or their nodes' neighbours (an outlier pulls its
        neighbours over the threshold; they wait for the next solve), kept only while their
        removal, with the ones before them, cuts no node off."""
        edges, near = self.edges, [set() for _ in range(self.solver.n)]
        for k in self.accepted:
            near[edges[k].target].add(edges[k].source)
            near[edges[k].source].add(edges[k].target)
        picked: list[int] = []
        blocked: set[int] = set()  # nodes near an edge already considered
        for k in worst_first:
            ends = {edges[k].target, edges[k].source}
            if ends & blocked:
                continue
            zone = ends.union(*(near[v] for v in ends))
            blocked |= zone
            rest = [m for m in self.accepted if m != k and m not in picked]
            labels = components(self.solver.n, [(edges[m].target, edges[m].source) for m in rest])
            if labels[edges[k].target] == labels[edges[k].source]:
                picked.append(k)
        return picked

    def test_untrusted(self, sol: Solution) -> bool:
        """Test every untrusted edge whose nodes the solution poses together (same component)
        against it: chi2 of its misfit under its covariance plus that of the adjusted relative
        pose. Consistent ones join the accepted edges; returns whether any did."""
        todo = [k for k, e in enumerate(self.edges) if not e.trusted and k not in self.rejected]
        todo = [k for k in todo if k not in self.accepted and self._together(sol, k)]
        if not todo:
            return False
        t0 = time.perf_counter()
        marginals = self.solver.marginals(sol)
        for k in todo:
            e = self.edges[k]
            Pi, Pj = sol.poses[e.target], sol.poses[e.source]
            joint = self.solver.joint(marginals, e.target, e.source)
            predicted = e.covariance + relative_covariance(Pi, Pj, joint)
            xi = se3_log(np.linalg.inv(e.T_target_source) @ np.linalg.inv(Pi) @ Pj)[0]
            chi2 = float(xi @ np.linalg.solve(predicted, xi))
            ok = chi2 <= self.threshold
            text = (
                f"untrusted, tested against the adjustment of the other links: chi2 "
                f"{chi2:.4g} {'<=' if ok else '>'} {self.threshold:.2f}"
            )
            if ok:
                self.accepted.add(k)
                self.tested[k] = text
            else:
                self.rejected[k] = text
        self.test_s = time.perf_counter() - t0
        return any(k in self.accepted for k in todo)

    def _together(self, sol: Solution, k: int) -> bool:
        i, j = self.edges[k].target, self.edges[k].source
        both = sol.poses[i] is not None and sol.poses[j] is not None
        return both and sol.labels[i] == sol.labels[j]

    def states(self) -> list[tuple[EdgeState, str]]:
        """Final state and reason of every edge."""
        free = bridges(self.solver.n, self.edges, sorted(self.accepted))
        out = []
        for k in range(len(self.edges)):
            if k in self.rejected:
                out.append((EdgeState.REJECTED, self.rejected[k]))
            elif k in self.tested:
                out.append((EdgeState.CONFIRMED, self.tested[k]))
            elif k in free and k in self.born_bridges:
                out.append((EdgeState.USED, "a bridge: no cycle of kept links, not checkable"))
            elif k in free:
                text = "a bridge once its cycles lost rejected links: which was wrong is ambiguous"
                out.append((EdgeState.USED, text))
            elif k in self.accepted:
                chi2 = self.last[k].chi2
                text = f"on a cycle of kept links, chi2 {chi2:.4g} <= {self.threshold:.2f}"
                out.append((EdgeState.CONFIRMED, text))
            else:
                text = "untrusted and not testable: no kept links pose its nodes together"
                out.append((EdgeState.UNUSED, text))
        return out


def _node_verdicts(
    edges: Sequence[Edge], states: Sequence[EdgeState], adjustment: Adjustment
) -> tuple[NodeVerdict, ...]:
    """Ok: posed by the adjustment. Suspect: reached from an ok node breadth-first through
    kept and unused edges (posed by composing them; ``via``: the first unused edge on the
    path). Unposed: the rest; the reason names the rejected links when only those touch it.
    (:func:`verify` never rejects a bridge, so rejections alone cannot cut a node off.)"""
    ok = {v: p for v, p in enumerate(adjustment.poses) if p is not None}
    unused = [k for k, s in enumerate(states) if s is EdgeState.UNUSED]
    kept = [k for k, s in enumerate(states) if s in (EdgeState.CONFIRMED, EdgeState.USED)]
    posed, via = compose(edges, kept + unused, ok, set(unused))
    out = []
    for v in range(len(adjustment.poses)):
        if v in ok:
            out.append(NodeVerdict(v, NodeStatus.OK, ok[v], adjustment.covariances[v], "adjusted"))
        elif v in posed:
            e = edges[via[v]]
            text = f"posed only through unused link {via[v]} (T_{e.target}_{e.source})"
            out.append(NodeVerdict(v, NodeStatus.SUSPECT, posed[v], None, text, via[v]))
        else:
            out.append(NodeVerdict(v, NodeStatus.UNPOSED, None, None, _unposed(edges, states, v)))
    return tuple(out)


def _unposed(edges: Sequence[Edge], states: Sequence[EdgeState], v: int) -> str:
    """Why node ``v`` has no pose."""
    touching = [k for k, e in enumerate(edges) if v in (e.target, e.source)]
    if not touching:
        return "no link"
    if all(states[k] is EdgeState.REJECTED for k in touching):
        return "only rejected links: " + ", ".join(map(str, touching))
    return "no kept or unused link connects it to the anchor"


def verify(
    n_nodes: int,
    anchor: int,
    edges: Sequence[Edge],
    initial_poses: Sequence[np.ndarray | None] | None = None,
    *,
    threshold: float = CHI2_6_999,
    kernel: str = "huber",
    kernel_width: float | None = None,
    max_iterations: int = 100,
    batch: bool = False,
) -> Verification:
    """Decide which links to keep by their consistency, adjust, and judge every node.

    1. The accepted edges start as the trusted ones. Solve (each connected component of them;
       the anchor's in the world frame); while the worst accepted edge that is not a bridge
       has ``chi2 > threshold``, reject it and solve again: one at a time, worst first.
       Bridges (no cycle of accepted edges) cannot be checked and stay accepted.
    2. Each untrusted edge whose nodes that solution poses together is tested against it:
       chi2 of its misfit under its covariance plus the adjusted relative pose's. Consistent
       ones are accepted (then step 1 runs again, so the kept set stays consistent);
       inconsistent ones are rejected; the rest are unused.
    3. Edge states: ``rejected``; ``confirmed`` (accepted on a cycle within the threshold, or
       untrusted and consistent); ``used`` (accepted bridges); ``unused``. Node statuses: ok
       (connected to the anchor through accepted edges: the final adjustment), suspect
       (reached only through unused edges: composed from the nearest ok node, ``via`` the
       unused edge), unposed (only rejected edges reach it, or none). Residuals are against
       the final poses (ok and suspect nodes).

    ``threshold``: chi-square of the whitened 6-DOF misfit (default p = 0.999); the robust
    kernel's width defaults to its square root. Options as :func:`adjust`. ``batch``: step 1
    rejects, per solve, every edge over the threshold with no worse one within one link of
    its nodes (and whose removal with the others cuts no node off): one solve per round
    instead of one per outlier, the same choices where outliers lie apart; for networks with
    many bad links.
    """
    t0 = time.perf_counter()
    width = float(np.sqrt(threshold)) if kernel_width is None else kernel_width
    solver = Solver(n_nodes, anchor, edges, initial_poses, kernel, width, max_iterations)
    run = _Verifier(solver, threshold, batch)
    sol = run.reject_until_consistent(solver.guess)
    if run.test_untrusted(sol):
        sol = run.reject_until_consistent(sol.poses)
    adjustment = adjustment_of(solver, sol, True, t0)
    states = run.states()
    nodes = _node_verdicts(edges, [s for s, _ in states], adjustment)
    found = residuals(edges, range(len(edges)), [n.pose for n in nodes], solver.sqrt_info)
    verdicts = tuple(
        EdgeVerdict(k, e.target, e.source, e.trusted, state, reason, found.get(k))
        for k, (e, (state, reason)) in enumerate(zip(edges, states, strict=True))
    )
    timings = {
        "solve_s": solver.solve_s,
        "test_s": run.test_s,
        "marginals_s": adjustment.marginals_s,
    }
    return Verification(
        verdicts, nodes, adjustment, threshold, solver.solves, time.perf_counter() - t0, timings
    )
