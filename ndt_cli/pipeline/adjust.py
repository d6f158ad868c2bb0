"""Global adjustment of a network of registration links with GTSAM.

The graph (:mod:`ndt_cli.pipeline.graph`): scans are nodes, links are edges with covariances.
Node covariances are 6x6 right perturbations of ``T_world_node`` (the node's body frame).
:func:`adjust` solves the pose graph (Levenberg-Marquardt, each link a ``BetweenFactorPose3``
under a robust Huber model); :mod:`ndt_cli.pipeline.verify` decides which links to keep.

Robust kernel: Huber on the whitened error norm with width ``sqrt(threshold)`` (4.74 sigma for
the 6-DOF chi-square at p = 0.999). Links within the threshold are plain least squares (weight
1, so the marginals of a clean network are the Gaussian ones); a link metres off (hundreds of
sigma) pulls with a bounded force, hundreds of times less than least squares. Huber is convex:
the solution does not depend on the initial poses, which are chained through the links and so
are metres off exactly where an outlier is. A redescending kernel (Cauchy) ignores an outlier
once in the right basin, but from poses chained through the outlier it settles where the good
links are explained away (tests: Cauchy alone 2.3 m off, Huber 3 cm, least squares 0.8 m);
``kernel="cauchy"`` therefore refines the Huber solution with Cauchy (3 cm where Huber alone
leaves up to 13 cm), at the price of inlier weights below 1. :func:`verify` uses Huber: it
removes the outliers' remaining pull by rejecting them and solving again.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ndt_cli.pipeline.covariance import sqrt_information
from ndt_cli.pipeline.graph import CHI2_6_999, Edge, EdgeResidual, components, compose, residuals
from ndt_cli.pipeline.marginals import marginal_covariances

PRIOR_SIGMA = 1e-6  # rad and m: the anchor's prior (fixes the gauge)
_KERNELS = ("huber", "cauchy", "none")


@dataclass(frozen=True, repr=False)
class Adjustment:
    """Result of :func:`adjust`, indexed by node and by edge (input order).

    ``poses``: ``T_world_node`` (world = the anchor's frame), None for nodes the edges do not
    connect to the anchor. ``covariances``: 6x6 marginal covariance of each pose (right
    perturbation, node body frame; rad and m), None when not posed or not computed.
    ``residuals``: per edge, None when the edge was not in the adjustment. Times in seconds.
    """

    poses: tuple[np.ndarray | None, ...]
    covariances: tuple[np.ndarray | None, ...]
    residuals: tuple[EdgeResidual | None, ...]
    iterations: int
    time_s: float
    solve_s: float = 0.0
    marginals_s: float = 0.0
    anchor: int = 0

    def __repr__(self) -> str:
        posed = sum(p is not None for p in self.poses)
        used = [r for r in self.residuals if r is not None]
        worst = max((r.chi2 for r in used), default=0.0)
        return (
            f"Adjustment({posed}/{len(self.poses)} nodes posed, {len(used)} edges, "
            f"worst chi2 {worst:.3g}, {self.iterations} it, {self.time_s:.3f} s)"
        )

    def sigmas(self, node: int) -> np.ndarray | None:
        """1-sigma of node's pose: rotation [deg] x3 then translation [m] x3 (body axes)."""
        C = self.covariances[node]
        if C is None:
            return None
        s = np.sqrt(np.diag(C))
        return np.concatenate([np.degrees(s[:3]), s[3:]])


@dataclass(frozen=True)
class Solution:
    """Poses of the nodes the solved edges reach (``T_root_node`` per component; the anchor's
    component in the world frame), the component labels, and GTSAM's graph and values."""

    poses: list[np.ndarray | None]
    labels: np.ndarray
    ids: list[int]  # the edges in the graph
    graph: object
    values: object
    iterations: int
    solve_s: float


class Solver:
    """The GTSAM factor of every edge, built once; solves any subset of the edges."""

    def __init__(
        self,
        n_nodes: int,
        anchor: int,
        edges: Sequence[Edge],
        initial_poses: Sequence[np.ndarray | None] | None,
        kernel: str,
        width: float,
        max_iterations: int,
    ) -> None:
        import gtsam

        _check(n_nodes, anchor, edges, initial_poses, kernel)
        self.g, self.n, self.anchor, self.edges = gtsam, n_nodes, anchor, edges
        self.guess = [None] * n_nodes if initial_poses is None else list(initial_poses)
        self.anchor_pose = np.eye(4) if self.guess[anchor] is None else self.guess[anchor]
        self.sqrt_info = sqrt_information(np.array([e.covariance for e in edges]).reshape(-1, 6, 6))
        self.factors = self._factors("huber" if kernel == "cauchy" else kernel, width)
        self.refine = self._factors("cauchy", width) if kernel == "cauchy" else None
        self.max_iterations = max_iterations
        self.solves, self.solve_s = 0, 0.0

    def _factors(self, kernel: str, width: float) -> list:
        return [
            self.g.BetweenFactorPose3(
                e.target, e.source, self.g.Pose3(e.T_target_source), self._noise(R, kernel, width)
            )
            for e, R in zip(self.edges, self.sqrt_info, strict=True)
        ]

    def _noise(self, R: np.ndarray, kernel: str, width: float) -> object:
        base = self.g.noiseModel.Gaussian.SqrtInformation(R)
        if kernel == "none":
            return base
        est = self.g.noiseModel.mEstimator
        robust = est.Huber.Create(width) if kernel == "huber" else est.Cauchy.Create(width)
        return self.g.noiseModel.Robust.Create(robust, base)

    def solve(
        self, active: Sequence[int], guess: Sequence[np.ndarray | None], every_component: bool
    ) -> Solution:
        """Levenberg-Marquardt on the edges ``active`` of the anchor's component (and, with
        ``every_component``, of every other component, each held at its lowest node)."""
        g, t0 = self.g, time.perf_counter()
        labels = components(self.n, [(self.edges[k].target, self.edges[k].source) for k in active])
        keep = {labels[self.anchor]}
        if every_component:
            keep |= {labels[self.edges[k].target] for k in active}
        ids = [k for k in active if labels[self.edges[k].target] in keep]
        roots: dict[int, int] = {}
        for v in range(self.n):  # each component is held at its lowest node, or the anchor
            if labels[v] in keep and labels[v] not in roots:
                roots[labels[v]] = v
        roots[labels[self.anchor]] = self.anchor
        fixed = {r: np.eye(4) if guess[r] is None else guess[r] for r in roots.values()}
        fixed[self.anchor] = self.anchor_pose
        given = {v: p for v, p in enumerate(guess) if p is not None and labels[v] in keep}
        initial, _ = compose(self.edges, ids, {**given, **fixed})
        values = g.Values()
        for v, pose in initial.items():
            values.insert(v, g.Pose3(pose))
        graph, values, iterations = self._optimise(self.factors, ids, fixed, values)
        if self.refine is not None:  # Cauchy from the Huber solution: its basin is the right one
            graph, values, more = self._optimise(self.refine, ids, fixed, values)
            iterations += more
        poses: list[np.ndarray | None] = [None] * self.n
        for v in initial:
            poses[v] = values.atPose3(v).matrix()
        self.solves += 1
        dt = time.perf_counter() - t0
        self.solve_s += dt
        return Solution(poses, labels, ids, graph, values, iterations, dt)

    def _optimise(
        self, factors: list, ids: Sequence[int], fixed: dict[int, np.ndarray], values: object
    ) -> tuple[object, object, int]:
        """Levenberg-Marquardt on the factors ``ids`` plus a tight prior on each fixed node."""
        g = self.g
        graph = g.NonlinearFactorGraph()
        for k in ids:
            graph.add(factors[k])
        prior = g.noiseModel.Isotropic.Sigma(6, PRIOR_SIGMA)
        for r, pose in fixed.items():
            graph.add(g.PriorFactorPose3(r, g.Pose3(pose), prior))
        params = g.LevenbergMarquardtParams()
        params.setMaxIterations(self.max_iterations)
        params.setRelativeErrorTol(1e-6)
        params.setAbsoluteErrorTol(1e-10)
        optimizer = g.LevenbergMarquardtOptimizer(graph, values, params)
        return graph, optimizer.optimize(), optimizer.iterations()


def _check(
    n_nodes: int,
    anchor: int,
    edges: Sequence[Edge],
    initial_poses: Sequence[np.ndarray | None] | None,
    kernel: str,
) -> None:
    """ValueError for node indices out of range, a wrong number of initial poses, or an
    unknown kernel."""
    if not 0 <= anchor < n_nodes:
        raise ValueError(f"anchor {anchor} is not a node (0..{n_nodes - 1})")
    for e in edges:
        if not (0 <= e.target < n_nodes and 0 <= e.source < n_nodes):
            raise ValueError(f"{e!r} names a node outside 0..{n_nodes - 1}")
    if initial_poses is not None and len(initial_poses) != n_nodes:
        raise ValueError(f"{len(initial_poses)} initial poses for {n_nodes} nodes")
    if kernel not in _KERNELS:
        raise ValueError(f"kernel must be one of {_KERNELS}, not {kernel!r}")


def adjustment_of(
    solver: Solver, sol: Solution, with_marginals: bool, t0: float, every_component: bool = False
) -> Adjustment:
    """The :class:`Adjustment` of the anchor's component of a solution (``every_component``:
    of every component it solved, each in the frame it was held in)."""
    home = sol.labels[solver.anchor]
    if every_component:
        poses = list(sol.poses)
        ids = list(sol.ids)
    else:
        poses = [p if sol.labels[v] == home else None for v, p in enumerate(sol.poses)]
        ids = [k for k in sol.ids if sol.labels[solver.edges[k].target] == home]
    found = residuals(solver.edges, ids, poses, solver.sqrt_info)
    covs: list[np.ndarray | None] = [None] * solver.n
    t1 = time.perf_counter()
    if with_marginals:
        posed = [v for v, p in enumerate(poses) if p is not None]
        for v, cov in marginal_covariances(solver.g, sol.graph, sol.values, posed).items():
            covs[v] = cov
    return Adjustment(
        poses=tuple(poses),
        covariances=tuple(covs),
        residuals=tuple(found.get(k) for k in range(len(solver.edges))),
        iterations=sol.iterations,
        time_s=time.perf_counter() - t0,
        solve_s=sol.solve_s,
        marginals_s=time.perf_counter() - t1,
        anchor=solver.anchor,
    )


def adjust(
    n_nodes: int,
    anchor: int,
    edges: Sequence[Edge],
    initial_poses: Sequence[np.ndarray | None] | None = None,
    *,
    kernel: str = "huber",
    kernel_width: float = float(np.sqrt(CHI2_6_999)),
    marginals: bool = True,
    max_iterations: int = 100,
) -> Adjustment:
    """Adjust the poses of the nodes that ``edges`` connect to ``anchor`` (GTSAM, LM).

    ``initial_poses``: ``T_world_node`` guesses (None entries, or None for all: composed
    through the edges breadth-first from the anchor). The anchor is held at its initial pose
    (identity when None) by a prior of ``PRIOR_SIGMA``. Every edge is a ``BetweenFactorPose3``
    with its covariance under ``kernel``: "huber", "cauchy" (Huber, then Cauchy from there)
    or "none" (least squares); ``kernel_width`` in sigma of the whitened error norm. Nodes
    not connected to the anchor get None and their edges are left out (no residual).
    ``marginals``: compute every posed node's 6x6 covariance. Raises ValueError for nodes
    out of range, a wrong number of initial poses or an unknown kernel.
    """
    t0 = time.perf_counter()
    solver = Solver(n_nodes, anchor, edges, initial_poses, kernel, kernel_width, max_iterations)
    sol = solver.solve(range(len(edges)), solver.guess, every_component=False)
    return adjustment_of(solver, sol, marginals, t0)
