"""Branch-and-bound kernels of the global search (Numba) and their plain-numpy twins.

A *node* is a block of ``2^h x 2^h`` lattice translations ``(i0 .. i0+2^h-1, j0 .. j0+2^h-1)`` at
one yaw. Its bound is ``sum_k P_h[slice_k, qx_k + i0, qy_k + j0]``: ``P_h`` is the field max-pooled
over ``2^h x 2^h`` pixels (level ``h`` of the pyramid, :func:`ndt_cli.ndt.bnb.max_pyramid`) and
``(qx_k, qy_k)`` the pixel of source point ``k`` at that yaw and translation (0, 0). The kernels
read the pyramid as one flat integer array (uint8, or int16 where free space costs):
``flat[h * level_size + base_k + i0 * ny + j0]``, with ``base_k = (slice_k * nx + qx_k) * ny +
qy_k`` precomputed per yaw (every read is in bounds by construction). At ``h = 0`` the bound
is the exact score of the translation.

Everything here is integer arithmetic, so the Numba kernels and the numpy twins agree bit for
bit, and a round's tasks (one yaw each) are independent, so results do not depend on threads.

*Anchors* are up to K leaves (rows: score, yaw index, i, j) that are pairwise *separated*: more
than twice the exclusion apart in translation or in yaw. Any pose is then "the same" as at most
one anchor, so the K-th greedy distinct pick of the whole search scores at least the lowest
anchor: that is the pruning threshold (see :mod:`ndt_cli.ndt.bnb`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from ndt_cli.core.threads import parallel_for

POOL_CAP = 4096  # leaves a task records before its buffer overflows (it is then rerun larger)


@dataclass(frozen=True)
class Lattice:
    """What every task reads: the flat pyramid and the sizes of the search (all integers)."""

    flat: np.ndarray  # (levels * level_size,) uint8 or int16
    level_size: int  # slices * nx * ny
    ny: int
    top: int  # level of the root blocks
    last: int  # largest lattice index (2n)
    n_yaw: int
    r2_sep: int  # anchors differ by more than this squared lattice distance...
    yaw_sep: int  # ...or by more than this many yaw steps (cyclic)
    roots: np.ndarray  # (R, 2) int64 block starts (i0, j0) at level ``top``


@numba.njit(cache=True)
def insert_anchor(anchors, n, score, m, i, j, n_yaw, r2_sep, yaw_sep):  # pragma: no cover
    """Offer a leaf to the anchors (K,4) int64 holding ``n`` rows; returns the new count.

    A leaf separated from every anchor is added (or replaces the lowest when K are held and it
    scores higher); a leaf too close to exactly one anchor replaces it when it scores higher.
    The anchors stay pairwise separated and their lowest score never decreases.
    """
    near, hit = 0, -1
    for a in range(n):
        dm = abs(anchors[a, 1] - m) % n_yaw
        dm = min(dm, n_yaw - dm)
        di, dj = anchors[a, 2] - i, anchors[a, 3] - j
        if di * di + dj * dj <= r2_sep and dm <= yaw_sep:
            near += 1
            hit = a
    if near > 1:
        return n
    if near == 0 and n < anchors.shape[0]:
        hit, n, better = n, n + 1, True
    else:
        if near == 0:  # K held: the lowest anchor makes room
            hit = 0
            for a in range(1, n):
                if anchors[a, 0] < anchors[hit, 0]:
                    hit = a
        better = score > anchors[hit, 0]
    if better:
        anchors[hit, 0], anchors[hit, 1], anchors[hit, 2], anchors[hit, 3] = score, m, i, j
    return n


@numba.njit(cache=True)
def threshold(anchors, n):  # pragma: no cover
    """Pruning threshold: the lowest anchor score once K anchors are held, else 1 (> 0)."""
    if n < anchors.shape[0]:
        return np.int64(1)
    low = anchors[0, 0]
    for a in range(1, n):
        low = min(low, anchors[a, 0])
    return max(low, np.int64(1))


@numba.njit(cache=True)
def _bound(flat, start, base):  # pragma: no cover
    total = np.int64(0)
    for k in range(base.shape[0]):
        total += np.int64(flat[start + base[k]])
    return total


@numba.njit(cache=True)
def _children(flat, level_size, ny, base, h, i0, j0, last, theta, cb, ci, cj):  # pragma: no cover
    """Bounds of the (up to 4) children of a node that reach ``theta``, best first (ties: child
    order), in ``cb, ci, cj``; returns (kept, evaluated)."""
    step = 1 << (h - 1)
    start = (h - 1) * level_size
    kept = evaluated = 0
    for c in range(4):
        i, j = i0 + step * (c // 2), j0 + step * (c % 2)
        if i > last or j > last:
            continue
        v = _bound(flat, start + i * ny + j, base)
        evaluated += 1
        if v < theta:
            continue
        p = kept
        while p > 0 and cb[p - 1] < v:  # stable insertion, best first
            cb[p], ci[p], cj[p] = cb[p - 1], ci[p - 1], cj[p - 1]
            p -= 1
        cb[p], ci[p], cj[p] = v, i, j
        kept += 1
    return kept, evaluated


@numba.njit(cache=True)
def _search_yaw(
    flat,
    level_size,
    ny,
    top,
    last,
    n_yaw,
    r2_sep,
    yaw_sep,
    base,
    m,
    roots,
    rbound,
    anchors,
    na,
    pool,
):  # pragma: no cover
    """Depth-first, best-bound-first search of one yaw from its roots (sorted best first).

    Records every leaf reaching the current threshold in ``pool`` (rows beyond its length are
    counted only); returns (leaves recorded, nodes evaluated)."""
    anc = anchors.copy()
    theta = threshold(anc, na)
    size = roots.shape[0] + 4 * (top + 1)
    sh, si = np.empty(size, np.int64), np.empty(size, np.int64)
    sj, sb = np.empty(size, np.int64), np.empty(size, np.int64)
    cb, ci, cj = np.empty(4, np.int64), np.empty(4, np.int64), np.empty(4, np.int64)
    sp = count = nodes = 0
    for r in range(roots.shape[0] - 1, -1, -1):  # the best root on top of the stack
        sh[sp], si[sp], sj[sp], sb[sp] = top, roots[r, 0], roots[r, 1], rbound[r]
        sp += 1
    while sp > 0:
        sp -= 1
        h, i0, j0, b = sh[sp], si[sp], sj[sp], sb[sp]
        if b < theta:
            continue
        if h == 0:
            if count < pool.shape[0]:
                pool[count, 0], pool[count, 1], pool[count, 2], pool[count, 3] = b, m, i0, j0
            count += 1
            na = insert_anchor(anc, na, b, m, i0, j0, n_yaw, r2_sep, yaw_sep)
            theta = threshold(anc, na)
            continue
        kept, ev = _children(flat, level_size, ny, base, h, i0, j0, last, theta, cb, ci, cj)
        nodes += ev
        for c in range(kept - 1, -1, -1):
            sh[sp], si[sp], sj[sp], sb[sp] = h - 1, ci[c], cj[c], cb[c]
            sp += 1
    return count, nodes


@numba.njit(cache=True, nogil=True)
def _search_round(
    start,
    stop,
    flat,
    level_size,
    ny,
    top,
    last,
    n_yaw,
    r2_sep,
    yaw_sep,
    bases,
    yaws,
    roots,
    rbounds,
    orders,
    anchors,
    na,
    pools,
    counts,
    nodes,
):  # pragma: no cover
    """Tasks ``start .. stop-1`` of a round (one yaw each), each writing only its own rows of
    the outputs."""
    for t in range(start, stop):
        order = orders[t]
        c, e = _search_yaw(
            flat,
            level_size,
            ny,
            top,
            last,
            n_yaw,
            r2_sep,
            yaw_sep,
            bases[t],
            yaws[t],
            roots[order],
            rbounds[t][order],
            anchors,
            na,
            pools[t],
        )
        counts[t] = c
        nodes[t] = e


@numba.njit(cache=True, nogil=True)
def _root_bounds(start, stop, flat, level_size, ny, top, bases, roots, out):  # pragma: no cover
    """Bound of every root block (level ``top``) at yaws ``start .. stop-1``, into their rows
    of ``out`` (n_yaw, R)."""
    first = top * level_size
    for m in range(start, stop):
        for r in range(roots.shape[0]):
            out[m, r] = _bound(flat, first + roots[r, 0] * ny + roots[r, 1], bases[m])


def root_bounds(lat: Lattice, bases: np.ndarray) -> np.ndarray:
    """Bounds (n_yaw, R) int64 of every yaw's root blocks; ``bases`` (n_yaw, N) int64."""
    out = np.zeros((len(bases), len(lat.roots)), np.int64)
    if bases.shape[1]:
        args = (lat.flat, lat.level_size, lat.ny, lat.top, bases, lat.roots, out)
        parallel_for(_root_bounds, len(bases), *args)
    return out


