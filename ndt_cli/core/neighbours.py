"""Exact nearest neighbours of 3D points on a grid of cubic cells (Numba), with numpy twins.

The points whose neighbours the method needs are thinned to one per voxel (ICP's 0.1 m, the
levelling's 0.25 m), so their density is bounded. A query looks at the grid's cells shell by
shell around its own, skipping cells farther than what it has found, until no unseen cell can
hold anything nearer: the answer is that of an exhaustive search, and that of scipy's k-d tree
(the tests hold them equal). Ties in distance go to the lower input index. With cells ten
voxels wide (:data:`~ndt_cli.core.geometry.CELLS_PER_VOXEL`, the fastest on scans), a grid of a
scan's 0.1 m points builds in a third of the time of scipy's k-d tree and ICP as a whole takes
two thirds; and no process of the method needs to import scipy.

- :func:`nearest`: the nearest point closer than a bound (ICP's correspondences).
- :func:`knn`: the k nearest points in order of distance (the neighbourhoods of normals).

``NUMBA`` builds the grid with a hash table of its cells (:func:`grid`) and queries it with a
kernel; ``NUMPY``, the twins, sorts the cells' keys and searches them (:func:`grid_numpy`);
each queries only grids it built. Queries run in threads over blocks of queries
(:func:`~ndt_cli.core.threads.parallel_for`); every query writes only its own row, so results do
not depend on the number of threads. Coordinates are metres, any frame, within 2**20 cells of
its origin (a reduced frame).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.core.threads import parallel_for

OFFSET = 1 << 20  # cell indices are packed as 21-bit fields: +-2**20 cells around the origin
_FIELD = (1 << 21) - 1
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: 2**64 / golden ratio
_NONE = np.int64(-1)


@dataclass(frozen=True, repr=False)
class CellGrid:
    """Points grouped by cubic cells of ``cell`` metres (see the module docstring).

    ``data`` (N,3) float64: the points as given (indices refer to its rows); ``points`` the same
    points grouped by cell, ``order`` the row of ``data`` of each; the points of the m-th cell
    are rows ``starts[m] .. starts[m+1]-1``. ``keys`` (M,) int64: each cell's packed indices.
    ``table`` (T,2) int64: an open-addressing hash table of (key, m), empty for the numpy twin,
    which searches ``keys`` (then ascending). ``lo``, ``hi`` (3,): the range of cell indices
    that hold points."""

    data: np.ndarray
    points: np.ndarray
    order: np.ndarray
    keys: np.ndarray
    starts: np.ndarray
    table: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    cell: float

    def __len__(self) -> int:
        return len(self.data)

    def __repr__(self) -> str:
        return f"CellGrid({len(self)} points in {len(self.keys)} cells of {self.cell:g} m)"


def _cells(points: np.ndarray, cell: float) -> np.ndarray:
    """(N,3) int64 cell indices of (N,3) points, shifted by :data:`OFFSET`; a ValueError when a
    point lies outside the packable range."""
    ijk = np.floor(points / cell).astype(np.int64) + OFFSET
    if len(ijk) and (ijk.min() < 0 or ijk.max() > _FIELD):
        raise ValueError("points too far from the origin for a neighbour grid")
    return ijk


def _pack(ijk: np.ndarray) -> np.ndarray:
    return (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]


@numba.njit(cache=True, nogil=True, inline="always")
def _slot(key, mask):  # pragma: no cover - compiled
    return np.int64((np.uint64(key) * _GOLDEN) >> np.uint64(20)) & mask


@numba.njit(cache=True, nogil=True)
def _build(keys, table, slot_of, counts):  # pragma: no cover - compiled
    """Insert every point's cell key into ``table``: the m-th new key gets m; ``slot_of[p]``
    is the cell of point p and ``counts[m+1]`` its number of points. Returns M."""
    mask = table.shape[0] - 1
    m = 0
    for p in range(keys.shape[0]):
        key = keys[p]
        b = _slot(key, mask)
        while table[b, 0] != _NONE and table[b, 0] != key:
            b = (b + 1) & mask
        if table[b, 0] == _NONE:
            table[b, 0] = key
            table[b, 1] = m
            m += 1
        slot_of[p] = table[b, 1]
        counts[table[b, 1] + 1] += 1
    return m


@numba.njit(cache=True, nogil=True)
def _scatter(data, slot_of, fill, points, order):  # pragma: no cover - compiled
    """Points grouped by cell, each cell's points in input order."""
    for p in range(data.shape[0]):
        row = fill[slot_of[p]]
        fill[slot_of[p]] += 1
        order[row] = p
        points[row, 0] = data[p, 0]
        points[row, 1] = data[p, 1]
        points[row, 2] = data[p, 2]


