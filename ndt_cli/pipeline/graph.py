"""The pose graph of a scan network: links as edges with covariances, connectivity, bridges,
poses composed along edges, and residuals.

Nodes are scans (indices ``0 .. n_nodes-1``); an :class:`Edge` is a registration link whose
``T_target_source`` maps the source node's reduced frame into the target node's, with a 6x6
covariance in GTSAM's ``Pose3`` tangent (rotation [rad] first, then translation [m]; right
perturbation ``T @ Exp(xi)``, source body frame; see :mod:`ndt_cli.pipeline.covariance`).
Poses are ``T_world_node`` with the world = the anchor node's frame.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ndt_cli.pipeline.covariance import se3_log, sqrt_information

CHI2_6_999 = 22.457744  # chi-square quantile, 6 degrees of freedom, p = 0.999


@dataclass(frozen=True, repr=False)
class Edge:
    """A link: ``T_target_source`` (4x4, reduced frames, ``p_target = T @ p_source``) and its
    6x6 ``covariance`` (right perturbation, source body frame; rad and m). ``trusted``: the
    link's own quality gate passed (ok status). ``horizontal`` False: the link says nothing
    of where its scans are horizontally (degenerate; its rotation and height count).
    ``walked``: it joins neighbours along the walk (scans taken one after the other), whose
    gate's word may stand where no other bridge's does (``quality.trust_walk_bridges``).
    ``vouched``: trusted on the walk's word, its own gate having doubted it for its evidence
    alone (:attr:`~ndt_cli.pipeline.links.Link.vouched`)."""

    target: int
    source: int
    T_target_source: np.ndarray
    covariance: np.ndarray
    trusted: bool = True
    horizontal: bool = True
    walked: bool = False
    vouched: bool = False

    def __post_init__(self) -> None:
        T = np.asarray(self.T_target_source, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"{self.name}: T_target_source must be a finite 4x4 matrix")
        if self.target == self.source:
            raise ValueError(f"{self.name}: a link needs two different nodes")
        C = np.asarray(self.covariance, dtype=float)
        if (
            C.shape != (6, 6)
            or not np.all(np.isfinite(C))
            or np.abs(C - C.T).max() > 1e-9 * np.abs(C).max()
        ):
            raise ValueError(f"{self.name}: the covariance must be a finite symmetric 6x6 matrix")
        try:
            np.linalg.cholesky(C)
        except np.linalg.LinAlgError:
            raise ValueError(f"{self.name}: the covariance must be positive definite") from None
        object.__setattr__(self, "T_target_source", T)
        object.__setattr__(self, "covariance", C)

    @property
    def name(self) -> str:
        """``T_<target>_<source>``."""
        return f"T_{self.target}_{self.source}"

    def __repr__(self) -> str:
        tx, ty, tz = self.T_target_source[:3, 3]
        trust = "trusted" if self.trusted else "untrusted"
        return f"Edge({self.name}, {trust}, t=({tx:.3f}, {ty:.3f}, {tz:.3f}) m)"


@dataclass(frozen=True)
class EdgeResidual:
    """Misfit of a link against adjusted poses: ``chi2`` of its whitened error (the squared
    Mahalanobis norm of ``Log(inv(T_target_source) @ inv(T_w_target) @ T_w_source)``), and the
    rotation [deg] and translation [m] differences (as ``ndt-eval``)."""

    chi2: float
    rotation_deg: float
    translation_m: float

    def __repr__(self) -> str:
        return (
            f"EdgeResidual(chi2 {self.chi2:.3g}, {self.rotation_deg:.4f} deg, "
            f"{self.translation_m:.4f} m)"
        )


def components(n_nodes: int, pairs: Sequence[tuple[int, int]]) -> np.ndarray:
    """Connected-component label of every node (int array) for undirected ``pairs``; labels
    count up from 0 in the order of each component's lowest node (union-find with path
    halving: linear in practice, and no sparse-matrix library for a few thousand edges)."""
    parent = list(range(n_nodes))

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in pairs:
        ra, rb = root(int(a)), root(int(b))
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)  # the lowest node is the root
    labels = np.empty(n_nodes, dtype=int)
    by_root: dict[int, int] = {}
    for node in range(n_nodes):
        labels[node] = by_root.setdefault(root(node), len(by_root))
    return labels


def bridges(n_nodes: int, edges: Sequence[Edge], ids: Sequence[int]) -> set[int]:
    """The ids of the edges (among ``ids``) that lie on no cycle of those edges (iterative
    Tarjan; parallel edges form a cycle)."""
    adj: list[list[tuple[int, int]]] = [[] for _ in range(n_nodes)]
    for k in ids:
        adj[edges[k].target].append((edges[k].source, k))
        adj[edges[k].source].append((edges[k].target, k))
    disc, low, out, clock = [-1] * n_nodes, [0] * n_nodes, set(), 0
    for root in range(n_nodes):
        if disc[root] >= 0 or not adj[root]:
            continue
        disc[root] = low[root] = clock
        clock += 1
        stack = [(root, -1, iter(adj[root]))]
        while stack:
            v, via, neighbours = stack[-1]
            for w, k in neighbours:
                if k == via:
                    continue
                if disc[w] < 0:
                    disc[w] = low[w] = clock
                    clock += 1
                    stack.append((w, k, iter(adj[w])))
                    break
                low[v] = min(low[v], disc[w])
            else:
                stack.pop()
                if stack:
                    u = stack[-1][0]
                    low[u] = min(low[u], low[v])
                    if low[v] > disc[u]:
                        out.add(via)
    return out


def uncheckable(n_nodes: int, edges: Sequence[Edge], ids: Sequence[int]) -> set[int]:
    """The ids of the edges (among ``ids``) that no cycle of those edges can check: the
    :func:`bridges`, and the horizontal edges on no cycle of horizontal edges. A cycle that
    a degenerate edge closes checks no horizontal position: two wrong links that put a
    piece of street turned or shifted the same way would agree around it, trivially."""
    level = [k for k in ids if edges[k].horizontal]
    return bridges(n_nodes, edges, ids) | bridges(n_nodes, edges, level)


def _step(edge: Edge, pose: np.ndarray, from_node: int) -> np.ndarray:
    """``T_world_other`` of the edge's other node, from ``T_world_from_node`` and the edge."""
    if from_node == edge.target:
        return pose @ edge.T_target_source
    return pose @ np.linalg.inv(edge.T_target_source)


