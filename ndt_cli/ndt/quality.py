"""The quality gate: how well the winning pose fits, and the status that follows.

A converged result is ``degenerate`` when the smaller over the larger eigenvalue of the NDT
Hessian's translation block, or of ICP's translation information once rotation is free, is below
``quality.min_constraint_ratio``; it is ``suspect`` when its score per point, overlap or
ambiguity misses the thresholds of ``quality``, when ICP moved the pose to where the slices
fit clearly worse, or when the free-space check kept a pose other than the one of most evidence
(:mod:`ndt_cli.ndt.visibility`). Every measure is taken on 1 m cells built with the default
grid settings (:func:`~ndt_cli.ndt.levels.gate_inputs`), whatever the configuration. The order
of precedence: ``no_overlap``, ``not_converged``, ``degenerate``, ``suspect``, ``ok``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.config.schema import QualityConfig
from ndt_cli.ndt.backend import Kernels
from ndt_cli.ndt.grid import NDTMap
from ndt_cli.ndt.kernels import HESS, MATCHED, SCORE, SourcePoints, sym3
from ndt_cli.ndt.refine import Refinement
from ndt_cli.ndt.result import Status

ICP_KEEPS = 0.8  # a refined pose must keep this share of the NDT pose's score on the gate map


@dataclass(frozen=True)
class Fit:
    """How the winning pose fits at the finest cell: score, score per source point, overlap
    (share of (point, grid) pairs in a cell), the 3x3 Hessian of -score, and the ambiguity."""

    score: float
    per_point: float
    overlap: float
    hessian: np.ndarray
    ambiguity: float


def measure_fit(
    ndt: NDTMap, src: SourcePoints, pose: np.ndarray, ambiguity: float, kernels: Kernels
) -> Fit:
    """The :class:`Fit` of ``pose`` (reduced frames) against the finest map."""
    final = kernels.accumulate(ndt, src, pose, True)[0]
    score = float(final[SCORE])
    pairs = int(np.diff(ndt.slice_grids)[src.slice_id].sum())  # points times their slice's grids
    overlap = float(final[MATCHED]) / max(pairs, 1)
    return Fit(score, score / max(len(src), 1), overlap, sym3(final[HESS]), ambiguity)


def weakest_direction(H: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit direction (x, y; target frame) along which translating changes the score least,
    and the ratio of the smallest to the largest curvature of the score in translation."""
    w, V = np.linalg.eigh(H[:2, :2])
    if w[1] <= 0:
        return V[:, 0], 0.0
    return V[:, 0], float(max(w[0], 0.0) / w[1])


def ndt_warnings(fit: Fit, q: QualityConfig) -> tuple[list[str], np.ndarray | None]:
    """Warnings of the NDT fit, and the weak translation direction (levelled target frame, a
    3-vector) when the fit is degenerate."""
    weak, constraint = weakest_direction(fit.hessian)
    degenerate = constraint < q.min_constraint_ratio
    checks = [
        (
            fit.per_point < q.min_score_per_point,
            f"score per point {fit.per_point:.3f} < {q.min_score_per_point}",
        ),
        (fit.overlap < q.min_overlap, f"overlap {fit.overlap:.2f} < {q.min_overlap}"),
        (
            degenerate,
            f"degenerate: translation along ({weak[0]:.2f}, {weak[1]:.2f}) is weakly "
            f"constrained (ratio {constraint:.4f} < {q.min_constraint_ratio})",
        ),
        (
            fit.ambiguity > q.max_ambiguity,
            f"ambiguous: the weaker of the two best solutions has {fit.ambiguity:.2f} of the "
            "stronger's evidence",
        ),
    ]
    direction = np.array([weak[0], weak[1], 0.0]) if degenerate else None
    return [text for bad, text in checks if bad], direction


def icp_warnings(
    refined: Refinement, level: np.ndarray, q: QualityConfig
) -> tuple[list[str], np.ndarray | None]:
    """Warnings of the ICP refinement (a rejected correction, a weak translation), and the weak
    direction in the levelled target frame (``level``: target axes to levelled axes)."""
    if refined.rejected:
        return [refined.rejected], None
    if refined.icp is None:
        return [], None
    weak, constraint = refined.icp.weakest_translation()
    if constraint >= q.min_constraint_ratio:
        return [], None
    weak = level @ weak  # as seen in the levelled target frame
    text = (
        f"degenerate (ICP): translation along ({weak[0]:.2f}, {weak[1]:.2f}, {weak[2]:.2f}) "
        f"is weakly constrained (ratio {constraint:.4f} < {q.min_constraint_ratio})"
    )
    return [text], weak


@dataclass(frozen=True)
class Verdict:
    """Status, warnings and the weakly constrained direction (levelled target frame) if any."""

    status: Status
    warnings: tuple[str, ...]
    weak_direction: np.ndarray | None


def judge(
    fit: Fit,
    converged: bool,
    refined: Refinement,
    level: np.ndarray,
    q: QualityConfig,
    after: Fit | None = None,
    picked: str = "",
) -> Verdict:
    """The verdict on a registration, in the order of precedence of the module docstring.
    ``after``: the fit of the pose after ICP (same map and points as ``fit``), if ICP ran;
    ``picked``: why the pose is not the one of most evidence ('' when it is)."""
    warnings, weak = ndt_warnings(fit, q)
    warnings += [picked] if picked else []
    more, weak_icp = icp_warnings(refined, level, q)
    warnings += more
    if after is not None and not refined.rejected and after.score < ICP_KEEPS * fit.score:
        warnings.append(
            f"ICP moved the pose to where the slices fit worse (score per point "
            f"{fit.per_point:.3f} -> {after.per_point:.3f})"
        )
    weak = weak if weak is not None else weak_icp
    if fit.score <= 0.0:
        status = Status.NO_OVERLAP
    elif not converged:
        status = Status.NOT_CONVERGED
    elif weak is not None:
        status = Status.DEGENERATE
    else:
        status = Status.SUSPECT if warnings else Status.OK
    return Verdict(status, tuple(warnings), weak)
