"""Multi-slice 2D NDT registration of two scans (Ripperda & Brenner 2005), in named stages.

1. **Start search** (no initial guess, :mod:`ndt_cli.ndt.search`): by default the exact global
   branch-and-bound search over (x, y, yaw) (:mod:`ndt_cli.ndt.bnb`), whose best distinct poses
   are the candidates; when its second pose scores nearly as well as its best, the grid of
   Newton starts at the coarsest cell runs too and its candidates join (``search.method:
   starts``: the grid alone). With a guess (:mod:`ndt_cli.ndt.guess`), its headings refined
   from a cell of twice its uncertainty and, when it is uncertain by more than a metre, the
   best poses of a local search within that uncertainty.
2. **Coarse to fine** (:mod:`ndt_cli.ndt.coarse_to_fine`): every candidate refined through the
   finer cell sizes (from ``search.bnb_start_cell`` after the global search), with restarts
   from +-1/2 and +-1 cell offsets at the first of them (after the global search) or at each.
3. **Winner by evidence**: fit-weighted scores over the three finest levels; the second
   distinct candidate's share is the ambiguity. The second replaces the first when the first
   puts clearly more points into the space the other scanner saw to be empty
   (:mod:`ndt_cli.ndt.visibility`); the link is then at least suspect. When the free space
   refutes the favourite or puts many of the kept pose's points into empty space, the global
   search's next distinct poses are refined too (up to :data:`DEEPER_CANDIDATES` in all) and
   every candidate is judged again.
4. **Quality metrics** of the winner at the finest cell (:mod:`ndt_cli.ndt.quality`).
5. **Refinement**: robust point-to-plane ICP in full 6-DOF (:mod:`ndt_cli.ndt.refine`).
6. **Status** from the gate's thresholds and the degeneracy of both Hessians.

Every stage receives its own config section. The compiled kernels are injectable
(:mod:`ndt_cli.ndt.backend`): ``kernels=NUMPY`` runs the whole method on the numpy twins.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ndt_cli.config.scenes import for_scene
from ndt_cli.config.schema import Config
from ndt_cli.core.geometry import Surfaces
from ndt_cli.core.transforms import pose2d_matrix, yaw_of
from ndt_cli.ndt.backend import NUMBA, Kernels
from ndt_cli.ndt.coarse_to_fine import Ranked, Refined, coarse_to_fine, rank, with_verification
from ndt_cli.ndt.grid import NDTMap
from ndt_cli.ndt.guess import Guess, beyond_text, guess_starts, within
from ndt_cli.ndt.kernels import SourcePoints
from ndt_cli.ndt.levels import SourceSampler, TargetMaps, gate_inputs
from ndt_cli.ndt.precompile import search_kernels_ahead
from ndt_cli.ndt.prepare import PreparedScan, load_and_prepare_pair
from ndt_cli.ndt.quality import Fit, Sights, Verdict, measure_fit, verdict_of
from ndt_cli.ndt.refine import Refinement, refine_pose
from ndt_cli.ndt.result import Deeper, LevelStats, RegistrationResult, Rival
from ndt_cli.ndt.rivals import Judged, describe_rival, judge_measured
from ndt_cli.ndt.search import global_start, start_search
from ndt_cli.ndt.terrain import height_offset
from ndt_cli.ndt.visibility import free_space_share, margin, scanner_inside


@dataclass(frozen=True)
class _Start:
    """Candidate poses (reduced frames), the search's level records, the refinement schedule,
    whether each of its levels restarts from the offsets, and how many of the candidates the
    global search gave (0: none)."""

    candidates: np.ndarray
    levels: list[LevelStats]
    schedule: tuple[float, ...]
    restarts: tuple[bool, ...]
    searched: int = 0
    guessed: np.ndarray | None = None  # the initial guess's planar pose (None: no guess)


def _starts(
    target: PreparedScan,
    source: PreparedScan,
    maps: TargetMaps,
    sampler: SourceSampler,
    cfg: Config,
    init: Guess | None,
    guess: np.ndarray | None,
    kernels: Kernels,
) -> _Start:
    """Where the refinement starts. ``init`` replaces the search
    (:func:`~ndt_cli.ndt.guess.guess_starts`).
    ``guess`` is one more candidate beside the search's: it wins only if it fits better, so a
    wrong guess cannot be accepted where the search alone would not accept it."""
    if init is not None:
        p0 = _planar(target, source, np.asarray(init.T_target_source, float))
        starts, levels, schedule = guess_starts(p0, init, cfg, maps, sampler, kernels)
        flags = (cfg.search.refine_offsets,) * len(schedule)
        return _Start(starts, levels, schedule, flags, guessed=p0)
    start = _search(target, source, maps, sampler, cfg, kernels)
    if guess is not None:
        extra = _planar(target, source, np.asarray(guess, float))
        start = replace(start, candidates=np.vstack([start.candidates, extra]))
    return start


def _search(
    target: PreparedScan,
    source: PreparedScan,
    maps: TargetMaps,
    sampler: SourceSampler,
    cfg: Config,
    kernels: Kernels,
) -> _Start:
    """The configured search: the global one (refined from ``bnb_start_cell`` m, restarts at
    that level only), falling back to the start grid too when it is ambiguous or finds no
    overlap at all; or the grid."""
    cells, s = cfg.grid.cell_sizes, cfg.search
    stages, candidates = [], []
    if s.method == "bnb":
        found = global_start(target, source, s, kernels, cfg.slices.heights)
        stages.append(found.level)
        candidates.append(found.candidates)
        if len(found.candidates) and found.ratio < s.fallback_ratio:
            schedule = tuple(c for c in cells if c <= s.bnb_start_cell) or (min(cells),)
            flags = (s.refine_offsets,) + (False,) * (len(schedule) - 1)
            return _Start(found.candidates, stages, schedule, flags, len(found.candidates))
    grid = start_search(target, source, maps, sampler, cells[0], s, cfg.optimizer, kernels)
    stages.append(grid.level)
    candidates.append(grid.candidates)
    schedule = cells[1:] if len(cells) > 1 else cells
    searched = sum(len(c) for c in candidates[:-1])
    return _Start(
        np.vstack(candidates), stages, schedule, (s.refine_offsets,) * len(schedule), searched
    )


def _planar(target: PreparedScan, source: PreparedScan, T: np.ndarray) -> np.ndarray:
    """(tx, ty, yaw) of a 4x4 T_target_source between the scans' reduced, levelled frames."""
    L = target.to_local() @ T @ source.from_local()
    return np.array([L[0, 3], L[1, 3], yaw_of(L)])


