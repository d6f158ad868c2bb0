"""From a point cloud to what the registration needs: reduction point, ground level, slices.

A scan's reduced frame is its own frame shifted by the reduction point ``r``: the centre of its
bounding box in x, y (rounded to whole metres) and its ground level in z. All float maths happens
there, so georeferenced coordinates (e.g. 5e6 m UTM northings) lose no precision, and slice
heights are simply z values.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ndt_cli.config import Config
from ndt_cli.errors import InputError
from ndt_cli.slicing import cut_slices, estimate_ground, fit_ground_plane
from ndt_cli.transforms import levelling_rotation, rotation4, rotation_angle_deg, translation

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PreparedScan:
    """A scan cut into slices. ``slices[k]`` is (n_k, 2) float64, metres, reduced frame."""

    path: Path | None
    reduction: np.ndarray  # (3,) float64: a point of the ground plane below the bounding-box centre
    ground_z: float  # ground level, scan frame (= reduction[2])
    slices: tuple[np.ndarray, ...]
    n_points: int
    level: np.ndarray = field(default_factory=lambda: np.eye(3))  # scan axes -> levelled axes
    points3d: np.ndarray | None = None  # thinned 3D points minus the reduction (for ICP), m

    def to_local(self) -> np.ndarray:
        """4x4 from the scan frame to the reduced, levelled frame: q = L (p - reduction)."""
        return rotation4(self.level) @ translation(-self.reduction)

    def from_local(self) -> np.ndarray:
        """4x4 from the reduced, levelled frame back to the scan frame."""
        return translation(self.reduction) @ rotation4(self.level.T)

    @property
    def tilt_deg(self) -> float:
        """Angle (degrees) between the scan's z axis and the ground normal."""
        return rotation_angle_deg(self.level)

    @property
    def label(self) -> str:
        return str(self.path) if self.path is not None else "<array>"

    def centroid(self) -> np.ndarray:
        """Median (x, y) of all slice points, reduced frame: a robust centre of the scene."""
        xy = np.concatenate(self.slices)
        return np.median(xy, axis=0) if len(xy) else np.zeros(2)


def load_points(scan: str | Path | np.ndarray) -> tuple[np.ndarray, Path | None]:
    """(N,3) float64 points of a file path or an array (non-finite and (0,0,0) points dropped)."""
    if isinstance(scan, str | Path):
        from ndt_cli import io

        cloud = io.read(scan)
        return cloud.points, cloud.path
    pts = np.asarray(scan, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise InputError(f"expected an (N,3) array of points, got shape {pts.shape}")
    pts = pts[:, :3]
    keep = np.isfinite(pts).all(axis=1) & np.any(pts != 0, axis=1)
    if not keep.all():
        log.info("dropped %d non-finite or (0,0,0) points", int((~keep).sum()))
        pts = pts[keep]
    if len(pts) == 0:
        raise InputError("the array holds no usable points")
    return np.ascontiguousarray(pts), None


def prepare(points: np.ndarray, cfg: Config, path: Path | None = None) -> PreparedScan:
    """Find the reduction point and ground level of a scan and cut its slices."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre_xy = np.round(0.5 * (lo[:2] + hi[:2]))
    if cfg.ground.z is not None:
        ground = float(cfg.ground.z)
    else:
        ground = estimate_ground(points[:, 2] - np.round(lo[2]), cfg.ground.bin_size) + np.round(
            lo[2]
        )
    reduction = np.array([centre_xy[0], centre_xy[1], ground])
    local = points - reduction
    level = np.eye(3)
    if cfg.ground.level and cfg.ground.z is None:
        a, b, c = fit_ground_plane(local)
        reduction[2] += c  # the reduction point lies on the ground plane
        ground = float(reduction[2])
        level = levelling_rotation(a, b)
        local = (points - reduction) @ level.T
    slices = cut_slices(local, 0.0, cfg.slices.heights, cfg.slices.thickness)
    n_slice = sum(len(s) for s in slices)
    if n_slice < cfg.grid.min_points:
        raise InputError(
            f"no points in any slice at heights {list(cfg.slices.heights)} m above the ground "
            f"(ground found at z = {ground:.2f}); check slices.heights or set ground.z",
            path,
        )
    thin = None
    if cfg.refine.method == "icp":
        from ndt_cli.refine import voxel_thin

        thin = voxel_thin(points - reduction, cfg.refine.voxel)
    return PreparedScan(path, reduction, ground, tuple(slices), len(points), level, thin)


def load_and_prepare(scan: str | Path | np.ndarray, cfg: Config) -> PreparedScan:
    """:func:`load_points` then :func:`prepare`."""
    pts, path = load_points(scan)
    return prepare(pts, cfg, path)
