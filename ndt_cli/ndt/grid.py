"""The 2D normal distributions transform of the target: one grid per slice and cell size.

Every cell with at least ``min_points`` points gets the mean ``q`` and covariance ``Sigma`` of its
points (metres, reduced target frame). The inverse covariance is stored, with the small eigenvalue
clamped so that a facade, which is almost a line inside a cell, keeps a finite density.
All slices of one cell size live in flat arrays that the Numba kernels read directly; cells are
found through a dense index per grid (no dictionaries, no fixed extent: each grid covers the
bounding box of its slice's points).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.core.groups import group_keys, group_sums
from ndt_cli.errors import ConfigError

MAX_INDEX_CELLS = 100_000_000  # dense index entries over all grids (400 MB of int32)


@dataclass(frozen=True)
class NDTMap:
    """All slices' NDT grids at one cell size, as flat arrays.

    Grid g covers ``grid_shape[g] = (nx, ny)`` cells of ``cell_size`` metres from ``grid_origin[g]``
    (x0, y0); cell (ix, iy) has the entry ``cell_index[grid_offset[g] + ix*ny + iy]``,
    the row of its normal distribution in ``means`` / ``icov`` or -1 when it has too few points.
    Slice k owns the grids ``slice_grids[k] .. slice_grids[k+1]-1`` (1, or 4 with overlap).
    ``icov`` rows hold the inverse covariance (a, b, c) of [[a, b], [b, c]] in 1/m^2.
    """

    cell_size: float
    grid_origin: np.ndarray  # (G, 2) float64
    grid_shape: np.ndarray  # (G, 2) int64
    grid_offset: np.ndarray  # (G,) int64
    slice_grids: np.ndarray  # (K+1,) int64
    cell_index: np.ndarray  # (sum nx*ny,) int32
    means: np.ndarray  # (M, 2) float64
    icov: np.ndarray  # (M, 3) float64
    counts: np.ndarray  # (M,) int64 points per cell

    @property
    def n_slices(self) -> int:
        return len(self.slice_grids) - 1

    @property
    def n_cells(self) -> int:
        return len(self.means)


def cell_statistics(
    xy: np.ndarray,
    origin: np.ndarray,
    cell_size: float,
    min_points: int,
    min_eigen_ratio: float,
    min_variance: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """Cells of one grid: (keys, means, inverse covariances, counts, (nx, ny)).

    ``keys`` are ``ix * ny + iy`` of the cells that have ``>= min_points`` points.
    """
    ij = np.floor((xy - origin) / cell_size).astype(np.int64)
    nx, ny = int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1
    keys_all = ij[:, 0] * ny + ij[:, 1]
    keys, inverse, counts = group_keys(keys_all)
    n = counts.astype(np.float64)
    # centre on the cell's own mean before the second moments (no cancellation)
    means = group_sums(inverse, xy, keys.size) / n[:, None]
    d = xy - means[inverse]
    m2 = group_sums(
        inverse, np.column_stack([d[:, 0] ** 2, d[:, 0] * d[:, 1], d[:, 1] ** 2]), keys.size
    )
    keep = counts >= min_points
    keys, means, m2, counts = keys[keep], means[keep], m2[keep], counts[keep]
    cov = np.empty((keys.size, 2, 2))
    denom = (counts - 1.0)[:, None]  # unbiased, as in the paper
    cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1] = (m2 / denom).T
    cov[:, 1, 0] = cov[:, 0, 1]
    icov = regularised_inverse(cov, min_eigen_ratio, min_variance)
    return keys, means, icov, counts, (nx, ny)


def regularised_inverse(cov: np.ndarray, min_eigen_ratio: float, min_variance: float) -> np.ndarray:
    """Inverse of (M,2,2) covariances with eigenvalues clamped to
    ``>= max(min_eigen_ratio * largest, min_variance)``; returned as (M,3) rows (a, b, c)."""
    w, V = np.linalg.eigh(cov)
    floor = np.maximum(min_eigen_ratio * w[:, 1:2], min_variance)
    w = np.maximum(w, floor)
    inv = (V / w[:, None, :]) @ np.swapaxes(V, 1, 2)
    return np.column_stack([inv[:, 0, 0], 0.5 * (inv[:, 0, 1] + inv[:, 1, 0]), inv[:, 1, 1]])


def build_map(
    slices: Sequence[np.ndarray],
    cell_size: float,
    *,
    min_points: int = 3,
    min_eigen_ratio: float = 1e-3,
    min_variance: float = 1e-4,
    overlap: bool = False,
) -> NDTMap:
    """Build the NDT of every slice (list of (n_k, 2) arrays, metres) at ``cell_size``.

    With ``overlap`` each slice gets Biber's four grids, shifted by half a cell in x, y and both;
    a point then scores in all four. A slice with fewer than ``min_points`` points gets grids
    without cells (it scores zero).
    """
    shifts = [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5)] if overlap else [(0.0, 0.0)]
    origins, shapes, offsets, index_parts = [], [], [], []
    means_parts, icov_parts, count_parts = [], [], []
    slice_grids = [0]
    n_index = 0
    n_cells = 0
    for xy in slices:
        for sx, sy in shifts:
            if len(xy) < min_points:
                origin = np.zeros(2)
                keys = np.zeros(0, np.int64)
                means, icov, counts, (nx, ny) = np.zeros((0, 2)), np.zeros((0, 3)), keys, (1, 1)
            else:
                origin = np.floor(column_bounds(xy)[0] / cell_size - np.array([sx, sy])) * cell_size
                origin = origin + np.array([sx, sy]) * cell_size
                keys, means, icov, counts, (nx, ny) = cell_statistics(
                    xy, origin, cell_size, min_points, min_eigen_ratio, min_variance
                )
            if n_index + nx * ny > MAX_INDEX_CELLS:
                raise ConfigError(
                    f"cell size {cell_size} m is too small for the extent of the scans "
                    f"(more than {MAX_INDEX_CELLS} cells); use larger grid.cell_sizes"
                )
            index = np.full(nx * ny, -1, dtype=np.int32)
            index[keys] = np.arange(n_cells, n_cells + keys.size, dtype=np.int32)
            origins.append(origin)
            shapes.append((nx, ny))
            offsets.append(n_index)
            index_parts.append(index)
            means_parts.append(means)
            icov_parts.append(icov)
            count_parts.append(counts)
            n_index += nx * ny
            n_cells += keys.size
        slice_grids.append(len(origins))
    return NDTMap(
        cell_size=float(cell_size),
        grid_origin=np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 2),
        grid_shape=np.asarray(shapes, dtype=np.int64).reshape(-1, 2),
        grid_offset=np.asarray(offsets, dtype=np.int64),
        slice_grids=np.asarray(slice_grids, dtype=np.int64),
        cell_index=np.concatenate(index_parts).astype(np.int32),
        means=np.ascontiguousarray(np.concatenate(means_parts), dtype=np.float64).reshape(-1, 2),
        icov=np.ascontiguousarray(np.concatenate(icov_parts), dtype=np.float64).reshape(-1, 3),
        counts=np.concatenate(count_parts).astype(np.int64),
    )