def grid(data: np.ndarray, cell: float) -> CellGrid:
    """A :class:`CellGrid` of (N,3) points in cells of ``cell`` metres (N >= 0)."""
    data = np.ascontiguousarray(data, dtype=np.float64).reshape(-1, 3)
    ijk = _cells(data, cell)
    keys = _pack(ijk)
    table = np.full((_table_size(len(data)), 2), _NONE, np.int64)  # as many cells as points
    slot_of, counts = np.empty(len(data), np.int64), np.zeros(len(data) + 1, np.int64)
    m = _build(keys, table, slot_of, counts)
    starts = np.cumsum(counts[: m + 1])
    points, order = np.empty_like(data), np.empty(len(data), np.int64)
    _scatter(data, slot_of, starts[:-1].copy(), points, order)
    cell_keys = np.empty(m, np.int64)
    used = table[:, 0] != _NONE
    cell_keys[table[used, 1]] = table[used, 0]
    compact = np.full((_table_size(m), 2), _NONE, np.int64)  # sized to the cells: in cache
    _build(cell_keys, compact, np.empty(m, np.int64), np.zeros(m + 1, np.int64))
    return CellGrid(data, points, order, cell_keys, starts, compact, *_range(ijk), float(cell))


def _table_size(n: int) -> int:
    """Slots of a hash table for ``n`` keys: a power of two, at most half full."""
    return 1 << max(4, int(2 * n).bit_length())


def grid_numpy(data: np.ndarray, cell: float) -> CellGrid:
    """Plain-numpy twin of :func:`grid`: the cells in ascending key order, no hash table."""
    data = np.ascontiguousarray(data, dtype=np.float64).reshape(-1, 3)
    ijk = _cells(data, cell)
    keys = _pack(ijk)
    order = np.argsort(keys, kind="stable")
    cell_keys, counts = np.unique(keys[order], return_counts=True)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    empty = np.empty((0, 2), np.int64)
    return CellGrid(data, data[order], order, cell_keys, starts, empty, *_range(ijk), float(cell))


