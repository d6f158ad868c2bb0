"""One pass over the points of a chunk (Numba), with plain-numpy twins that the tests compare.

A scan of millions of points is touched twice while it is prepared: once for a regular sample
(numpy), and once to cut the slices (each point's height above the ground model under it) and
thin the points for ICP, fused into a single loop over each chunk of the scan (float64 or
float32 coordinates, or a LAS file's integers with their scale and offset); everything else
works on the much smaller results. Coordinates are metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.core.geometry import VOXEL_OFFSET as _OFFSET
from ndt_cli.core.geometry import voxel_keys
from ndt_cli.io.blocks import Block
from ndt_cli.ndt.slicing import cut_slices
from ndt_cli.ndt.terrain import Terrain

MAX_SLICES = 63  # slice membership is a bit mask in an int64

Grouped = tuple[np.ndarray, np.ndarray, np.ndarray]  # voxel keys, (n,3) sums, counts


def bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis minimum and maximum of (N,3) points (:func:`column_bounds`); it needs no
    compiled kernel, so a scan's first pass does not wait for Numba to load."""
    return column_bounds(points)


RECENT_BITS = 12  # voxels remembered while grouping (about a scan line's), 64 KB: in cache
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: 2**64 / golden ratio


@numba.njit(cache=True, nogil=True, inline="always")
def _slice_bits(hz, heights, half):  # pragma: no cover - compiled
    # bit k set: the height hz (m above the ground) is within half of slice k's height
    bits = np.int64(0)
    for k in range(heights.shape[0]):
        if abs(hz - heights[k]) <= half:
            bits |= np.int64(1) << k
    return bits


@numba.njit(cache=True, nogil=True, inline="always")
def _voxel_key(x, y, z, voxel):  # pragma: no cover - compiled
    # the packed key of a point's voxel, and whether its indices fit the key's 21 bits each
    ix = np.int64(np.floor(x / voxel)) + _OFFSET
    iy = np.int64(np.floor(y / voxel)) + _OFFSET
    iz = np.int64(np.floor(z / voxel)) + _OFFSET
    fits = min(ix, iy, iz) >= 0 and max(ix, iy, iz) < 2 * _OFFSET
    return (ix << 42) | (iy << 21) | iz, fits


@numba.njit(cache=True, nogil=True)
def _slice_pass(
    points,
    scale,
    offset,
    reduction,
    level,
    heights,
    half,
    voxel,
    ground,
    frame,
    bits_out,
    xy,
    keys,
    sums,
    counts,
):  # pragma: no cover - compiled
    # points: float64, or LAS integers when scale holds 3 values (x = X * scale + offset)
    # frame: ground grid origin x, y, 1 / cell, and the largest squared distance kept (m^2)
    # the points in any slice are written one after the other (bits_out, xy), as the grouped
    # voxels (keys, sums, counts): only the rows written are touched, so memory grows with them
    scaled = scale.shape[0] == 3
    m = -1
    hit = 0
    recent_key = np.zeros(1 << RECENT_BITS, np.int64)  # a small direct-mapped table of the
    recent_row = np.full(1 << RECENT_BITS, -1, np.int64)  # voxels seen last and their rows
    shift = np.uint64(64 - RECENT_BITS)
    inside = True
    far = 0
    nx, ny = ground.shape
    for i in range(points.shape[0]):
        if scaled:
            px = points[i, 0] * scale[0] + offset[0]
            py = points[i, 1] * scale[1] + offset[1]
            pz = points[i, 2] * scale[2] + offset[2]
        else:
            px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        x = px - reduction[0]
        y = py - reduction[1]
        z = pz - reduction[2]
        if x * x + y * y + z * z > frame[3]:
            far += 1
            continue
        lx = level[0, 0] * x + level[0, 1] * y + level[0, 2] * z
        ly = level[1, 0] * x + level[1, 1] * y + level[1, 2] * z
        lz = level[2, 0] * x + level[2, 1] * y + level[2, 2] * z
        gi = min(max(np.int64(np.floor((lx - frame[0]) * frame[2])), 0), nx - 1)
        gj = min(max(np.int64(np.floor((ly - frame[1]) * frame[2])), 0), ny - 1)
        hz = lz - ground[gi, gj]
        bits = _slice_bits(hz, heights, half)
        if bits != 0:
            bits_out[hit] = bits
            xy[hit, 0] = lx
            xy[hit, 1] = ly
            hit += 1
        if voxel > 0.0:
            key, fits = _voxel_key(x, y, z, voxel)
            inside = inside and fits
            h = np.int64((np.uint64(key) * _GOLDEN) >> shift)
            row = recent_row[h]
            if row < 0 or recent_key[h] != key:  # neighbouring points and scan lines share
                m += 1  # voxels: a voxel seen recently adds to its row, another starts one
                row = m
                keys[m] = key
                sums[m, 0] = 0.0
                sums[m, 1] = 0.0
                sums[m, 2] = 0.0
                counts[m] = 0.0
                recent_key[h] = key
                recent_row[h] = m
            sums[row, 0] += x
            sums[row, 1] += y
            sums[row, 2] += z
            counts[row] += 1.0
    return m + 1, hit, inside, far