def _round_args(lat: Lattice) -> tuple:
    return (lat.flat, lat.level_size, lat.ny, lat.top, lat.last, lat.n_yaw, lat.r2_sep, lat.yaw_sep)


def search_round(
    lat: Lattice,
    bases: np.ndarray,
    yaws: np.ndarray,
    rbounds: np.ndarray,
    anchors: np.ndarray,
    n_anchors: int,
) -> tuple[list[np.ndarray], np.ndarray]:
    """Search the yaws ``yaws`` (B,) in parallel, each from the anchors (K,4) int64 as they were
    at the round's start. ``bases`` (B,N) and root bounds (B,R) belong to those yaws.

    Returns per yaw its recorded leaves (n,4) int64 (score, yaw index, i, j) in search order,
    and the nodes (B,) each evaluated. A yaw whose leaves overflow :data:`POOL_CAP` is rerun
    alone with room for all of them (same inputs, same result)."""
    orders = np.argsort(-rbounds, axis=1, kind="stable")
    B = len(yaws)
    pools = np.empty((B, POOL_CAP, 4), np.int64)
    counts, nodes = np.zeros(B, np.int64), np.zeros(B, np.int64)
    args = (*_round_args(lat), bases, yaws, lat.roots, rbounds, orders, anchors, n_anchors)
    parallel_for(_search_round, B, *args, pools, counts, nodes)
    leaves = [pools[t, : counts[t]].copy() for t in range(B)]
    for t in np.flatnonzero(counts > POOL_CAP):
        big = np.zeros((1, counts[t], 4), np.int64)
        one = (bases[t : t + 1], yaws[t : t + 1], lat.roots, rbounds[t : t + 1], orders[t : t + 1])
        _search_round(
            0,
            1,
            *_round_args(lat),
            *one,
            anchors,
            n_anchors,
            big,
            counts[t : t + 1],
            nodes[t : t + 1],
        )
        leaves[t] = big[0]
    return leaves, nodes


