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
from scipy import ndimage
from scipy.spatial import cKDTree

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
    origin = xy.min(axis=0) - CELL
    ij = np.floor((xy - origin) / CELL).astype(np.int64)
    image = np.zeros(tuple(ij.max(axis=0) + 1), dtype=bool)
    image[ij[:, 0], ij[:, 1]] = True
    labels, n = ndimage.label(image, structure=np.ones((3, 3)))
    point_label = labels[ij[:, 0], ij[:, 1]]
    count = np.bincount(point_label, minlength=n + 1)[1:]
    centre = np.stack([np.bincount(point_label, xy[:, k], n + 1)[1:] for k in (0, 1)], axis=1)
    centre /= np.maximum(count, 1)[:, None]
    boxes = ndimage.find_objects(labels)
    wide = np.array([max(b[0].stop - b[0].start, b[1].stop - b[1].start) for b in boxes]) * CELL
    small = (count >= MIN_POINTS) & (wide <= MAX_EXTENT)
    if not small.any():
        return np.zeros((0, 2))
    around = cKDTree(xy).query_ball_point(
        centre[small], ALONE + 0.5 * wide[small], return_length=True
    )
    alone = np.flatnonzero(small)[around == count[small]]
    return centre[alone]


def _merged(points: np.ndarray) -> np.ndarray:
    """``points`` with those within :data:`MERGE` m of an earlier one folded into it (their
    mean), in the order given."""
    if len(points) == 0:
        return points
    tree = cKDTree(points)
    taken = np.zeros(len(points), dtype=bool)
    out = []
    for k in range(len(points)):
        if taken[k]:
            continue
        group = [g for g in tree.query_ball_point(points[k], MERGE) if not taken[g]]
        taken[group] = True
        out.append(points[group].mean(axis=0))
    return np.array(out)


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