def _range(ijk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The range of cell indices that hold points (empty: lo > hi)."""
    if len(ijk) == 0:
        return np.full(3, OFFSET, np.int64), np.full(3, OFFSET - 1, np.int64)
    return column_bounds(ijk)


# ------------------------------------------------------------------------------ queries (Numba)


@numba.njit(cache=True, nogil=True, inline="always")
def _find(table, key):  # pragma: no cover - compiled
    """The cell number of ``key``, or -1."""
    mask = table.shape[0] - 1
    b = _slot(key, mask)
    while True:
        k = table[b, 0]
        if k == key:
            return table[b, 1]
        if k == _NONE:
            return _NONE
        b = (b + 1) & mask


@numba.njit(cache=True, nogil=True, inline="always")
def _gap(v, f, cell):  # pragma: no cover - compiled
    """Distance from coordinate ``v`` to the cell ``[f, f + 1) * cell`` along one axis."""
    low = f * cell
    if v < low:
        return low - v
    high = low + cell
    return v - high if v > high else 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def _reach(c, lo, hi):  # pragma: no cover - compiled
    """The first and the last shell (Chebyshev distance in cells from cell ``c``) that meet the
    occupied range ``lo .. hi``."""
    first = last = 0
    for a in range(3):
        first = max(first, lo[a] - c[a], c[a] - hi[a])
        last = max(last, c[a] - lo[a], hi[a] - c[a])
    return max(first, 0), last


@numba.njit(cache=True, nogil=True, inline="always")
def _unseen(x, f, s, cell):  # pragma: no cover - compiled
    """Squared distance from ``x`` (in cell ``f``) to the nearest point outside the cells
    within ``s`` of ``f``: nothing beyond shell ``s`` is nearer."""
    g = np.inf
    for a in range(3):
        g = min(g, x[a] - (f[a] - s) * cell, (f[a] + s + 1) * cell - x[a])
    return g * g


@numba.njit(cache=True, nogil=True, inline="always")
def _take(d2, p, dist, index, cnt):  # pragma: no cover - compiled
    """Insert (d2, p) into the sorted ``dist``/``index`` (distance, then index ascending) that
    hold ``cnt`` of at most ``len(dist)``; returns the new count."""
    k = dist.shape[0]
    j = min(cnt, k - 1)  # full: the last (the farthest) drops out
    while j > 0 and (d2 < dist[j - 1] or (d2 == dist[j - 1] and p < index[j - 1])):
        dist[j], index[j] = dist[j - 1], index[j - 1]
        j -= 1
    dist[j], index[j] = d2, p
    return min(cnt + 1, k)


@numba.njit(cache=True, nogil=True, inline="always")
def _better(d2, p, dist, index, cnt):  # pragma: no cover - compiled
    """Whether (d2, p) belongs among the ``cnt`` kept so far (at most ``len(dist)``)."""
    k = dist.shape[0]
    return cnt < k or d2 < dist[k - 1] or (d2 == dist[k - 1] and p < index[k - 1])


@numba.njit(cache=True, nogil=True, inline="always")
def _visit(m, x, b2, points, order, starts, d, idx, cnt):  # pragma: no cover - compiled
    """Offer the points of cell ``m`` (-1: none) to the query ``x``; returns the new count."""
    if m < 0:
        return cnt
    for r in range(starts[m], starts[m + 1]):
        e0 = points[r, 0] - x[0]
        e1 = points[r, 1] - x[1]
        e2 = points[r, 2] - x[2]
        d2 = e0 * e0 + e1 * e1 + e2 * e2
        if d2 < b2 and _better(d2, order[r], d, idx, cnt):
            cnt = _take(d2, order[r], d, idx, cnt)
    return cnt


@numba.njit(cache=True, nogil=True)
def _knn(
    start, stop, q, bound, points, order, starts, table, lo, hi, cell, dist, index
):  # pragma: no cover - compiled
    """Queries ``start .. stop-1``: the k = ``dist.shape[1]`` nearest points closer than
    ``bound``, shell by shell around the query's cell (only the cells in the occupied range
    ``lo .. hi``), skipping cells farther than the k-th found; a row ends with inf / N where
    fewer exist."""
    k, n, b2 = dist.shape[1], points.shape[0], bound * bound
    f, c = np.empty(3, np.int64), np.empty(3, np.int64)
    a0, a1 = np.empty(3, np.int64), np.empty(3, np.int64)
    for a in range(start, stop):
        x, d, idx = q[a], dist[a], index[a]
        d[:], idx[:] = np.inf, n
        for t in range(3):
            f[t] = np.int64(np.floor(x[t] / cell))
            c[t] = f[t] + OFFSET
        first, last = _reach(c, lo, hi)
        if bound < np.inf:
            last = min(last, np.int64(np.ceil(bound / cell)))
        cnt = 0
        for s in range(first, last + 1):
            for t in range(3):  # the shell's offsets that stay in the occupied range
                a0[t], a1[t] = max(-s, lo[t] - c[t]), min(s, hi[t] - c[t])
            for di in range(a0[0], a1[0] + 1):
                g0 = _gap(x[0], f[0] + di, cell) ** 2
                if g0 >= b2 or (cnt == k and g0 > d[k - 1]):
                    continue
                for dj in range(a0[1], a1[1] + 1):
                    g1 = g0 + _gap(x[1], f[1] + dj, cell) ** 2
                    if g1 >= b2 or (cnt == k and g1 > d[k - 1]):
                        continue
                    face = abs(di) == s or abs(dj) == s  # else only dk = -s and s
                    dk, step = (a0[2], 1) if face else (-s, 2 * s)
                    while dk <= a1[2]:
                        g2 = g1 + _gap(x[2], f[2] + dk, cell) ** 2
                        if dk >= a0[2] and g2 < b2 and (cnt < k or g2 <= d[k - 1]):
                            key = ((c[0] + di) << 42) | ((c[1] + dj) << 21) | (c[2] + dk)
                            cnt = _visit(
                                _find(table, key), x, b2, points, order, starts, d, idx, cnt
                            )
                        dk += step
            if cnt == k and d[k - 1] < _unseen(x, f, s, cell):
                break
        for j in range(cnt):
            d[j] = np.sqrt(d[j])


def knn(
    g: CellGrid, queries: np.ndarray, k: int, bound: float = np.inf
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest points of ``g`` to each (Q,3) query closer than ``bound`` metres,
    nearest first: distances (Q,k) float64 and row indices into ``g.data`` (Q,k) int64; where
    fewer exist the row ends with inf and ``len(g)`` (as scipy's ``cKDTree.query``)."""
    q = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
    dist, index = np.empty((len(q), k)), np.empty((len(q), k), np.int64)
    if len(q) and k > 0:
        args = (q, float(bound), g.points, g.order, g.starts, g.table, g.lo, g.hi, g.cell)
        parallel_for(_knn, len(q), *args, dist, index)
    return dist, index


