"""Landmarks of a scan and the shapes they make, for finding which scans may overlap without
matching every pair.

A scan's **landmarks** are the small objects standing alone in its slices: tree trunks, poles,
posts, people (:func:`landmarks`). Their horizontal positions, in the scan's reduced,
levelled frame (m), are the centres of the compact groups of occupied cells with no other
point around them. Facades, hedges and parked cars are too long to be one; clutter
beside a wall is not alone.

Three landmarks make a triangle whose side lengths do not change when the scan is turned or
moved (:func:`triangle_keys`): two scans that saw the same objects share triangles, whatever
their headings. The keys are the sorted side lengths, each counted in steps of
:data:`KEY_STEP` m.
"""

from __future__ import annotations

import numpy as np

from ndt_cli.ndt.slicing import voxel_filter_2d

THIN = 0.05  # m: the slices thinned to one point per cell of this first (a 17 M-point scan's
# million slice points took 0.3 s, thinned 0.09 s, with nearly all the same landmarks)
CELL = 0.3  # m: cells of the occupancy image the landmarks are found in
MAX_EXTENT = 1.2  # m: a landmark's occupied cells fit in a square this wide (a trunk, a pole)
ALONE = 1.5  # m: no other point this close to a landmark (within this plus half its width
# of its centre)
MIN_POINTS = 3  # thinned points a landmark needs in a slice
MERGE = 0.5  # m: landmarks of different slices closer than this are one
MOST = 200  # landmarks kept per scan, nearest the scanner first (triangles grow as n^3)
SHORTEST, LONGEST = 3.0, 45.0  # m: the side lengths of the triangles kept
KEY_STEP = 0.3  # m: a triangle's sides are counted in steps of this


def landmarks(slices: tuple[np.ndarray, ...]) -> np.ndarray:
    """(n, 2) m: the landmarks of a scan's ``slices`` ((n_k, 2) m each, its reduced, levelled
    frame), nearest the scanner first, at most :data:`MOST`."""
    thin = [voxel_filter_2d(np.reshape(s, (-1, 2)), THIN) for s in slices]
    found = [_alone(s) for s in thin if len(s) >= MIN_POINTS]
    points = np.concatenate([np.zeros((0, 2)), *found])
    merged = _merged(points[np.argsort(np.hypot(*points.T), kind="stable")])
    return merged[:MOST]


def _alone(xy: np.ndarray) -> np.ndarray:
    """Centres (m) of the compact groups of occupied cells of one slice with no other point
    within :data:`ALONE` m of their edge."""
    ij = np.floor((xy - (xy.min(axis=0) - CELL)) / CELL).astype(np.int64)  # every j >= 1
    cols = int(ij[:, 1].max()) + 2  # a free column each side: no 8-neighbour wraps a row
    cell = ij[:, 0] * cols + ij[:, 1]
    occupied, point_cell = np.unique(cell, return_inverse=True)
    group = components(occupied, cols)
    point_label = group[point_cell]
    n = int(group.max()) + 1
    count = np.bincount(point_label, minlength=n)
    centre = np.stack([np.bincount(point_label, xy[:, k], n) for k in (0, 1)], axis=1)
    centre /= np.maximum(count, 1)[:, None]
    span = [_extent(ij[:, k], point_label, n) for k in (0, 1)]
    wide = np.maximum(*span) * CELL
    small = (count >= MIN_POINTS) & (wide <= MAX_EXTENT)
    if not small.any():
        return np.zeros((0, 2))
    radius = ALONE + 0.5 * wide[small]
    around = points_within(xy, centre[small], radius)
    return centre[np.flatnonzero(small)[around == count[small]]]


