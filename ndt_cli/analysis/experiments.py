"""The paper's experiments on the user's own scans: score profiles, convergence basin, optimisers.

Every function works from the aligned pose of the pair (reduced frames, see
:mod:`ndt_cli.ndt.prepare`) and returns plain rows (dicts) whose keys carry their units; the CLI
writes them as CSV and plots them.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from ndt_cli.config.schema import Config
from ndt_cli.core.transforms import pose2d_matrix, wrap_angle, yaw_of
from ndt_cli.ndt.kernels import SCORE, SourcePoints, accumulate
from ndt_cli.ndt.levels import SourceSampler, TargetMaps
from ndt_cli.ndt.optimize import optimize
from ndt_cli.ndt.prepare import PreparedScan
from ndt_cli.ndt.register import Guess, register_prepared
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.workers import Failure, default_jobs, threads_per_job


@dataclass(frozen=True)
class Pair:
    """A prepared pair and its aligned pose p = (tx, ty, phi) in the reduced frames."""

    target: PreparedScan
    source: PreparedScan
    aligned: np.ndarray

    @classmethod
    def make(
        cls, target: PreparedScan, source: PreparedScan, cfg: Config, at: np.ndarray | None
    ) -> Pair:
        """``at``: 4x4 T_target_source of the aligned pose; None registers the pair first."""
        T = register_prepared(target, source, cfg).T_target_source if at is None else at
        local = target.to_local() @ T @ source.from_local()
        return cls(target, source, np.array([local[0, 3], local[1, 3], yaw_of(local)]))

    def to_matrix(self, p: np.ndarray) -> np.ndarray:
        """4x4 T_target_source of a reduced-frame pose."""
        return self.target.from_local() @ pose2d_matrix(*p, tz=0.0) @ self.source.to_local()


def _first_slices(src: SourcePoints, k: int) -> SourcePoints:
    keep = src.slice_id < k
    return SourcePoints(np.ascontiguousarray(src.xy[keep]), src.slice_id[keep])


def rotation_profile(
    pair: Pair, cfg: Config, cell: float, step_deg: float = 2.0
) -> list[dict[str, Any]]:
    """Score as the source turns from -180 to 180 degrees about its slice centroid, for the
    first 1..k slices (the paper's figs. 3 and 11). Rows: slices, rotation_deg, score,
    score_per_point."""
    maps = TargetMaps(pair.target.slices, cfg.grid)
    src = SourceSampler(pair.source.slices, cfg.source).fine
    tx, ty, phi = pair.aligned
    c, s = np.cos(phi), np.sin(phi)
    centre = np.array([[c, -s], [s, c]]) @ pair.source.centroid() + [tx, ty]
    deltas = np.radians(np.arange(-180.0, 180.0 + 1e-9, step_deg))
    poses = []
    for d in deltas:
        R = np.array([[np.cos(d), -np.sin(d)], [np.sin(d), np.cos(d)]])
        poses.append([*(R @ ([tx, ty] - centre) + centre), phi + d])
    rows = []
    for k in range(1, len(cfg.slices.heights) + 1):
        part = _first_slices(src, k)
        scores = accumulate(maps(cell), part, np.array(poses))[:, SCORE]
        for d, score in zip(deltas, scores, strict=True):
            rows.append(
                {
                    "slices": k,
                    "rotation_deg": round(float(np.degrees(d)), 6),
                    "score": score,
                    "score_per_point": score / max(len(part), 1),
                }
            )
    return rows


def translation_profile(
    pair: Pair,
    cfg: Config,
    cell: float,
    x_range: tuple[float, float] = (-100.0, 100.0),
    y_range: tuple[float, float] = (-30.0, 40.0),
    step: float = 2.0,
) -> list[dict[str, Any]]:
    """Score as the aligned source is shifted over a grid (target frame axes; the paper's figs. 4
    and 12), for the first 1..k slices. Rows: slices, dx_m, dy_m, score, score_per_point."""
    maps = TargetMaps(pair.target.slices, cfg.grid)
    src = SourceSampler(pair.source.slices, cfg.source).fine
    xs = np.arange(x_range[0], x_range[1] + 1e-9, step)
    ys = np.arange(y_range[0], y_range[1] + 1e-9, step)
    grid = np.array([[dx, dy] for dx in xs for dy in ys])
    poses = np.column_stack([pair.aligned[:2] + grid, np.full(len(grid), pair.aligned[2])])
    rows = []
    for k in range(1, len(cfg.slices.heights) + 1):
        part = _first_slices(src, k)
        scores = accumulate(maps(cell), part, poses)[:, SCORE]
        for (dx, dy), score in zip(grid, scores, strict=True):
            rows.append(
                {
                    "slices": k,
                    "dx_m": round(float(dx), 6),
                    "dy_m": round(float(dy), 6),
                    "score": score,
                    "score_per_point": score / max(len(part), 1),
                }
            )
    return rows


BASIN_VARIANTS = ("1 slice, single start", "all slices, single start", "all slices, multi-start")


def _variant_config(cfg: Config, variant: str) -> Config:
    if variant.startswith("1 slice"):
        cfg = cfg.replace(slices={"heights": list(cfg.slices.heights[:1])})
    # the NDT basin itself: no ICP after it
    return cfg.replace(
        search={"refine_offsets": variant.endswith("multi-start")}, refine={"method": "none"}
    )


def _basin_task(
    target: Any,
    source: Any,
    cfg: Config,
    aligned: np.ndarray,
    variant: str,
    offsets: np.ndarray,
    tol: tuple[float, float],
) -> list[dict[str, Any]]:
    """Register from every offset start (a worker task); one row per start."""
    vcfg = _variant_config(cfg, variant)
    k = len(vcfg.slices.heights)  # the variant's slices are the first k of the full set
    target = replace(target, slices=target.slices[:k])
    source = replace(source, slices=source.slices[:k])
    pair = Pair(target, source, aligned)
    wide = max(vcfg.grid.cell_sizes) / 2.0  # the paper's basin: the whole schedule from the start
    rows = []
    for dx, dy, dyaw in offsets:
        start = aligned + np.array([dx, dy, np.radians(dyaw)])
        init = Guess(pair.to_matrix(start), sigma_m=wide, sigma_deg=1.0)  # its heading only
        result = register_prepared(target, source, vcfg, init=init)
        local = target.to_local() @ result.T_target_source @ source.from_local()
        err_t = float(np.hypot(local[0, 3] - aligned[0], local[1, 3] - aligned[1]))
        err_r = float(abs(np.degrees(wrap_angle(yaw_of(local) - aligned[2]))))
        rows.append(
            {
                "variant": variant,
                "start_dx_m": dx,
                "start_dy_m": dy,
                "start_dyaw_deg": dyaw,
                "start_distance_m": float(np.hypot(dx, dy)),
                "final_error_m": err_t,
                "final_error_deg": err_r,
                "success": err_t <= tol[1] and err_r <= tol[0],
            }
        )
    return rows


def basin_offsets(
    max_translation: float, translation_step: float, max_yaw: float, yaw_step: float
) -> np.ndarray:
    """(N,3) start offsets (dx m, dy m, dyaw deg): a square grid of translations times yaws."""
    t = np.arange(-max_translation, max_translation + 1e-9, translation_step)
    y = np.arange(-max_yaw, max_yaw + 1e-9, yaw_step)
    return np.array(list(itertools.product(t, t, y)), dtype=float)


def basin(
    pair: Pair,
    cfg: Config,
    offsets: np.ndarray,
    *,
    variants: Sequence[str] = BASIN_VARIANTS,
    tol: tuple[float, float] = (0.3, 0.15),
    jobs: int | None = None,
) -> list[dict[str, Any]]:
    """Register from many start offsets around the aligned pose, per variant (the paper's
    fig. 17). Runs in parallel processes; rows in a fixed order whatever ``jobs`` is."""
    jobs = default_jobs(jobs)
    chunks = np.array_split(offsets, max(1, min(len(offsets), 4 * jobs)))
    tasks = {
        (v, i): partial(_basin_task, pair.target, pair.source, cfg, pair.aligned, v, chunk, tol)
        for v in variants
        for i, chunk in enumerate(chunks)
        if len(chunk)
    }
    pool = WorkerPool(jobs, threads_per_job(jobs))
    try:
        results = dict(pool.run(tasks))
    finally:
        pool.close()
    rows: list[dict[str, Any]] = []
    for key in tasks:
        value = results[key]
        if isinstance(value, Failure):
            raise RuntimeError(f"basin task {key} failed: {value}")
        rows.extend(value)
    return rows


def success_rates(rows: list[dict[str, Any]], bin_m: float) -> list[dict[str, Any]]:
    """Success rate per variant and start-distance bin (m)."""
    out = []
    for variant in dict.fromkeys(r["variant"] for r in rows):
        mine = [r for r in rows if r["variant"] == variant]
        bins = sorted({int(r["start_distance_m"] // bin_m) for r in mine})
        for b in bins:
            sel = [r["success"] for r in mine if int(r["start_distance_m"] // bin_m) == b]
            out.append(
                {
                    "variant": variant,
                    "start_distance_from_m": b * bin_m,
                    "start_distance_to_m": (b + 1) * bin_m,
                    "starts": len(sel),
                    "success_rate": float(np.mean(sel)),
                }
            )
    return out


def optimizer_traces(
    pair: Pair,
    cfg: Config,
    start_offset: tuple[float, float, float],
    schedules: dict[str, Sequence[float]],
) -> list[dict[str, Any]]:
    """Score and pose after every iteration of each optimiser through its cell schedule, from
    the aligned pose plus ``start_offset`` (dx m, dy m, dyaw deg); the paper's figs. 14-16.
    Rows: method, cell_m, iteration (counted over all levels), score, tx_m, ty_m, yaw_deg in
    the target frame (of the reduced pose, i.e. relative to the reduction points)."""
    rows = []
    src = SourceSampler(pair.source.slices, cfg.source).fine
    maps = TargetMaps(pair.target.slices, cfg.grid)
    for method, cells in schedules.items():
        ocfg = replace(cfg.optimizer, method=method)
        offset = np.array([start_offset[0], start_offset[1], np.radians(start_offset[2])])
        p = (pair.aligned + offset)[None]
        iteration = 0
        for cell in cells:
            ndt = maps(cell)
            res = optimize(lambda P, m=ndt: accumulate(m, src, P), p, ocfg, cell)
            for state in res.path[:, 0, :]:
                if np.isnan(state[3]):
                    break
                iteration += 1
                rows.append(
                    {
                        "method": method,
                        "cell_m": cell,
                        "iteration": iteration,
                        "score": state[3],
                        "tx_m": state[0],
                        "ty_m": state[1],
                        "yaw_deg": float(np.degrees(wrap_angle(state[2]))),
                    }
                )
            p = res.params
    return rows
