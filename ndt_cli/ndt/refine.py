"""Point-to-plane ICP refinement of an NDT result in full 6-DOF (the paper's suggested last step).

Works on voxel-thinned 3D points in the target's reduced frame (metres). Target normals come
from the local covariance of each point's neighbours; residuals are point-to-plane distances,
weighted by Huber's function; the correspondence distance shrinks from ``max_distance`` to
``min_distance``. Correspondences and neighbourhoods come from a grid of the target's points
(:mod:`ndt_cli.core.neighbours`, exact nearest neighbours); no per-point Python loops.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ndt_cli.config.schema import RefineConfig
from ndt_cli.core.geometry import SURFACES, Surfaces, normals, voxel_thin
from ndt_cli.core.transforms import rotation_from_vector, transform_errors, translation

_MIN_PLANARITY = 0.7  # target points whose neighbourhood is not clearly planar are not used
# a planar source point is paired only with a target point whose normal is within 30 degrees
_COMPATIBLE = np.cos(np.radians(30.0))
FACING_MARGIN = 0.1  # m: a scanner nearer a surface's plane than this sees it edge-on


def facing(q: np.ndarray, n: np.ndarray, seen_from: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Per target point ``q`` (N,3) with unit normal ``n`` (either sign): whether the other
    scanner (at ``other``) stands on the side of the surface that this scanner (at
    ``seen_from``) saw, or within :data:`FACING_MARGIN` m of its plane. Where it does not,
    the two scans saw opposite faces (of a thin wall, a trunk, a door leaf), which are
    centimetres apart: matching them would shift the pose by the wall's thickness."""
    a = np.einsum("ij,ij->i", n, seen_from - q)
    b = np.einsum("ij,ij->i", n, other - q)
    return (a * b > 0) | (np.minimum(np.abs(a), np.abs(b)) < FACING_MARGIN)


@dataclass(frozen=True)
class IcpResult:
    """Refined 4x4 (source to target, the frames of the inputs), RMS of the inlier point-to-plane
    distances (m), inlier count, iterations, the 6x6 normal matrix ``hessian`` of the weighted
    point-to-plane residuals at the solution (rotation vector rad about the centroid of the
    matched points, then translation m; axes of the inputs), and ``overlap``: the share of the
    (thinned) source points with a target point within ``overlap_distance`` after alignment;
    ``centroid``: the point the rotation of ``hessian`` is about (inputs' frame, m)."""

    T: np.ndarray
    rms: float
    inliers: int
    iterations: int
    hessian: np.ndarray
    overlap: float
    centroid: np.ndarray = field(default_factory=lambda: np.zeros(3))  # of the matched points

    @property
    def hessian_eigenvalues(self) -> np.ndarray:
        """Eigenvalues of :attr:`hessian`, ascending (units mix rad and m)."""
        return np.linalg.eigvalsh(self.hessian)

    def weakest_translation(self) -> tuple[np.ndarray, float]:
        """Least constrained translation direction (unit 3-vector) and the ratio of the smallest
        to the largest eigenvalue of the translation information once rotation is free (the
        Schur complement of the rotation block): near 0 means a shift along the direction
        barely changes the residuals, as along a straight corridor."""
        H = self.hessian
        Hrr, Hrt, Htt = H[:3, :3], H[:3, 3:], H[3:, 3:]
        S = Htt - Hrt.T @ np.linalg.solve(Hrr + 1e-12 * np.eye(3), Hrt)
        w, V = np.linalg.eigh(0.5 * (S + S.T))
        return V[:, 0], float(w[0] / w[-1]) if w[-1] > 0 else 0.0


