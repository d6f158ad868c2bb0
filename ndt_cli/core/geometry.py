"""Small geometric building blocks on 3D points (metres, any frame): voxel thinning and the
normals of local planes."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ndt_cli.core import neighbours
from ndt_cli.core.merge import Groups, merge_groups
from ndt_cli.core.neighbours import CellGrid, NeighbourKernels
from ndt_cli.core.planes import local_planes, local_planes_numpy

Merge = Callable[[Groups, Groups], Groups]  # merge_groups' type
Planes = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]  # local_planes' type
VOXEL_OFFSET = 1 << 20  # voxel indices are packed as 21-bit fields: +-1e6 voxels from origin
CELLS_PER_VOXEL = 10  # a neighbour grid's cell in voxels of its points: the fastest queries


@dataclass(frozen=True)
class Surfaces:
    """What finds local surfaces in 3D points: a neighbour grid with its queries
    (:mod:`ndt_cli.core.neighbours`) and the planes of neighbourhoods
    (:mod:`ndt_cli.core.planes`); the compiled kernels or their numpy twins."""

    neighbours: NeighbourKernels
    planes: Planes

    def grid(self, points: np.ndarray, voxel: float) -> CellGrid:
        """A neighbour grid of points thinned to one per ``voxel`` metres."""
        return self.neighbours.grid(points, CELLS_PER_VOXEL * voxel)

    def __repr__(self) -> str:
        return f"Surfaces({self.neighbours!r}, {self.planes.__name__})"


SURFACES = Surfaces(neighbours.NUMBA, local_planes)
SURFACES_NUMPY = Surfaces(neighbours.NUMPY, local_planes_numpy)


def voxel_keys(points: np.ndarray, voxel: float) -> np.ndarray:
    """One int64 key per (N,3) point: its ``voxel`` cube's indices packed in 21-bit fields, so
    that keys sort by x index, then y, then z."""
    ijk = np.floor(points / voxel).astype(np.int64) + VOXEL_OFFSET
    if len(ijk) and (ijk.min() < 0 or ijk.max() >= 2 * VOXEL_OFFSET):
        raise ValueError("points too far from the origin for voxel thinning")
    return (ijk[:, 0] << 42) | (ijk[:, 1] << 21) | ijk[:, 2]


class VoxelThinner:
    """One point (the centroid) per ``voxel`` metre cube, accumulated over chunks of points.

    The result is ordered by voxel (x index, then y, then z), whatever the chunking. Coordinates
    must lie within 2**20 voxels of the origin (a reduced frame; 105 km at 0.1 m). Each chunk's
    voxels are merged into those so far (``merge``: :func:`~ndt_cli.core.merge.merge_groups` or
    its numpy twin), so memory grows with the voxels, not with the chunks.
    """

    def __init__(self, voxel: float, merge: Merge = merge_groups) -> None:
        self.voxel = voxel
        self._merge = merge
        self._groups: Groups | None = None

    def add(self, points: np.ndarray) -> None:
        if len(points) == 0:
            return
        self.add_grouped(voxel_keys(points, self.voxel), points, np.ones(len(points)))

    def add_grouped(self, keys: np.ndarray, sums: np.ndarray, counts: np.ndarray) -> None:
        """Add rows already grouped by voxel key (see :func:`voxel_keys`): coordinate sums
        (n,3) and point counts; a key may repeat."""
        part = _grouped(keys, sums, counts)
        self._groups = part if self._groups is None else self._merge(self._groups, part)

    def result(self) -> np.ndarray:
        """(n,3) float64 centroids, one per occupied voxel."""
        if self._groups is None:
            return np.empty((0, 3))
        _, sums, counts = self._groups
        return sums / counts[:, None]


def _grouped(
    keys: np.ndarray, values: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique keys (sorted), the per-key sums of the (n,3) ``values`` and of ``weights``."""
    uniq, inverse = np.unique(keys, return_inverse=True)
    sums = np.column_stack([np.bincount(inverse, weights=values[:, k]) for k in range(3)])
    return uniq, sums, np.bincount(inverse, weights=weights)


def voxel_thin(points: np.ndarray, voxel: float) -> np.ndarray:
    """One point (the centroid) per ``voxel`` metre cube (see :class:`VoxelThinner`)."""
    thinner = VoxelThinner(voxel)
    thinner.add(points)
    return thinner.result()


def normals(
    points: np.ndarray, grid: CellGrid, k: int = 12, surfaces: Surfaces = SURFACES
) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals from the covariance of each point's ``k`` nearest neighbours in ``grid``,
    and a planarity in [0, 1] (1 - smallest/middle eigenvalue) to drop points without a clear
    plane (:mod:`ndt_cli.core.planes`)."""
    _, idx = surfaces.neighbours.knn(grid, points, k)
    return surfaces.planes(grid.data, idx)
