"""What every level of the coarse-to-fine schedule scores: target maps, source points, starts.

The target's NDT maps are built once per cell size on first use. The moving scan's slice points
of a level are voxel-filtered to a tenth of its cell (at least ``source.voxel``): a 20 m cell
needs no 0.2 m detail, and this halves the time of a registration at unchanged results.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from ndt_cli.config.schema import GridConfig, OptimizerConfig, SourceConfig
from ndt_cli.ndt.backend import Kernels
from ndt_cli.ndt.grid import NDTMap, build_map
from ndt_cli.ndt.kernels import SourcePoints
from ndt_cli.ndt.optimize import BatchResult, optimize
from ndt_cli.ndt.result import LevelStats
from ndt_cli.ndt.slicing import subsample, voxel_filter_2d

VOXEL_PER_CELL = 0.1  # source points of a level are thinned to a tenth of its cell
GATE_CELL = 1.0  # m: the quality gate judges every result on 1 m cells built with the defaults


class TargetMaps:
    """Target NDT maps (one per cell size, all slices), built on first use."""

    def __init__(self, slices: Sequence[np.ndarray], grid: GridConfig) -> None:
        self._slices = slices
        self._grid = grid
        self._maps: dict[float, NDTMap] = {}
        self.build_s = 0.0  # time spent building maps, s

    def __call__(self, cell: float) -> NDTMap:
        if cell not in self._maps:
            t0 = time.perf_counter()
            g = self._grid
            self._maps[cell] = build_map(
                self._slices,
                cell,
                min_points=g.min_points,
                min_eigen_ratio=g.min_eigen_ratio,
                min_variance=g.min_variance,
                overlap=g.overlap,
            )
            self.build_s += time.perf_counter() - t0
        return self._maps[cell]


def source_points(slices: Sequence[np.ndarray], voxel: float, cap: int) -> SourcePoints:
    """Slice points voxel-filtered at ``voxel`` m, at most ``cap`` per slice (deterministic)."""
    return SourcePoints.from_slices(
        [subsample(voxel_filter_2d(s, voxel), cap, seed=k) for k, s in enumerate(slices)]
    )


class SourceSampler:
    """The moving scan's slice points at the density each level needs."""

    def __init__(self, slices: Sequence[np.ndarray], source: SourceConfig) -> None:
        self._slices = slices
        self.voxel = source.voxel
        self.cap = source.points_per_slice
        self.fine = source_points(slices, self.voxel, self.cap)  # the finest level's points

    def at(self, cell: float, cap: int | None = None) -> SourcePoints:
        """Points of a level: voxel-filtered at a tenth of the cell (at least ``source.voxel``),
        at most ``cap`` (never more than ``source.points_per_slice``) per slice."""
        voxel = max(self.voxel, cell * VOXEL_PER_CELL)
        if voxel == self.voxel and cap is None:
            return self.fine
        return source_points(self._slices, voxel, min(cap or self.cap, self.cap))


Evaluator = Callable[[np.ndarray], np.ndarray]


def evaluator(ndt: NDTMap, src: SourcePoints, method: str, kernels: Kernels) -> Evaluator:
    """Pose scorer of one level: the accumulators of a batch of poses (S,3)."""
    lm = method != "newton"  # Newton needs no Levenberg-Marquardt terms
    return lambda P: kernels.accumulate(ndt, src, P, lm)


def run_level(
    ndt: NDTMap,
    src: SourcePoints,
    starts: np.ndarray,
    optimizer: OptimizerConfig,
    kernels: Kernels,
) -> BatchResult:
    """Optimise every start (S,3) at one level in one batch."""
    return optimize(
        evaluator(ndt, src, optimizer.method, kernels), starts, optimizer, ndt.cell_size
    )


def level_stats(
    cell: float, res: BatchResult, winner: int, n_starts: int, n_points: int, t0: float
) -> LevelStats:
    """The record of a level, for the start that won it."""
    return LevelStats(
        cell,
        n_starts,
        int(res.iterations[winner]),
        float(res.score[winner]),
        float(res.score[winner] / max(n_points, 1)),
        bool(res.converged[winner]),
        time.perf_counter() - t0,
    )


def gate_inputs(
    maps: TargetMaps,
    sampler: SourceSampler,
    target_slices: Sequence[np.ndarray],
    source_slices: Sequence[np.ndarray],
    grid: GridConfig,
    source: SourceConfig,
) -> tuple[NDTMap, SourcePoints]:
    """The map and points on which the quality gate judges a result: 1 m cells and the default
    grid and thinning settings, whatever the configuration (the gate's thresholds mean the same
    for every config; a config with huge cell variances cannot make a poor fit look good)."""
    default_grid = GridConfig(cell_sizes=grid.cell_sizes)
    if grid == default_grid and source == SourceConfig():
        return maps(GATE_CELL), sampler.fine
    fixed = TargetMaps(target_slices, GridConfig(cell_sizes=(GATE_CELL,)))
    return fixed(GATE_CELL), SourceSampler(source_slices, SourceConfig()).fine