class _Normals:
    """Normals and planarity of ``points`` (from their neighbours in ``grid``), computed for
    the points asked for only, once each."""

    def __init__(self, points: np.ndarray, grid: object, surfaces: Surfaces) -> None:
        self.points, self.grid, self.surfaces = points, grid, surfaces
        self.n = np.zeros((len(points), 3))
        self.planarity = np.full(len(points), np.nan)  # NaN: not computed yet

    def at(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(normals, planarity) of the points ``idx``."""
        need = np.unique(idx[np.isnan(self.planarity[idx])])
        if len(need):
            found = normals(self.points[need], self.grid, surfaces=self.surfaces)
            self.n[need], self.planarity[need] = found
        return self.n[idx], self.planarity[idx]


class _Matcher:
    """Pairs of source and target points that may be matched: the nearest target point within
    a distance, on a clearly planar surface, that the source point's own normal (where planar)
    and the scanners' sides (when known, :func:`facing`) agree with. Frames of the inputs."""

    def __init__(
        self,
        tgt: np.ndarray,
        src_all: np.ndarray,
        stride: int,
        cell: float,
        surfaces: Surfaces,
        scanners: tuple[np.ndarray, np.ndarray] | None,
    ) -> None:
        self.tgt, self.stride, self.surfaces, self.scanners = tgt, stride, surfaces, scanners
        self.grid = surfaces.grid(tgt, cell)
        self.tgt_normals = _Normals(tgt, self.grid, surfaces)
        self.src_normals = _Normals(src_all, surfaces.grid(src_all, cell), surfaces)

    def pairs(
        self, p: np.ndarray, T: np.ndarray, dist: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For the source points ``p`` (moved by ``T``, the target's frame): which are paired,
        and the target index and unit normal of each one paired."""
        d, j = self.surfaces.neighbours.nearest(self.grid, p, dist)
        ok = np.isfinite(d)
        near = j[ok]
        n_t, planar_t = self.tgt_normals.at(near)
        n_s, planar_s = self.src_normals.at(np.flatnonzero(ok) * self.stride)
        alike = np.abs(np.einsum("ij,ij->i", n_s @ T[:3, :3].T, n_t)) > _COMPATIBLE
        keep = (planar_t > _MIN_PLANARITY) & ((planar_s <= _MIN_PLANARITY) | alike)
        if self.scanners is not None:
            seen_by_source = T[:3, :3] @ self.scanners[1] + T[:3, 3]
            keep &= facing(self.tgt[near], n_t, self.scanners[0], seen_by_source)
        ok[ok] = keep
        return ok, near[keep], n_t[keep]


def icp(
    target: np.ndarray,
    source: np.ndarray,
    T0: np.ndarray,
    *,
    voxel: float | None = 0.1,
    spacing: float = 0.1,
    max_distance: float = 1.0,
    min_distance: float = 0.1,
    iterations: int = 40,
    huber: float = 0.02,
    max_source_points: int = 20_000,
    overlap_distance: float = 0.2,
    surfaces: Surfaces = SURFACES,
    scanners: tuple[np.ndarray, np.ndarray] | None = None,
) -> IcpResult:
    """Refine ``T0`` (source -> target) by robust point-to-plane ICP. ``voxel=None``: the
    points are thinned already, to about ``spacing`` metres (it sizes the target's grid).
    Target normals are computed for the points ICP reaches only. ``scanners``: the target's
    scanner in the target's frame and the source's in the source's (m); when given, a pair
    whose surface the two scanners saw from opposite sides is not matched (:func:`facing`)."""
    tgt = target if voxel is None else voxel_thin(target, voxel)
    src_all = source if voxel is None else voxel_thin(source, voxel)
    stride = max(1, len(src_all) // max_source_points)  # a regular stride: deterministic
    src = src_all[::stride]
    cell = spacing if voxel is None else voxel
    matcher = _Matcher(tgt, src_all, stride, cell, surfaces, scanners)
    T = np.array(T0, dtype=float)
    dist = max_distance
    it = 0
    H = np.zeros((6, 6))
    rms, inliers = float("nan"), 0
    pi = ni = w = np.zeros((0, 3))
    for it in range(1, iterations + 1):  # noqa: B007
        p = src @ T[:3, :3].T + T[:3, 3]
        ok, j, n = matcher.pairs(p, T, dist)
        if ok.sum() < 6:
            break
        pi, ni = p[ok], n
        r = np.einsum("ij,ij->i", pi - tgt[j], ni)
        w = np.where(np.abs(r) <= huber, 1.0, huber / np.maximum(np.abs(r), 1e-12))
        J = np.column_stack([np.cross(pi, ni), ni])
        H = (J * w[:, None]).T @ J
        g = (J * w[:, None]).T @ r
        x = -np.linalg.solve(H + 1e-9 * np.eye(6), g)
        dT = np.eye(4)
        dT[:3, :3] = rotation_from_vector(x[:3])
        dT[:3, 3] = x[3:]
        T = dT @ T
        inlier = np.abs(r) <= 3 * huber
        rms, inliers = (
            float(np.sqrt(np.mean(r[inlier] ** 2))) if inlier.any() else rms,
            int(inlier.sum()),
        )
        dist = max(min_distance, 0.7 * dist)
        if np.linalg.norm(x[:3]) < 1e-6 and np.linalg.norm(x[3:]) < 1e-5 and dist == min_distance:
            break
    centroid = pi.mean(axis=0) if len(pi) else np.zeros(3)
    if len(pi):  # the curvature about the matched points' centroid: independent of the frame
        J = np.column_stack([np.cross(pi - centroid, ni), ni])
        H = (J * w[:, None]).T @ J
    moved = src @ T[:3, :3].T + T[:3, 3]
    d, _ = surfaces.neighbours.nearest(matcher.grid, moved, overlap_distance)
    return IcpResult(T, rms, inliers, it, H, float(np.isfinite(d).mean()), centroid)


@dataclass(frozen=True)
class Rejection:
    """An ICP correction that was not applied (too large, or ICP found no fit): how far it
    would have moved the pose, m and degrees (the target's reduced frame)."""

    moved_m: float
    moved_deg: float

    def describe(self) -> str:
        """The warning a rejected correction gives."""
        return f"ICP refinement rejected (it moved {self.moved_m:.2f} m, {self.moved_deg:.2f} deg)"


@dataclass(frozen=True)
class Refinement:
    """``T_target_source`` after refinement (unchanged when ICP was not run or its correction
    was rejected), the ICP outcome (None when not run) and, when its correction was not
    applied, the :class:`Rejection` (None when it was, or ICP did not run)."""

    T: np.ndarray
    icp: IcpResult | None = None
    rejection: Rejection | None = None
    start: np.ndarray | None = None  # the pose refinement started from (the NDT result)

    @property
    def rejected(self) -> str:
        """The warning of a correction that was not applied ('' when it was, or no ICP)."""
        return "" if self.rejection is None else self.rejection.describe()


def refine_pose(
    target_points: np.ndarray | None,
    source_points: np.ndarray | None,
    target_reduction: np.ndarray,
    source_reduction: np.ndarray,
    T: np.ndarray,
    refine: RefineConfig,
    overlap_distance: float,
    surfaces: Surfaces = SURFACES,
    scanners: tuple[np.ndarray, np.ndarray] | None = None,
) -> Refinement:
    """ICP of the scans' thinned points (each minus its reduction point) from ``T``; a
    correction larger than ``refine.max_correction`` (m, or degrees) is not applied.
    ``scanners``: each scanner's position in its scan's frame (m), when known."""
    if target_points is None or source_points is None:
        return Refinement(T, start=T)
    T_red = translation(-target_reduction) @ T @ translation(source_reduction)
    res = icp(
        target_points,
        source_points,
        T_red,
        voxel=None,
        spacing=refine.voxel,
        max_distance=refine.max_distance,
        min_distance=refine.min_distance,
        huber=refine.huber,
        iterations=refine.iterations,
        overlap_distance=overlap_distance,
        surfaces=surfaces,
        scanners=None
        if scanners is None
        else (scanners[0] - target_reduction, scanners[1] - source_reduction),
    )
    moved_deg, moved_m = transform_errors(res.T, T_red)
    if (
        not np.isfinite(res.rms)
        or moved_m > refine.max_correction
        or moved_deg > refine.max_correction
    ):
        return Refinement(T, res, Rejection(moved_m, moved_deg), T)
    T_icp = translation(target_reduction) @ res.T @ translation(-source_reduction)
    return Refinement(T_icp, res, start=T)
