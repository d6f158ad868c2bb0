"""Where a registration with an initial guess starts (:class:`Guess`: a pose and how far it
may be off): the guess's headings refined from a cell as coarse as twice its uncertainty, and,
when that cell is coarser than 2 m, a local search around it; the coarse to fine refinement
and the judge (:mod:`ndt_cli.ndt.rivals`) then treat every pose found within the guess's
reach (:func:`within`) as they treat the global search's candidates."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ndt_cli.config.schema import Config
from ndt_cli.core.transforms import wrap_angle
from ndt_cli.ndt.backend import Kernels
from ndt_cli.ndt.coarse_to_fine import VERIFY_CELLS, Ranked, coarse_to_fine
from ndt_cli.ndt.levels import SourceSampler, TargetMaps, level_stats, run_level
from ndt_cli.ndt.result import LevelStats
from ndt_cli.ndt.search import distinct_indices


@dataclass(frozen=True)
class Guess:
    """An initial guess of ``T_target_source`` (4x4, the scans' own frames) and how far it may
    be from the truth: ``sigma_m`` (m) and ``sigma_deg`` (degrees); a GNSS position or a
    placement by hand is within about 1 m and 5 degrees."""

    T_target_source: np.ndarray
    sigma_m: float = 1.0
    sigma_deg: float = 5.0


ALL_ROUND_DEG = 45.0  # a guess this uncertain in heading is searched all round


def first_cell(cells: Sequence[float], sigma_m: float) -> float:
    """The cell size (m) a guess within ``sigma_m`` starts at: the smallest configured cell of
    at least twice its uncertainty (restarts at +-1 cell then cover it), the coarsest when none
    is that large. Coarser levels would let a good guess slide away: on a busy street the
    truth itself, refined from 20 m cells, ended 16.6 m along the street."""
    wide = [c for c in cells if c >= 2.0 * sigma_m]
    return min(wide) if wide else max(cells)


def guess_starts(
    p0: np.ndarray,
    init: Guess,
    cfg: Config,
    maps: TargetMaps,
    sampler: SourceSampler,
    kernels: Kernels,
) -> tuple[np.ndarray, list[LevelStats], tuple[float, ...]]:
    """Candidates around the guess ``p0`` (tx, ty m, yaw rad between the scans' reduced,
    levelled frames), the levels run to find them and the schedule they are refined through.
    Its heading and +-``sigma_deg`` are refined from :func:`first_cell` down. Where that cell
    is coarser than the first verification cell (2 m; ``sigma_m`` above 1 m on a street's
    cells), the guess is also searched locally at 2 m cells (:func:`_local_starts`), and from
    2 m on all these poses are refined together and judged: a coarse cell lets a guess slide
    along a uniform scene (a busy street, a guess 2 m and 2 degrees off: 3.3 m along it from
    5 m cells, at the truth from 2 m), and every pose within the guess's uncertainty that fits
    is a candidate, a pose slid along the scene that fits about as well a rival, as it is to the
    global search. (Indoors, whose cells start at 2 m, the local search made 2 more scans of the
    sweep's office floors ok and 1 of them wrong: it is not run there.)"""
    cells, flags = cfg.grid.cell_sizes, cfg.search.refine_offsets
    turns = [0.0] if init.sigma_deg < 2.0 else [0.0, -init.sigma_deg, init.sigma_deg]
    if init.sigma_deg >= ALL_ROUND_DEG:  # a position without a heading: every 15 degrees
        turns = list(np.arange(-180.0, 180.0, 15.0))
    starts = p0[None, :] + np.radians(np.array(turns))[:, None] * np.array([0.0, 0.0, 1.0])
    first, verify = first_cell(cells, init.sigma_m), VERIFY_CELLS[0]
    coarse = tuple(c for c in cells if verify < c <= first)
    levels: list[LevelStats] = []
    if coarse:
        slid = coarse_to_fine(starts, coarse, maps, sampler, cfg.optimizer, flags, kernels)
        local, level = _local_starts(starts, init.sigma_m, maps, sampler, cfg, kernels)
        starts, levels = np.vstack([slid.candidates, starts, local]), [*slid.levels, level]
    schedule = tuple(c for c in cells if c <= min(first, verify)) or VERIFY_CELLS
    return starts, levels, schedule


LOCAL_STEPS = 4  # the local search's grid: 2 * LOCAL_STEPS + 1 positions a side


def _local_starts(
    headings: np.ndarray,
    sigma_m: float,
    maps: TargetMaps,
    sampler: SourceSampler,
    cfg: Config,
    kernels: Kernels,
) -> tuple[np.ndarray, LevelStats]:
    """The best distinct poses (``search.keep_candidates``) of Newton runs at the first
    verification cell (2 m) from every heading at a grid of positions within +-``sigma_m`` of
    the guess (steps of at most 1 m, the cell's reach; at most :data:`LOCAL_STEPS` a side), as
    :func:`~ndt_cli.ndt.search.start_search` does for the whole scene, and the level's
    record."""
    t0, cell = time.perf_counter(), VERIFY_CELLS[0]
    n = min(LOCAL_STEPS, int(np.ceil(sigma_m / (cell / 2.0))))
    steps = sigma_m * np.arange(-n, n + 1) / n
    grid = np.array([[x, y, 0.0] for x in steps for y in steps])
    starts = (headings[:, None, :] + grid[None, :, :]).reshape(-1, 3)
    points = sampler.at(cell, cfg.search.points_per_slice)
    res = run_level(maps(cell), points, starts, cfg.optimizer, kernels)
    keep = distinct_indices(res.params, res.score, cfg.search.keep_candidates, cell)
    best = int(np.argmax(res.score))
    return res.params[keep], level_stats(cell, res, best, len(starts), len(points), t0)


GUESS_REACH = 3.0  # sigmas: a pose farther from the guess is not one the guess allows


def reach_of(pose: np.ndarray, p0: np.ndarray, init: Guess) -> tuple[float, float, bool]:
    """How far planar ``pose`` is from the guess ``p0`` (tx, ty m, yaw rad; the scans'
    reduced frames): metres, degrees, and whether that is beyond :data:`GUESS_REACH` times
    its uncertainty (a guess of 45 degrees or more allows every heading)."""
    metres = float(np.hypot(pose[0] - p0[0], pose[1] - p0[1]))
    degrees = abs(float(np.degrees(wrap_angle(pose[2] - p0[2]))))
    far = metres > GUESS_REACH * init.sigma_m
    turned = init.sigma_deg < ALL_ROUND_DEG and degrees > GUESS_REACH * init.sigma_deg
    return metres, degrees, bool(far or turned)


def within(ranked: Ranked, p0: np.ndarray, init: Guess) -> Ranked:
    """The candidates the guess allows (:func:`reach_of`), in their order; all of them when it
    allows none (the verdict then says the pose is beyond the guess)."""
    keep = [k for k, pose in enumerate(ranked.poses) if not reach_of(pose, p0, init)[2]]
    if not keep or len(keep) == len(ranked.poses):
        return ranked
    return Ranked(
        ranked.poses[keep], ranked.scores[keep], ranked.evidence[keep], ranked.converged[keep]
    )


def beyond_text(pose: np.ndarray, p0: np.ndarray, init: Guess) -> str:
    """The verdict's warning when the final ``pose`` is beyond the guess's reach ('' when not)."""
    metres, degrees, far = reach_of(pose, p0, init)
    if not far:
        return ""
    return (
        f"the pose is {metres:.2f} m and {degrees:.1f} deg from the guess, beyond "
        f"{GUESS_REACH:g} times its uncertainty ({init.sigma_m:.2g} m, {init.sigma_deg:.2g} deg)"
    )