def lifted(target: PreparedScan, source: PreparedScan, pose: np.ndarray) -> np.ndarray:
    """The 4x4 ``T_target_source`` (the scans' own frames) of a planar ``pose`` (tx, ty, yaw)
    between their reduced, levelled frames, at the height their ground models agree on
    (:func:`~ndt_cli.ndt.terrain.height_offset`; 0 when they share no measured ground)."""
    tz = height_offset(target.terrain, source.terrain, pose)
    planar = pose2d_matrix(*pose, tz=0.0 if tz is None else tz)
    return target.from_local() @ planar @ source.to_local()


def _refine(
    target: PreparedScan,
    source: PreparedScan,
    T: np.ndarray,
    ok: bool,
    cfg: Config,
    surfaces: Surfaces,
) -> Refinement:
    """ICP from the NDT result ``T`` when it is asked for and NDT found a converged overlap
    (``ok``)."""
    if cfg.refine.method != "icp" or not ok:
        return Refinement(T, start=T)
    return refine_pose(
        target.points3d,
        source.points3d,
        target.reduction,
        source.reduction,
        T,
        cfg.refine,
        cfg.quality.overlap_distance,
        surfaces,
        _scanners(target, source),
    )


def _scanners(target: PreparedScan, source: PreparedScan) -> tuple[np.ndarray, np.ndarray] | None:
    """Both scanners at their frames' origins (m), when both scans are in their scanner's own
    frame (:func:`~ndt_cli.ndt.visibility.scanner_inside`); None when either is not."""
    for scan in (target, source):
        if scan.points3d is None or not scanner_inside(scan.points3d + scan.reduction):
            return None
    return np.zeros(3), np.zeros(3)


DEEPER_CANDIDATES = 16  # distinct poses of the global search refined when its favourite is doubtful
DEEPER_SHARE = 0.03  # a kept pose with more of its points in free space is doubtful (true: 0-2 %)