def nearest(g: CellGrid, queries: np.ndarray, bound: float) -> tuple[np.ndarray, np.ndarray]:
    """The nearest point of ``g`` to each (Q,3) query closer than ``bound`` metres: distances
    (Q,) (inf where none) and row indices into ``g.data`` (``len(g)`` where none)."""
    dist, index = knn(g, queries, 1, bound)
    return dist[:, 0], index[:, 0]


# ------------------------------------------------------------------------ queries (numpy twins)


def knn_numpy(
    g: CellGrid, queries: np.ndarray, k: int, bound: float = np.inf
) -> tuple[np.ndarray, np.ndarray]:
    """Plain-numpy twin of :func:`knn` on a grid of :func:`grid_numpy`: the same shells of
    cells for all queries at once, each shell's candidates merged with those kept so far."""
    q = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, 3)
    d2 = np.full((len(q), k), np.inf)
    index = np.full((len(q), k), len(g), np.int64)
    f = np.floor(q / g.cell).astype(np.int64)
    c = f + OFFSET
    first = np.maximum(np.maximum(g.lo - c, c - g.hi).max(axis=1, initial=0), 0)
    last = np.maximum(c - g.lo, g.hi - c).max(axis=1, initial=0)
    if bound < np.inf:
        last = np.minimum(last, int(np.ceil(bound / g.cell)))
    todo = np.flatnonzero(first <= last) if k > 0 and len(g) else np.zeros(0, np.int64)
    s = 0
    while len(todo):
        _merge(d2, index, _shell_candidates(g, q, f, todo[first[todo] <= s], s, d2, bound), len(g))
        outside = _unseen_numpy(q[todo], f[todo], s, g.cell)
        done = (d2[todo, -1] < outside) | (last[todo] <= s)
        todo, s = todo[~done], s + 1
    return np.sqrt(d2), index


def _shell_offsets(s: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(n,3) int64 cell offsets at Chebyshev distance ``s`` within ``lo .. hi`` per axis: the
    six faces of the shell's cube, each cut to the range."""
    if s == 0:
        inside = (lo <= 0).all() and (hi >= 0).all()
        return np.zeros((1 if inside else 0, 3), np.int64)

    def span(axis: int, inner: bool) -> np.ndarray:
        edge = s - 1 if inner else s
        return np.arange(max(-edge, lo[axis]), min(edge, hi[axis]) + 1)

    faces = []
    for v in (-s, s):
        for axis in range(3):  # x faces whole, y faces inside x, z faces inside x and y
            if not lo[axis] <= v <= hi[axis]:
                continue
            spans = [span(b, inner=b < axis) for b in range(3)]
            spans[axis] = np.array([v])
            mesh = np.meshgrid(*spans, indexing="ij")
            faces.append(np.stack(mesh, axis=-1).reshape(-1, 3))
    return np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)


