"""The start search: where the coarse-to-fine refinement begins when there is no initial guess.

``search.method: bnb`` (:func:`global_start`): the exact global search of
:mod:`ndt_cli.ndt.bnb` over every heading and every translation of a window on a likelihood
field of the target slices; its best distinct poses are the candidates, and the refinement
starts at 5 m cells. ``search.method: starts`` (:func:`start_search`, below):

At the coarsest cell size the solver starts from ``search.yaw_starts`` headings times a grid of
translations around the pose that puts the source's slice centroid onto the target's, plus the
paper's zero translation at every heading, all in one batch. The ``search.keep_candidates``
best distinct solutions go on to the finer levels. Starting from zero alone finds the heading
but not the position along a street, where facades give almost no gradient.

Cost: ``yaw_starts * ((2 * range / step + 1)^2 + 1)`` starts (984 with the defaults) times the
search points (``search.points_per_slice`` per slice) per iteration.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ndt_cli.config.schema import OptimizerConfig, SearchConfig
from ndt_cli.core.transforms import pose2d_matrix, wrap_angle, yaw_of
from ndt_cli.ndt.backend import Kernels
from ndt_cli.ndt.bnb import (
    FIELD_MAX,
    PENALTY_MAX,
    ScoreField,
    likelihood_field,
    penalised,
    pixel_centres,
    search_field,
)
from ndt_cli.ndt.levels import SourceSampler, TargetMaps, level_stats, run_level
from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.ndt.result import LevelStats
from ndt_cli.ndt.visibility import free_at_heights

MIN_SEPARATION_DEG = 10.0  # poses closer than this in yaw and half a cell apart are one


def search_starts(target: PreparedScan, source: PreparedScan, search: SearchConfig) -> np.ndarray:
    """(S,3) start poses (reduced frames): every start yaw times a translation grid around the
    pose that aligns the slice centroids, plus every start yaw at zero translation in the scans'
    own frames (the paper's p0 = 0)."""
    c_target, c_source = target.centroid(), source.centroid()
    yaws = 2 * np.pi * np.arange(search.yaw_starts) / search.yaw_starts
    n = int(np.floor(search.translation_range / search.translation_step + 1e-9))
    offsets = search.translation_step * np.arange(-n, n + 1)
    ox, oy = np.meshgrid(offsets, offsets, indexing="ij")
    grid = np.column_stack([ox.ravel(), oy.ravel()])
    starts = []
    for yaw in yaws:
        c, si = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -si], [si, c]])
        starts.append(np.column_stack([c_target - R @ c_source + grid, np.full(len(grid), yaw)]))
        zero = target.to_local() @ pose2d_matrix(0.0, 0.0, yaw) @ source.from_local()
        starts.append(np.array([[zero[0, 3], zero[1, 3], yaw_of(zero)]]))
    return np.concatenate(starts)


def distinct_indices(params: np.ndarray, scores: np.ndarray, k: int, cell: float) -> np.ndarray:
    """Indices of up to ``k`` best poses that differ by more than half a cell or 10 degrees.

    At least the best pose is kept, even when it scores zero.
    """
    picked: list[int] = []
    for i in np.argsort(-scores, kind="stable"):
        p = params[i]
        if picked and scores[i] <= 0:
            break
        if all(
            np.hypot(*(p[:2] - params[j, :2])) > 0.5 * cell
            or abs(wrap_angle(p[2] - params[j, 2])) > np.radians(MIN_SEPARATION_DEG)
            for j in picked
        ):
            picked.append(int(i))
            if len(picked) == k:
                break
    return np.array(picked, dtype=np.int64)


@dataclass(frozen=True)
class StartSearch:
    """Distinct candidate poses (K,3) in the reduced frames, the record of the level, and (bnb)
    the second distinct pose's score over the best's."""

    candidates: np.ndarray
    level: LevelStats
    ratio: float = float("nan")


def search_field_of(
    target: PreparedScan, resolution: float, heights: Sequence[float], penalty: float
) -> ScoreField:
    """The target's likelihood field at ``resolution`` m; with ``penalty`` > 0 (points on a
    target pixel) and a scanner whose sight is known, a point landing in space it saw empty at
    the slice's height (``heights``, m above the ground, one per slice) costs that much."""
    field = likelihood_field(target.slices, resolution=resolution)
    if penalty <= 0 or len(heights) != field.values.shape[0]:
        return field
    free = free_at_heights(target, pixel_centres(field), heights)
    if free is None:
        return field
    cost = round(min(penalty * FIELD_MAX, PENALTY_MAX))
    return penalised(field, free.reshape(field.values.shape), cost)


def global_start(
    target: PreparedScan,
    source: PreparedScan,
    search: SearchConfig,
    kernels: Kernels,
    heights: Sequence[float] = (),
) -> StartSearch:
    """The best distinct poses of the exact global search (:mod:`ndt_cli.ndt.bnb`); ``heights``
    (m above the ground, one per slice) place the slices for ``search.free_space_penalty``."""
    t0 = time.perf_counter()
    field = search_field_of(target, search.bnb_resolution, heights, search.free_space_penalty)
    found = search_field(
        field,
        source.slices,
        window=search.bnb_window,
        candidates=search.bnb_candidates,
        exclusion=search.bnb_exclusion,
        kernels=kernels.search,
    )
    found = replace(found, time_s=time.perf_counter() - t0)
    best = float(found.scores[0]) if len(found.scores) else 0.0
    level = LevelStats(
        search.bnb_resolution,
        found.nodes,
        0,
        best,
        best / max(found.n_points, 1),
        True,
        found.time_s,
    )
    return StartSearch(found.poses, level, float(found.ratio))


def start_search(
    target: PreparedScan,
    source: PreparedScan,
    maps: TargetMaps,
    sampler: SourceSampler,
    cell: float,
    search: SearchConfig,
    optimizer: OptimizerConfig,
    kernels: Kernels,
) -> StartSearch:
    """Optimise every start at the coarsest ``cell`` and keep the best distinct solutions."""
    t0 = time.perf_counter()
    coarse = sampler.at(cell, search.points_per_slice)
    starts = search_starts(target, source, search)
    res = run_level(maps(cell), coarse, starts, optimizer, kernels)
    keep = distinct_indices(res.params, res.score, search.keep_candidates, cell)
    best = int(np.argmax(res.score))
    return StartSearch(res.params[keep], level_stats(cell, res, best, len(starts), len(coarse), t0))