def _doubtful(judged: Judged, start: _Start) -> bool:
    """The global search gave candidates, and the free space refuted the favourite of the
    refined ones or puts more than :data:`DEEPER_SHARE` of the kept pose's points into space
    the other scanner saw empty."""
    share = float(judged.shares[0]) if len(judged.shares) else float("nan")
    return 0 < start.searched < DEEPER_CANDIDATES and (bool(judged.note) or share > DEEPER_SHARE)


def _deeper(
    target: PreparedScan,
    source: PreparedScan,
    start: _Start,
    refined: Refined,
    run: Callable[[np.ndarray], Refined],
    cfg: Config,
    kernels: Kernels,
) -> Refined:
    """``refined`` joined by the global search's next distinct poses, up to
    :data:`DEEPER_CANDIDATES` in all, refined through the same schedule. The search's score
    counts the points that land near target points, so a street turned by 180 degrees or slid
    until the two scanners stand together, where each scan's densely seen surroundings meet the
    other's, can outscore the truth by a sixth (scans 46 m apart on a busy street: the truth
    was its ninth distinct pose); when the free space doubts the refined candidates
    (:func:`_doubtful`), the truth may be further down the search's list. The first picks of
    the search do not depend on how many are asked, so the new ones are the poses after those
    refined."""
    more = replace(cfg.search, bnb_candidates=DEEPER_CANDIDATES)
    found = global_start(target, source, more, kernels, cfg.slices.heights)
    extra = found.candidates[start.searched :]
    if len(extra) == 0:
        return refined
    second = run(extra)
    return replace(refined.joined(second), levels=(*refined.levels, found.level, *second.levels))


def _allowed(
    refined: Refined, schedule: Sequence[float], start: _Start, init: Guess | None
) -> Ranked:
    """The refined candidates by evidence, those beyond the initial guess's reach dropped
    (:func:`~ndt_cli.ndt.guess.within`)."""
    ranked = rank(refined, schedule[-1])
    return ranked if start.guessed is None else within(ranked, start.guessed, init)


def _judged(ranked: Ranked, target: PreparedScan, source: PreparedScan, cfg: Config) -> Judged:
    """The candidates judged by what the scanners saw (:func:`~ndt_cli.ndt.rivals.
    judge_measured`); nothing is measured, and nothing refuted, for scans that cannot say
    what they saw or with the check off."""
    s, q = cfg.search, cfg.quality
    ambiguity = (q.max_ambiguity, min(q.max_ambiguity, q.max_ambiguity_turned))
    sights = (target.sight, source.sight)
    measure = None
    if s.free_space_ratio > 0.0 and sights[0] is not None and sights[1] is not None:
        gap = margin(cfg.refine.voxel)

        def measure(k: int) -> float:
            return free_space_share(*sights, lifted(target, source, ranked.poses[k]), gap)

    return judge_measured(ranked, measure, s.free_space_ratio, s.free_space_share, ambiguity)


def _rivals(
    judged: Judged,
    target: PreparedScan,
    source: PreparedScan,
    gate: tuple[NDTMap, SourcePoints],
    kernels: Kernels,
) -> tuple[Rival, ...]:
    """The winner's rivals as records: each pose lifted to the scans' frames, with its Hessian
    on the gate's cells."""
    r, out = judged.ranked, []
    for k in judged.rivals:
        pose = r.poses[k]
        share = float(judged.shares[k])
        evidence = float(r.evidence[k] / max(r.evidence[0], 1e-300))
        hessian = measure_fit(*gate, pose, 0.0, kernels).hessian
        text = describe_rival(r.poses[0], pose, evidence, share)
        out.append(Rival(lifted(target, source, pose), hessian, evidence, share, text))
    return tuple(out)


def _final_free_space(
    target: PreparedScan, source: PreparedScan, T: np.ndarray, cfg: Config
) -> tuple[float, float]:
    """The free-space shares of the final pose, in each direction's bin alone and around it
    (NaN when the check is off or a scan cannot say what it saw)."""
    if cfg.search.free_space_ratio <= 0.0 or target.sight is None or source.sight is None:
        return float("nan"), float("nan")
    gap = margin(cfg.refine.voxel)
    return tuple(
        free_space_share(target.sight, source.sight, T, gap, around) for around in (False, True)
    )


