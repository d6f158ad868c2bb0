"""Point-to-plane ICP refinement of an NDT result in full 6-DOF (the paper's suggested last step).

Works on voxel-thinned 3D points in the target's reduced frame (metres). Target normals come
from the local covariance of each point's neighbours; residuals are point-to-plane distances,
weighted by Huber's function; the correspondence distance shrinks from ``max_distance`` to
``min_distance``. Vectorised with scipy's cKDTree; no per-point Python loops.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

_MIN_PLANARITY = 0.7  # target points whose neighbourhood is not clearly planar are not used


@dataclass(frozen=True)
class IcpResult:
    """Refined 4x4 (source to target, the frames of the inputs), RMS of the inlier point-to-plane
    distances (m), inlier count, iterations, and the eigenvalues of the 6x6 normal matrix
    (rotation vector rad, translation m) at the solution: a small one means a weak direction."""

    T: np.ndarray
    rms: float
    inliers: int
    iterations: int
    hessian_eigenvalues: np.ndarray


def voxel_thin(points: np.ndarray, voxel: float) -> np.ndarray:
    """One point (the centroid) per ``voxel`` metre cube."""
    ijk = np.floor(points / voxel).astype(np.int64)
    ijk -= ijk.min(axis=0)
    dims = ijk.max(axis=0) + 1
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    out = np.column_stack([np.bincount(inverse, weights=points[:, k]) for k in range(3)])
    return out / counts[:, None]


def normals(points: np.ndarray, tree: cKDTree, k: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals from the covariance of each point's ``k`` neighbours, and a planarity in
    [0, 1] (1 - smallest/middle eigenvalue) to drop points without a clear plane."""
    _, idx = tree.query(points, k=k)
    nb = points[idx]
    d = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", d, d) / k
    w, V = np.linalg.eigh(cov)
    return V[:, :, 0], 1.0 - w[:, 0] / np.maximum(w[:, 1], 1e-12)


def icp(
    target: np.ndarray,
    source: np.ndarray,
    T0: np.ndarray,
    *,
    voxel: float = 0.1,
    max_distance: float = 1.0,
    min_distance: float = 0.1,
    iterations: int = 40,
    huber: float = 0.02,
    max_source_points: int = 20_000,
) -> IcpResult:
    """Refine ``T0`` (source -> target) by robust point-to-plane ICP."""
    tgt = voxel_thin(target, voxel)
    src = voxel_thin(source, voxel)
    src = src[:: max(1, len(src) // max_source_points)]  # a regular stride: deterministic
    tree = cKDTree(tgt)
    n, planarity = normals(tgt, tree)
    T = np.array(T0, dtype=float)
    dist = max_distance
    it = 0
    H = np.zeros((6, 6))
    rms, inliers = float("nan"), 0
    for it in range(1, iterations + 1):  # noqa: B007
        p = src @ T[:3, :3].T + T[:3, 3]
        d, j = tree.query(p, distance_upper_bound=dist)
        ok = np.isfinite(d)
        ok[ok] &= planarity[j[ok]] > _MIN_PLANARITY
        if ok.sum() < 6:
            break
        pi, ni = p[ok], n[j[ok]]
        r = np.einsum("ij,ij->i", pi - tgt[j[ok]], ni)
        w = np.where(np.abs(r) <= huber, 1.0, huber / np.maximum(np.abs(r), 1e-12))
        J = np.column_stack([np.cross(pi, ni), ni])
        H = (J * w[:, None]).T @ J
        g = (J * w[:, None]).T @ r
        x = -np.linalg.solve(H + 1e-9 * np.eye(6), g)
        dT = np.eye(4)
        dT[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
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
    return IcpResult(T, rms, inliers, it, np.linalg.eigvalsh(H))