def _shell_candidates(
    g: CellGrid,
    q: np.ndarray,
    f: np.ndarray,
    rows: np.ndarray,
    s: int,
    d2: np.ndarray,
    bound: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(query, squared distance, point) of every point closer than ``bound`` in the cells of
    shell ``s`` around the queries ``rows``, skipping cells farther than their k-th kept."""
    if len(rows) == 0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
    found: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    c = f[rows] + OFFSET
    for off in _shell_offsets(s, (g.lo - c).min(axis=0), (g.hi - c).max(axis=0)):
        cells = f[rows] + off
        low = cells * g.cell
        box = np.maximum(np.maximum(low - q[rows], q[rows] - (low + g.cell)), 0.0)
        gap2 = box[:, 0] ** 2 + box[:, 1] ** 2 + box[:, 2] ** 2  # the kernel's order
        ijk = cells + OFFSET
        inside = ((ijk >= g.lo) & (ijk <= g.hi)).all(axis=1)
        use = inside & (gap2 < bound * bound) & (gap2 <= d2[rows, -1])
        at, ijk = rows[use], ijk[use]
        key = _pack(ijk)
        m = np.minimum(np.searchsorted(g.keys, key), len(g.keys) - 1)
        hit = g.keys[m] == key
        at, m = at[hit], m[hit]
        counts = g.starts[m + 1] - g.starts[m]
        who = np.repeat(at, counts)
        row = np.repeat(g.starts[m] - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())
        e = g.points[row] - q[who]
        dd = e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1] + e[:, 2] * e[:, 2]  # the kernel's order
        near = dd < bound * bound
        found.append((who[near], dd[near], g.order[row][near]))
    if not found:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
    return tuple(np.concatenate(parts) for parts in zip(*found, strict=True))


def _merge(d2: np.ndarray, index: np.ndarray, cand: tuple[np.ndarray, ...], n: int) -> None:
    """Keep, per query, the k best of its kept (``d2``, ``index``) and its candidates
    ``(query, squared distance, point)``, ordered by distance, then point (``n``: no point)."""
    who, dd, pt = cand
    touched = np.unique(who)
    if len(touched) == 0:
        return
    k = d2.shape[1]
    kept = np.isfinite(d2[touched])
    who = np.concatenate([np.repeat(touched, kept.sum(axis=1)), who])
    dd = np.concatenate([d2[touched][kept], dd])
    pt = np.concatenate([index[touched][kept], pt])
    order = np.lexsort((pt, dd, who))
    who, dd, pt = who[order], dd[order], pt[order]
    rank = np.arange(len(who)) - np.searchsorted(who, who)
    keep = rank < k
    d2[touched], index[touched] = np.inf, n
    d2[who[keep], rank[keep]] = dd[keep]
    index[who[keep], rank[keep]] = pt[keep]


def _unseen_numpy(x: np.ndarray, f: np.ndarray, s: int, cell: float) -> np.ndarray:
    """Numpy twin of the kernels' bound: squared distance from each ``x`` to the nearest point
    outside the cells within ``s`` of its own cell ``f``."""
    g = np.minimum(x - (f - s) * cell, (f + s + 1) * cell - x).min(axis=1)
    return g * g


def nearest_numpy(g: CellGrid, queries: np.ndarray, bound: float) -> tuple[np.ndarray, np.ndarray]:
    """Plain-numpy twin of :func:`nearest`."""
    dist, index = knn_numpy(g, queries, 1, bound)
    return dist[:, 0], index[:, 0]


@dataclass(frozen=True)
class NeighbourKernels:
    """One implementation of the grid and its queries (see the module docstring)."""

    grid: Callable[[np.ndarray, float], CellGrid]
    knn: Callable[..., tuple[np.ndarray, np.ndarray]]
    nearest: Callable[[CellGrid, np.ndarray, float], tuple[np.ndarray, np.ndarray]]

    def __repr__(self) -> str:
        return f"NeighbourKernels({self.grid.__name__})"


NUMBA = NeighbourKernels(grid, knn, nearest)
NUMPY = NeighbourKernels(grid_numpy, knn_numpy, nearest_numpy)