@dataclass(frozen=True)
class _Stages:
    """What the stages found, as the result needs it."""

    levels: tuple[LevelStats, ...]
    converged: bool
    ranked: Ranked
    fit: Fit
    refinement: Refinement
    verdict: Verdict
    points_per_slice: tuple[int, ...]
    sights: Sights
    score_final: float
    shares: np.ndarray
    rivals: tuple[Rival, ...]
    scene: str
    deeper: Deeper


def register_prepared(
    target: PreparedScan,
    source: PreparedScan,
    cfg: Config,
    init: Guess | np.ndarray | None = None,
    kernels: Kernels = NUMBA,
    guess: np.ndarray | None = None,
    deeper: bool = True,
) -> RegistrationResult:
    """Register prepared scans. ``init``: a :class:`Guess` (or a 4x4 T_target_source, within
    1 m and 5 degrees) to start from instead of the search (the poses it allows are judged, a
    final pose beyond its reach is suspect: :mod:`ndt_cli.ndt.guess`); ``guess``: a 4x4
    T_target_source added to the search's candidates (a loop closure's pose from the network),
    never trusted more than the search; ``deeper``: refine the search's next distinct poses
    when the free space doubts the first ones (:func:`_deeper`); a campaign's probes of pairs
    that may not overlap at all leave it to the pairs of its plan (the result says it was
    skipped)."""
    if init is not None and not isinstance(init, Guess):
        init = Guess(np.asarray(init, float))
    t_start = time.perf_counter()
    maps = TargetMaps(target.slices, cfg.grid)
    sampler = SourceSampler(source.slices, cfg.source)
    start = _starts(target, source, maps, sampler, cfg, init, guess, kernels)
    schedule = with_verification(start.schedule)
    restarts = start.restarts + (start.restarts[-1],) * (len(schedule) - len(start.restarts))

    def run(candidates: np.ndarray) -> Refined:
        return coarse_to_fine(candidates, schedule, maps, sampler, cfg.optimizer, restarts, kernels)

    refined = run(start.candidates)
    judged = _judged(_allowed(refined, schedule, start, init), target, source, cfg)
    depth = Deeper.SKIPPED if _doubtful(judged, start) else Deeper.NONE
    if depth is Deeper.SKIPPED and deeper:
        refined = _deeper(target, source, start, refined, run, cfg, kernels)
        judged = _judged(_allowed(refined, schedule, start, init), target, source, cfg)
        depth = Deeper.DONE
    ranked = judged.ranked
    gate_map, gate_points = gate_inputs(
        maps, sampler, target.slices, source.slices, cfg.grid, cfg.source
    )
    fit = measure_fit(gate_map, gate_points, ranked.poses[0], ranked.ambiguity, kernels)
    rivals = _rivals(judged, target, source, (gate_map, gate_points), kernels)
    converged = bool(ranked.converged[0]) if judged.note else refined.converged
    T = lifted(target, source, ranked.poses[0])
    t_ndt = time.perf_counter() - t_start
    refinement = _refine(target, source, T, fit.score > 0.0 and converged, cfg, kernels.surfaces)
    moved = _planar(target, source, refinement.T) if refinement.icp is not None else None
    after = None if moved is None else measure_fit(gate_map, gate_points, moved, 0.0, kernels)
    second = float(judged.shares[1]) if len(judged.shares) > 1 else float("nan")
    final, around = _final_free_space(target, source, refinement.T, cfg)
    sights = Sights(final, second, judged.note, around, judged.kept_evidence)
    p0 = start.guessed
    beyond = "" if p0 is None else beyond_text(_planar(target, source, refinement.T), p0, init)
    verdict = verdict_of(
        fit, converged, refinement, target.level, cfg.quality, sights, rivals, beyond
    )
    per_slice = tuple(int(n) for n in sampler.fine.per_slice(len(source.slices)))
    stages = _Stages(
        (*start.levels, *refined.levels),
        converged,
        ranked,
        fit,
        refinement,
        verdict,
        per_slice,
        sights,
        float("nan") if after is None else after.per_point,
        judged.shares,
        rivals,
        cfg.scene.kind,
        depth,
    )
    timings = {
        "grid_s": maps.build_s,
        "ndt_s": t_ndt - maps.build_s,
        "refine_s": time.perf_counter() - t_start - t_ndt,
    }
    return _result(target, source, stages, time.perf_counter() - t_start, timings)