# ----------------------------------------------------------------------------- numpy twins


def _bound_numpy(flat: np.ndarray, start: int, base: np.ndarray) -> int:
    return int(flat[start + base].sum(dtype=np.int64))


def root_bounds_numpy(lat: Lattice, bases: np.ndarray) -> np.ndarray:
    """Plain-numpy twin of :func:`root_bounds`."""
    start = lat.top * lat.level_size
    offsets = lat.roots[:, 0] * lat.ny + lat.roots[:, 1]
    out = np.zeros((len(bases), len(lat.roots)), np.int64)
    for m, base in enumerate(bases):
        out[m] = [_bound_numpy(lat.flat, start + o, base) for o in offsets]
    return out


def _children_numpy(
    lat: Lattice, base: np.ndarray, h: int, i0: int, j0: int, theta: int
) -> tuple[list[tuple[int, int, int]], int]:
    """Twin of ``_children``: the kept children (bound, i, j) best first, and the count."""
    step, start = 1 << (h - 1), (h - 1) * lat.level_size
    found = []
    for c in range(4):
        i, j = i0 + step * (c // 2), j0 + step * (c % 2)
        if i <= lat.last and j <= lat.last:
            found.append((_bound_numpy(lat.flat, start + i * lat.ny + j, base), i, j))
    kept = sorted((f for f in found if f[0] >= theta), key=lambda f: -f[0])  # stable
    return kept, len(found)


def _search_yaw_numpy(
    lat: Lattice,
    base: np.ndarray,
    m: int,
    rbound: np.ndarray,
    anchors: np.ndarray,
    n_anchors: int,
) -> tuple[np.ndarray, int]:
    """Twin of ``_search_yaw`` (the anchors' rules run as plain Python)."""
    insert, limit = insert_anchor.py_func, threshold.py_func
    anc, na = anchors.copy(), n_anchors
    theta = limit(anc, na)
    order = np.argsort(-rbound, kind="stable")
    stack = [(lat.top, int(lat.roots[r, 0]), int(lat.roots[r, 1]), int(rbound[r])) for r in order]
    stack.reverse()
    leaves, nodes = [], 0
    while stack:
        h, i0, j0, b = stack.pop()
        if b < theta:
            continue
        if h == 0:
            leaves.append((b, m, i0, j0))
            na = insert(anc, na, b, m, i0, j0, lat.n_yaw, lat.r2_sep, lat.yaw_sep)
            theta = limit(anc, na)
            continue
        kept, evaluated = _children_numpy(lat, base, h, i0, j0, theta)
        nodes += evaluated
        stack.extend((h - 1, i, j, v) for v, i, j in reversed(kept))
    return np.array(leaves, np.int64).reshape(-1, 4), nodes


def search_round_numpy(
    lat: Lattice,
    bases: np.ndarray,
    yaws: np.ndarray,
    rbounds: np.ndarray,
    anchors: np.ndarray,
    n_anchors: int,
) -> tuple[list[np.ndarray], np.ndarray]:
    """Plain-numpy twin of :func:`search_round` (one yaw after the other)."""
    out = [
        _search_yaw_numpy(lat, bases[t], int(yaws[t]), rbounds[t], anchors, n_anchors)
        for t in range(len(yaws))
    ]
    return [leaves for leaves, _ in out], np.array([n for _, n in out], np.int64)


@numba.njit(cache=True)
def feed_anchors(anchors, n, leaves, n_yaw, r2_sep, yaw_sep):  # pragma: no cover
    """Offer the leaves (M,4) int64 to the anchors in order; returns the new anchor count."""
    for r in range(leaves.shape[0]):
        s, m, i, j = leaves[r, 0], leaves[r, 1], leaves[r, 2], leaves[r, 3]
        n = insert_anchor(anchors, n, s, m, i, j, n_yaw, r2_sep, yaw_sep)
    return n


def feed_anchors_numpy(
    anchors: np.ndarray, n: int, leaves: np.ndarray, n_yaw: int, r2_sep: int, yaw_sep: int
) -> int:
    """Plain-Python twin of :func:`feed_anchors`."""
    for s, m, i, j in leaves.tolist():
        n = insert_anchor.py_func(anchors, n, s, m, i, j, n_yaw, r2_sep, yaw_sep)
    return n


@dataclass(frozen=True)
class SearchKernels:
    """One implementation of the branch-and-bound kernels: Numba or the numpy twins."""

    name: str
    root_bounds: Callable[[Lattice, np.ndarray], np.ndarray]
    search_round: Callable[..., tuple[list[np.ndarray], np.ndarray]]
    feed_anchors: Callable[..., int]

    def __repr__(self) -> str:
        return f"SearchKernels({self.name})"


NUMBA = SearchKernels("numba", root_bounds, search_round, feed_anchors)
NUMPY = SearchKernels("numpy", root_bounds_numpy, search_round_numpy, feed_anchors_numpy)
