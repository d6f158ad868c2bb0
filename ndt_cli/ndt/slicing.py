"""Ground level, horizontal slices and 2D thinning.

All functions work in a scan's reduced frame: the scan's coordinates minus its reduction point,
so values stay small (metres) whatever the georeference.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.core.groups import group_keys, group_sums

GROUND_SAMPLE = 400_000  # points of a regular sample enough for the ground and the levelling


def cut_slices(
    points: np.ndarray, ground_z: float, heights: Sequence[float], thickness: float
) -> list[np.ndarray]:
    """Project the points of each horizontal slice onto the ground plane.

    Slice k holds the points with ``|z - ground_z - heights[k]| <= thickness / 2``; it is
    returned as an (n_k, 2) float64 array of (x, y), metres, in the frame of ``points``.
    """
    z = points[:, 2] - ground_z
    half = 0.5 * thickness
    return [
        np.ascontiguousarray(points[np.abs(z - h) <= half, :2], dtype=np.float64) for h in heights
    ]


def voxel_filter_2d(xy: np.ndarray, voxel: float) -> np.ndarray:
    """Keep one point per ``voxel`` x ``voxel`` square (the centroid of its points).

    The result is ordered by voxel key, so it does not depend on the input order.
    """
    if voxel <= 0 or len(xy) == 0:
        return xy
    ij = np.floor(xy / voxel).astype(np.int64)
    lo, hi = column_bounds(ij)
    ij -= lo
    keys = ij[:, 0] * (int(hi[1] - lo[1]) + 1) + ij[:, 1]
    _, inverse, counts = group_keys(keys)
    return group_sums(inverse, xy, counts.size) / counts[:, None]


def subsample(xy: np.ndarray, cap: int, seed: int = 0) -> np.ndarray:
    """At most ``cap`` points, drawn without replacement by a fixed-seed generator."""
    if len(xy) <= cap:
        return xy
    idx = np.random.default_rng(seed).choice(len(xy), size=cap, replace=False)
    return xy[np.sort(idx)]