def _vertical(scan: PreparedScan) -> str:
    """How a scan's vertical was found ("given" with ``ground.z``)."""
    return "given" if scan.vertical is None else scan.vertical.source.value


def _result(
    target: PreparedScan,
    source: PreparedScan,
    s: _Stages,
    runtime_s: float,
    timings: dict[str, float],
) -> RegistrationResult:
    icp = s.refinement.icp
    return RegistrationResult(
        T_target_source=s.refinement.T,
        status=s.verdict.status,
        converged=s.converged,
        score=s.fit.score,
        score_per_point=s.fit.per_point,
        overlap=s.fit.overlap,
        points_per_slice=s.points_per_slice,
        levels=s.levels,
        candidates=s.ranked.records(s.shares),
        hessian=s.fit.hessian,
        ground_z_target=target.ground_z,
        ground_z_source=source.ground_z,
        runtime_s=runtime_s,
        target=target.label,
        source=source.label,
        warnings=s.verdict.warnings,
        icp_rms=float("nan") if icp is None else icp.rms,
        icp_inliers=0 if icp is None else icp.inliers,
        icp_hessian=None if icp is None else icp.hessian,
        icp_rejected=s.refinement.rejection is not None,
        overlap_3d=float("nan") if icp is None else icp.overlap,
        weak_direction=s.verdict.weak_direction,
        timings=timings,
        reduction_target=target.reduction,
        reduction_source=source.reduction,
        level_target=target.level,
        level_source=source.level,
        icp_centroid=None if icp is None else icp.centroid,
        T_ndt=s.refinement.start,
        free_space=s.sights.final,
        free_space_around=s.sights.around,
        free_space_second=s.sights.second,
        score_per_point_final=s.score_final,
        notes=s.verdict.notes,
        refuted=s.verdict.refuted,
        vertical_target=_vertical(target),
        vertical_source=_vertical(source),
        rivals=s.rivals,
        scene=s.scene,
        deeper=s.deeper,
    )


def _indoors(*scans: PreparedScan) -> bool:
    """Every scan sees a ceiling over it (:mod:`ndt_cli.ndt.ceiling`)."""
    return all(s.ceiling is not None and s.ceiling.indoors for s in scans)


def register(
    target: str | Path | np.ndarray,
    source: str | Path | np.ndarray,
    config: Config | str | Path | None = None,
    init: Guess | np.ndarray | None = None,
    kernels: Kernels = NUMBA,
) -> RegistrationResult:
    """Register SOURCE onto TARGET; the result's ``T_target_source`` maps source to target.

    ``target``/``source`` are point files (PLY, LAS/LAZ, E57, PCD, xyz/txt/csv) or (N,3) arrays
    in metres; ``config`` a :class:`~ndt_cli.config.Config`, a YAML path or ``None`` for the
    defaults (``scene.kind`` auto: the interior settings when both scans see a ceiling);
    ``init`` an optional guess of ``T_target_source``: a :class:`Guess` with its uncertainty,
    or a 4x4 matrix (within 1 m and 5 degrees); no guess: a start search is run;
    ``kernels`` the compiled kernels or their numpy twins (:mod:`ndt_cli.ndt.backend`).
    """
    from ndt_cli.config import load

    t0 = time.perf_counter()
    cfg = config if isinstance(config, Config) else load(config)
    with search_kernels_ahead(enabled=kernels is NUMBA):  # on an empty cache: the other core
        tgt, src = load_and_prepare_pair(target, source, cfg, kernels)
        if cfg.scene.kind == "auto":
            cfg = for_scene(cfg, "indoor" if _indoors(tgt, src) else "street")
            if cfg.scene.kind == "indoor":  # cut again below the ceiling
                tgt, src = load_and_prepare_pair(target, source, cfg, kernels)
    t_read = time.perf_counter() - t0
    result = register_prepared(tgt, src, cfg, init, kernels)
    timings = {"read_prepare_s": t_read, **result.timings}
    return replace(result, runtime_s=time.perf_counter() - t0, timings=timings)