def compose(
    edges: Sequence[Edge],
    ids: Sequence[int],
    posed: dict[int, np.ndarray],
    marks: frozenset[int] | set[int] = frozenset(),
) -> tuple[dict[int, np.ndarray], dict[int, int | None]]:
    """Breadth-first from the ``posed`` nodes through the edges ``ids`` (in id order): the
    poses of every node reached, composed along the fewest links, and per node the first of
    the edges ``marks`` on its path (None when its path crosses none)."""
    poses, via = dict(posed), dict.fromkeys(posed)
    by_node: dict[int, list[int]] = {}
    for k in sorted(ids):
        by_node.setdefault(edges[k].target, []).append(k)
        by_node.setdefault(edges[k].source, []).append(k)
    queue = deque(sorted(posed))
    while queue:
        v = queue.popleft()
        for k in by_node.get(v, ()):
            w = edges[k].source if edges[k].target == v else edges[k].target
            if w not in poses:
                poses[w] = _step(edges[k], poses[v], v)
                via[w] = via[v] if via[v] is not None else (k if k in marks else None)
                queue.append(w)
    return poses, via


def residuals(
    edges: Sequence[Edge],
    ids: Sequence[int],
    poses: Sequence[np.ndarray | None],
    sqrt_info: Sequence[np.ndarray] | dict[int, np.ndarray] | None = None,
) -> dict[int, EdgeResidual]:
    """:class:`EdgeResidual` of each edge in ``ids`` whose two nodes have a pose (vectorised)."""
    ids = [k for k in ids if poses[edges[k].target] is not None]
    ids = [k for k in ids if poses[edges[k].source] is not None]
    if not ids:
        return {}
    Pi = np.array([poses[edges[k].target] for k in ids])
    Pj = np.array([poses[edges[k].source] for k in ids])
    T = np.array([edges[k].T_target_source for k in ids])
    rel = _inverse(Pi) @ Pj  # the adjusted T_target_source
    D = _inverse(T) @ rel
    xi = se3_log(D)
    if sqrt_info is None:
        sqrt_info = {k: sqrt_information(edges[k].covariance) for k in ids}
    R = np.array([sqrt_info[k] for k in ids])
    chi2 = np.einsum("nij,nj->ni", R, xi)
    chi2 = np.einsum("ni,ni->n", chi2, chi2)
    deg = np.degrees(np.linalg.norm(xi[:, :3], axis=1))  # the angle of the rotation of D
    dt = np.linalg.norm(rel[:, :3, 3] - T[:, :3, 3], axis=1)
    return {k: EdgeResidual(float(chi2[n]), float(deg[n]), float(dt[n])) for n, k in enumerate(ids)}


def _inverse(T: np.ndarray) -> np.ndarray:
    """Inverses of (N,4,4) rigid transforms."""
    out = np.zeros_like(T)
    Rt = np.transpose(T[:, :3, :3], (0, 2, 1))
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", Rt, T[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out