@dataclass(frozen=True)
class Cut:
    """What a pass over one chunk gives: the slices ((n_k,2) each, reduced levelled frame),
    the points grouped by ICP voxel (None without ICP points) and the number of points left
    out for lying farther than ``max_range`` from the reduction point."""

    slices: list[np.ndarray]
    grouped: Grouped | None
    far: int = 0


def _frame(terrain: Terrain | None, max_range: float) -> tuple[np.ndarray, np.ndarray]:
    """The ground grid and the kernel's frame numbers (grid origin, 1 / cell, max range^2)."""
    terrain = terrain or Terrain.flat()
    frame = np.array([*terrain.origin, 1.0 / terrain.cell, max_range * max_range])
    return np.ascontiguousarray(terrain.heights, np.float64), frame


def _block(points: np.ndarray | Block) -> Block:
    return points if isinstance(points, Block) else Block(points)


def slice_pass(
    points: np.ndarray | Block,
    reduction: np.ndarray,
    level: np.ndarray,
    heights: Sequence[float],
    thickness: float,
    voxel: float,
    terrain: Terrain | None = None,
    max_range: float = np.inf,
) -> Cut:
    """Cut the slices of one chunk and group its points by ICP voxel, in one pass.

    ``points``: (n,3) float64 metres, or a :class:`~ndt_cli.io.blocks.Block` (a LAS file's
    integers are scaled in the loop, to the coordinates :meth:`Block.xyz` gives).

    A point's height is taken above ``terrain`` (the ground under it; default: the plane
    z = 0) in the reduced, levelled frame ``L (p - reduction)``; slice k holds the points within
    ``thickness / 2`` of ``heights[k]``, as (n_k,2) points of that frame (as
    :func:`~ndt_cli.ndt.slicing.cut_slices` of the heights). When ``voxel`` > 0, the points
    ``p - reduction`` (unlevelled) are grouped by ``voxel`` cube: keys, coordinate sums and
    counts, each added in point order, one row per stretch of points in which the cube stayed
    among those seen recently (a key may repeat; merge with
    :meth:`~ndt_cli.core.geometry.VoxelThinner.add_grouped`). Points farther than
    ``max_range`` m from the reduction point are left out of both.
    """
    if len(heights) > MAX_SLICES:
        raise ValueError(f"at most {MAX_SLICES} slices")
    block = _block(points)
    if block.scaled:
        pts = np.ascontiguousarray(block.values)
        scale, offset = np.asarray(block.scale, np.float64), np.asarray(block.offset, np.float64)
    else:  # float64, or float32 (widened exactly in the loop)
        pts = np.ascontiguousarray(block.values)
        if pts.dtype not in (np.float32, np.float64):
            pts = pts.astype(np.float64)
        scale = offset = np.empty(0)
    n = len(pts)
    bits = np.empty(n, np.int64)  # allocated, touched only where written
    xy = np.empty((n, 2))
    m_max = n if voxel > 0 else 0
    keys, sums, counts = np.empty(m_max, np.int64), np.empty((m_max, 3)), np.empty(m_max)
    ground, frame = _frame(terrain, max_range)
    m, hits, inside, far = _slice_pass(
        pts,
        scale,
        offset,
        np.asarray(reduction, np.float64),
        np.ascontiguousarray(level, np.float64),
        np.asarray(heights, np.float64),
        0.5 * thickness,
        float(voxel),
        ground,
        frame,
        bits,
        xy,
        keys,
        sums,
        counts,
    )
    if not inside:
        raise ValueError("points too far from the origin for voxel thinning")
    bits, xy = bits[:hits], xy[:hits]  # the few points in any slice, then per slice
    slices = [np.ascontiguousarray(xy[(bits >> k) & 1 == 1]) for k in range(len(heights))]
    grouped = (keys[:m], sums[:m], counts[:m]) if voxel > 0 else None
    return Cut(slices, grouped, int(far))


def slice_pass_numpy(
    points: np.ndarray | Block,
    reduction: np.ndarray,
    level: np.ndarray,
    heights: Sequence[float],
    thickness: float,
    voxel: float,
    terrain: Terrain | None = None,
    max_range: float = np.inf,
) -> Cut:
    """Plain-numpy twin of :func:`slice_pass` (one row per point in the grouping)."""
    rel = _block(points).xyz() - reduction
    near = np.einsum("ij,ij->i", rel, rel) <= max_range * max_range
    rel = rel[near]
    lev = rel @ np.asarray(level).T
    ground = (terrain or Terrain.flat()).at(lev[:, :2])
    lev[:, 2] -= ground
    slices = cut_slices(lev, 0.0, heights, thickness)
    far = int((~near).sum())
    if voxel <= 0:
        return Cut(slices, None, far)
    return Cut(slices, (voxel_keys(rel, voxel), rel, np.ones(len(rel))), far)
