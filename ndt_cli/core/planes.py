"""Local planes of 3D points: the normal and planarity of each point's neighbourhood (Numba),
with a plain-numpy twin that the tests compare.

The neighbourhood of point i is the rows ``idx[i]`` of ``data`` (the k nearest, any
frame, metres). Its covariance (divided by k) has eigenvalues w0 <= w1 <= w2; the normal is the
unit eigenvector of w0 (its sign is arbitrary: ICP's point-to-plane terms and the levelling do
not depend on it), the planarity ``1 - w0 / w1`` is near 1 on a plane and near 0 on a line's or
a blob's points. The kernel diagonalises each 3x3 matrix by Jacobi rotations, exact to rounding;
numpy's batched ``eigh`` on (n,3,3) arrays costs several times more than the whole kernel.
"""

from __future__ import annotations

import numba
import numpy as np

_MAX_SWEEPS = 50  # Jacobi on a 3x3 matrix converges to rounding in about five


@numba.njit(cache=True, nogil=True)
def _eigen3(A, V):  # pragma: no cover - compiled
    """Diagonalise the symmetric 3x3 ``A`` in place by cyclic Jacobi rotations (eigenvalues on
    its diagonal); ``V`` ends with the unit eigenvectors as columns. One function with the
    rotation inline: Numba compiles it in a fraction of the time of nested calls."""
    for r in range(3):
        for c in range(3):
            V[r, c] = 1.0 if r == c else 0.0
    for _ in range(_MAX_SWEEPS):
        off = abs(A[0, 1]) + abs(A[0, 2]) + abs(A[1, 2])
        if off <= 1e-300 or off <= 1e-17 * (abs(A[0, 0]) + abs(A[1, 1]) + abs(A[2, 2])):
            return
        for pair in range(3):  # (0, 1), (0, 2), (1, 2)
            p = 0 if pair < 2 else 1
            q = 1 if pair == 0 else 2
            apq = A[p, q]
            if apq == 0.0:
                continue
            theta = (A[q, q] - A[p, p]) / (2.0 * apq)
            t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
            if theta < 0.0:
                t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            for r in range(3):  # A J: columns p and q
                arp = A[r, p]
                arq = A[r, q]
                A[r, p] = c * arp - s * arq
                A[r, q] = s * arp + c * arq
            for r in range(3):  # J^T (A J): rows p and q
                apr = A[p, r]
                aqr = A[q, r]
                A[p, r] = c * apr - s * aqr
                A[q, r] = s * apr + c * aqr
            A[p, q] = 0.0
            A[q, p] = 0.0
            for r in range(3):  # V J
                vrp = V[r, p]
                vrq = V[r, q]
                V[r, p] = c * vrp - s * vrq
                V[r, q] = s * vrp + c * vrq


@numba.njit(cache=True, nogil=True)
def _local_planes(data, idx, normal, planarity):  # pragma: no cover - compiled
    n, k = idx.shape
    A = np.empty((3, 3))
    V = np.empty((3, 3))
    for i in range(n):
        m0 = m1 = m2 = 0.0
        for j in range(k):
            p = idx[i, j]
            m0 += data[p, 0]
            m1 += data[p, 1]
            m2 += data[p, 2]
        m0 /= k
        m1 /= k
        m2 /= k
        c00 = c01 = c02 = c11 = c12 = c22 = 0.0
        for j in range(k):
            p = idx[i, j]
            d0 = data[p, 0] - m0
            d1 = data[p, 1] - m1
            d2 = data[p, 2] - m2
            c00 += d0 * d0
            c01 += d0 * d1
            c02 += d0 * d2
            c11 += d1 * d1
            c12 += d1 * d2
            c22 += d2 * d2
        A[0, 0] = c00 / k
        A[0, 1] = A[1, 0] = c01 / k
        A[0, 2] = A[2, 0] = c02 / k
        A[1, 1] = c11 / k
        A[1, 2] = A[2, 1] = c12 / k
        A[2, 2] = c22 / k
        _eigen3(A, V)
        lo = 0  # the smallest eigenvalue, then the middle one
        if A[1, 1] < A[lo, lo]:
            lo = 1
        if A[2, 2] < A[lo, lo]:
            lo = 2
        a, b = (lo + 1) % 3, (lo + 2) % 3
        mid = a if A[a, a] <= A[b, b] else b
        for r in range(3):
            normal[i, r] = V[r, lo]
        planarity[i] = 1.0 - A[lo, lo] / max(A[mid, mid], 1e-12)


def local_planes(data: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,3) unit normals and (n,) planarities of the neighbourhoods ``data[idx[i]]``: ``data``
    (m,3) points in metres, ``idx`` (n,k) row indices into it."""
    pts = np.ascontiguousarray(data, dtype=np.float64)
    rows = np.ascontiguousarray(idx, dtype=np.int64)
    normal, planarity = np.empty((len(rows), 3)), np.empty(len(rows))
    if len(rows):
        _local_planes(pts, rows, normal, planarity)
    return normal, planarity


def local_planes_numpy(data: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plain-numpy twin of :func:`local_planes` (numpy's ``eigh``; normals' signs may differ)."""
    nb = np.asarray(data, dtype=np.float64)[idx]
    d = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", d, d) / idx.shape[1]
    w, V = np.linalg.eigh(cov)
    return V[:, :, 0], 1.0 - w[:, 0] / np.maximum(w[:, 1], 1e-12)