def components(cells: np.ndarray, cols: int) -> np.ndarray:
    """The 8-connected group of each of the sorted, distinct ``cells`` (row * ``cols`` + column,
    no cell in the first or last column): groups numbered 0, 1, ... in the order of their first
    cell, as ``scipy.ndimage.label`` numbers them in an image (the tests hold them equal).
    Each cell is hooked to its neighbours' lowest cell until no edge joins two groups."""
    edges = [np.zeros(0, dtype=np.int64)] * 2
    for step in (1, cols - 1, cols, cols + 1):  # right, and the row below: left, under, right
        at = np.minimum(np.searchsorted(cells, cells + step), len(cells) - 1)
        hit = cells[at] == cells + step
        edges = [
            np.concatenate([edges[0], np.flatnonzero(hit)]),
            np.concatenate([edges[1], at[hit]]),
        ]
    a, b = edges
    root = np.arange(len(cells))
    while True:
        ra, rb = root[a], root[b]
        joined = ra != rb
        if not joined.any():
            break
        low = np.minimum(ra[joined], rb[joined])
        np.minimum.at(root, ra[joined], low)
        np.minimum.at(root, rb[joined], low)
        while not np.array_equal(root[root], root):  # each cell to its group's lowest cell
            root = root[root]
    return np.unique(root, return_inverse=True)[1]


def _extent(ij: np.ndarray, label: np.ndarray, n: int) -> np.ndarray:
    """Cells spanned along one axis by each of ``n`` groups (1 for a group one cell wide)."""
    hi = np.full(n, np.iinfo(np.int64).min)
    lo = np.full(n, np.iinfo(np.int64).max)
    np.maximum.at(hi, label, ij)
    np.minimum.at(lo, label, ij)
    return np.maximum(hi - lo + 1, 0)


def points_within(xy: np.ndarray, centres: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """How many of the points ``xy`` ((n, 2) m) lie within ``radius`` ((k,) m, inclusive) of
    each of the ``centres`` ((k, 2) m): from the points in the square of cells of
    :data:`CELL` m around each centre."""
    origin = xy.min(axis=0)
    ij = np.floor((xy - origin) / CELL).astype(np.int64)
    top = ij.max(axis=0)
    cols = int(top[1]) + 1
    order = np.argsort(ij[:, 0] * cols + ij[:, 1], kind="stable")
    key = (ij[:, 0] * cols + ij[:, 1])[order]
    lo = np.clip(np.floor((centres - radius[:, None] - origin) / CELL), 0, top).astype(np.int64)
    hi = np.clip(np.floor((centres + radius[:, None] - origin) / CELL), 0, top).astype(np.int64)
    rows = hi[:, 0] - lo[:, 0] + 1
    owner = np.repeat(np.arange(len(centres)), rows)
    row = lo[owner, 0] + np.arange(len(owner)) - np.repeat(np.cumsum(rows) - rows, rows)
    start = np.searchsorted(key, row * cols + lo[owner, 1], side="left")
    stop = np.searchsorted(key, row * cols + hi[owner, 1], side="right")
    size = stop - start
    at = np.arange(size.sum()) - np.repeat(np.cumsum(size) - size, size) + np.repeat(start, size)
    who = np.repeat(owner, size)
    near = order[at]
    d2 = np.sum((xy[near] - centres[who]) ** 2, axis=1)
    return np.bincount(who[d2 <= radius[who] ** 2], minlength=len(centres))


def _merged(points: np.ndarray) -> np.ndarray:
    """``points`` with those within :data:`MERGE` m of an earlier one folded into it (their
    mean), in the order given."""
    taken = np.zeros(len(points), dtype=bool)
    out = []
    for k in range(len(points)):
        if taken[k]:
            continue
        group = np.flatnonzero(~taken & (np.hypot(*(points - points[k]).T) <= MERGE))
        taken[group] = True
        out.append(points[group].mean(axis=0))
    return np.array(out).reshape(-1, 2)


def triangle_keys(points: np.ndarray) -> np.ndarray:
    """(m, 3) int64: the sorted side lengths of every triangle of ``points`` ((n, 2) m) whose
    sides are :data:`SHORTEST` to :data:`LONGEST` m, in steps of :data:`KEY_STEP` m, each
    distinct triangle shape once, sorted."""
    d = np.hypot(*(points[:, None, :] - points[None, :, :]).transpose(2, 0, 1))
    near = (d >= SHORTEST) & (d <= LONGEST)
    a, b = np.nonzero(np.triu(near, 1))
    if len(a) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    third = near[a] & near[b]
    third &= np.arange(len(points))[None, :] > b[:, None]
    row, c = np.nonzero(third)
    a, b = a[row], b[row]
    sides = np.sort(np.stack([d[a, b], d[b, c], d[a, c]], axis=1), axis=1)
    keys = np.floor(sides / KEY_STEP).astype(np.int64)
    return np.unique(keys, axis=0)
