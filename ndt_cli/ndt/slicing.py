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


def estimate_ground(z: np.ndarray, bin_size: float = 0.05) -> float:
    """Ground level (metres, same frame as ``z``) of a roughly upright scan.

    The ground is the densest horizontal layer: the mode of a height histogram with
    ``bin_size`` bins, refined by the median of the heights within two bins of the mode.
    Facades are vertical and spread over many bins, so they do not form such a peak.
    """
    z = np.asarray(z, dtype=np.float64)
    if z.size == 0:
        raise ValueError("no points to estimate the ground from")
    if z.size > GROUND_SAMPLE:  # a regular stride keeps it deterministic
        z = z[:: z.size // GROUND_SAMPLE + 1]
    lo, hi = float(z.min()), float(z.max())
    n_bins = max(1, int(np.ceil((hi - lo) / bin_size)))
    counts, edges = np.histogram(z, bins=n_bins, range=(lo, lo + n_bins * bin_size))
    # smooth over three bins so that noise splitting a layer across two bins does not matter
    smooth = np.convolve(counts, np.ones(3), mode="same")
    k = int(np.argmax(smooth))
    mode = 0.5 * (edges[k] + edges[k + 1])
    near = z[np.abs(z - mode) <= 2 * bin_size]
    return float(np.median(near)) if near.size else mode


def fit_ground_plane(
    points: np.ndarray, band: float = 0.3, iterations: int = 4
) -> tuple[float, float, float]:
    """Ground plane ``z = a x + b y + c`` (metres) of points whose ground is near z = 0.

    Least squares on the points within ``band`` of the current plane, repeated with a band that
    narrows to a third; outliers (kerbs, cars, low walls) leave the band. ``a`` and ``b`` are
    the slopes that a tilted scanner sees on level ground.
    """
    pts = points if len(points) <= GROUND_SAMPLE else points[:: len(points) // GROUND_SAMPLE + 1]
    a = b = c = 0.0
    for k in range(iterations):
        width = band * (1.0 - 2.0 * k / (3.0 * max(iterations - 1, 1)))
        near = np.abs(pts[:, 2] - (a * pts[:, 0] + b * pts[:, 1] + c)) <= width
        if near.sum() < 3:
            break
        a, b, c = _plane(pts[near])
    return float(a), float(b), float(c)


def _plane(g: np.ndarray) -> tuple[float, float, float]:
    """Least-squares ``z = a x + b y + c`` of (n,3) points: the normal equations of the slopes
    on coordinates centred on their mean (well conditioned), then ``c`` at the mean."""
    m = g.mean(axis=0)
    d = g - m
    xx, xy, yy = d[:, 0] @ d[:, 0], d[:, 0] @ d[:, 1], d[:, 1] @ d[:, 1]
    xz, yz = d[:, 0] @ d[:, 2], d[:, 1] @ d[:, 2]
    det = xx * yy - xy * xy
    if det <= 1e-12 * max(xx * yy, 1e-300):  # points on a line: no slope across it
        return 0.0, 0.0, float(m[2])
    a, b = (yy * xz - xy * yz) / det, (xx * yz - xy * xz) / det
    return a, b, float(m[2] - a * m[0] - b * m[1])


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
