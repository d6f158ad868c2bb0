"""Which scans overlap: a cheap global match of two scans at a coarse resolution.

A scan's :class:`Sketch` is what the match needs of it, a few kilobytes: its slices thinned to
one point per :data:`COARSE_RESOLUTION` pixel and the likelihood field of those slices
(:func:`ndt_cli.ndt.bnb.likelihood_field`), both in the scan's reduced, levelled frame (m).
:func:`coarse_match` runs the exact branch-and-bound search (:func:`ndt_cli.ndt.bnb.search_field`)
of one sketch on the other's field, both ways, over every heading and every translation within
:data:`COARSE_WINDOW` m: its score, the share of each scan's thinned points that land on the
other's structure at the best pose (mean of the two ways, 0..1), ranks the scans a new scan
may overlap with. It is a ranking, not a verdict: on a street, a scan shifted along the street
fits its facades too; the full registration and the network decide.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.ndt import bnb_kernels
from ndt_cli.ndt.bnb import ScoreField, likelihood_field, search_field
from ndt_cli.ndt.bnb_kernels import SearchKernels
from ndt_cli.ndt.landmarks import landmarks, triangle_keys
from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.ndt.slicing import voxel_filter_2d

COARSE_RESOLUTION = 2.0  # m: pixel of the coarse fields and of the match's lattice
COARSE_WINDOW = 60.0  # m: translations searched, +- around the aligned scene centres


@dataclass(frozen=True, repr=False)
class Sketch:
    """A scan at a coarse resolution: ``slices[k]`` (n_k, 2) m thinned to one point per pixel,
    and their ``field`` (reduced, levelled frame of the scan); ``to_local``: 4x4 from the
    scan's own frame to that frame; ``keys``: the triangles of its landmarks, found in its
    slices before thinning ((m, 3) int64, :func:`~ndt_cli.ndt.landmarks.triangle_keys`;
    none: kept by an older run)."""

    slices: tuple[np.ndarray, ...]
    field: ScoreField
    to_local: np.ndarray
    keys: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))

    @property
    def n_points(self) -> int:
        return sum(len(s) for s in self.slices)

    def __repr__(self) -> str:
        return f"Sketch({self.n_points} points at {self.field.resolution:g} m)"


def sketch(scan: PreparedScan, resolution: float = COARSE_RESOLUTION) -> Sketch:
    """The :class:`Sketch` of a prepared scan."""
    thin = tuple(voxel_filter_2d(np.reshape(s, (-1, 2)), resolution) for s in scan.slices)
    keys = triangle_keys(landmarks(scan.slices))
    return Sketch(thin, likelihood_field(thin, resolution=resolution), scan.to_local(), keys)


@dataclass(frozen=True)
class CoarseMatch:
    """How well two sketches fit: ``score`` in 0..1 (see the module docstring) and the best
    pose of the second scan in the first, ``T_first_second`` (4x4, the scans' own frames)."""

    score: float
    T_target_source: np.ndarray


def _one_way(target: Sketch, source: Sketch, kernels: SearchKernels) -> tuple[float, np.ndarray]:
    if source.n_points == 0 or target.n_points == 0:
        return 0.0, np.zeros(3)
    found = search_field(
        target.field, source.slices, window=COARSE_WINDOW, candidates=1, kernels=kernels
    )
    if len(found.scores) == 0:
        return 0.0, np.zeros(3)
    return float(found.scores[0]) / max(found.n_points, 1), found.poses[0]


def coarse_match(
    target: Sketch, source: Sketch, kernels: SearchKernels = bnb_kernels.NUMBA
) -> CoarseMatch:
    """The best coarse pose of ``source`` on ``target`` and the mean score of both ways."""
    there, pose = _one_way(target, source, kernels)
    back, _ = _one_way(source, target, kernels)
    T = np.linalg.inv(target.to_local) @ pose2d_matrix(*pose) @ source.to_local
    return CoarseMatch(0.5 * (there + back), T)
