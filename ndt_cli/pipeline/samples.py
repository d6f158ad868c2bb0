"""What the report's link inspector keeps of each scan: two of its slices, thinned.

A scan is prepared once, in a worker, and its prepared form is gone when the outputs are
written. So that the report can show any link's two scans overlaid without reading them again,
the worker keeps, with the scan's summary, the slice at the lowest height (1 m by default:
facades, doors, poles, cars) and the middle one (4 m: the upper storeys), each thinned to one
point per :data:`VOXEL` square, at most :data:`MAX_POINTS` points (a coarser square when there
are more), as float32 in the scan's reduced, levelled frame (the frame the slices were matched
in), with the 4x4 from the scan's own frame to that frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.ndt.slicing import voxel_filter_2d

VOXEL = 0.04  # m: a slice's points are thinned to one per square of this side, or coarser
MAX_POINTS = 6000  # per slice: squares 1.5 times larger until a slice holds at most this many


@dataclass(frozen=True)
class SliceSample:
    """Two slices of a scan: ``slices[k]`` (n_k, 2) float32 m in the scan's reduced, levelled
    frame, cut at ``heights[k]`` m above the ground; ``to_local``: 4x4 from the scan's own
    frame to that frame."""

    to_local: np.ndarray
    heights: tuple[float, ...]
    slices: tuple[np.ndarray, ...]


def chosen(n_slices: int) -> tuple[int, ...]:
    """The slices kept: the lowest and the middle one (one when there is one)."""
    return tuple(sorted({0, n_slices // 2})) if n_slices else ()


def thinned(xy: np.ndarray, voxel: float = VOXEL, cap: int = MAX_POINTS) -> np.ndarray:
    """``xy`` thinned to one point per ``voxel`` square, coarser until at most ``cap`` remain."""
    out = voxel_filter_2d(np.reshape(xy, (-1, 2)), voxel)
    while len(out) > cap:
        voxel *= 1.5
        out = voxel_filter_2d(out, voxel)
    return out.astype(np.float32)


def slice_sample(scan: PreparedScan, heights: tuple[float, ...]) -> SliceSample:
    """The :class:`SliceSample` of a prepared scan whose slices were cut at ``heights``."""
    keep = chosen(len(scan.slices))
    return SliceSample(
        scan.to_local(),
        tuple(float(heights[k]) for k in keep),
        tuple(thinned(scan.slices[k]) for k in keep),
    )
