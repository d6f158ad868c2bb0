"""Local solvers for the planar pose p = (tx, ty, phi) (metres, radians), many starts at once.

All three take an ``evaluate(P) -> accumulators`` callback (see :mod:`ndt_cli.ndt.kernels`) that
scores a batch of poses in one kernel call, and stop a start when its score has not improved for
``patience`` iterations or after ``max_iterations``. Each returns, per start, the pose with the
best score it visited. Steps are capped at ``max_step`` cells of translation and
``max_rotation_step_deg`` of rotation (the score is flat outside a cell: longer steps are guesses).

- ``newton`` minimises f(p) = -score(p) with H dp = -g. H is made positive definite by replacing
  its eigenvalues by their absolute values, floored at 1e-6 of the largest (a saddle then gives a
  descent step instead of an ascent one); a step that does not raise the score is rejected and
  retried at half length from the same pose.
- ``lm_fixed`` (the paper's eq. 4) minimises E(p) = 1/2 sum_j (1 - s_j(p))^2 over (point, grid)
  pairs, s_j the score of pair j, with (J^T J + lambda I) dp = -J^T r, r = 1 - s, J = dr/dp, a fixed
  lambda = ``lm_lambda`` * mean diag(J^T J) taken at the first iteration, and every update accepted.
- ``lm`` minimises the same E with the classic adaptive lambda: it starts at
  1e-2 * mean diag(J^T J); a step that lowers E is accepted and lambda divided by 10, otherwise
  the step is rejected and lambda multiplied by 10.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ndt_cli.config.schema import OptimizerConfig
from ndt_cli.ndt.kernels import ERR, GRAD, HESS, JTJ, JTR, SCORE, sym3

Evaluator = Callable[[np.ndarray], np.ndarray]
_STILL_M = 1e-3  # a best pose that moved less than this (m) ...
_STILL_RAD = 1e-5  # ... and this (rad) over the last ``patience`` iterations has converged
_STEP_M = 1e-4  # a start whose step is below this (m) ...
_STEP_RAD = 1e-6  # ... and this (rad) has converged
_REL_IMPROVEMENT = 1e-6  # a score must rise by this fraction to count as improved (sub-mm)


@dataclass(frozen=True)
class BatchResult:
    """Outcome per start: best pose (S,3), its score, iterations used, whether it converged
    (its score stopped improving for ``patience`` iterations, or its best pose moved less than
    1 mm and 1e-5 rad over the last ``patience`` iterations), and the best score after each
    iteration (``trace[k]`` for iteration k, NaN once a start has stopped)."""

    params: np.ndarray
    score: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    trace: np.ndarray
    evaluations: int
    path: np.ndarray  # (iterations, S, 4): pose (tx, ty, phi) and score of each start's current
    # state after every iteration (NaN once a start has stopped)


def _newton_steps(acc: np.ndarray) -> np.ndarray:
    H = sym3(acc[:, HESS])
    g = acc[:, GRAD]
    w, V = np.linalg.eigh(H)
    w = np.abs(w)
    w = np.maximum(w, np.maximum(1e-6 * w.max(axis=1, keepdims=True), 1e-12))
    return -np.einsum("sij,sj->si", V / w[:, None, :], np.einsum("sji,sj->si", V, g))


def _lm_steps(acc: np.ndarray, lam: np.ndarray) -> np.ndarray:
    A = sym3(acc[:, JTJ]) + lam[:, None, None] * np.eye(3)
    A[:, np.arange(3), np.arange(3)] += 1e-12  # no match at all: A = 0, step 0
    return -np.linalg.solve(A, acc[:, JTR][:, :, None])[:, :, 0]


def _cap(steps: np.ndarray, max_t: float, max_r: float) -> np.ndarray:
    nt = np.linalg.norm(steps[:, :2], axis=1)
    nr = np.abs(steps[:, 2])
    scale = np.minimum(
        1.0, np.minimum(max_t / np.maximum(nt, 1e-300), max_r / np.maximum(nr, 1e-300))
    )
    return steps * scale[:, None]


def _mean_diag(acc: np.ndarray) -> np.ndarray:
    return sym3(acc[:, JTJ])[:, np.arange(3), np.arange(3)].mean(axis=1)


def _still(moved: np.ndarray, tol_m: float, tol_rad: float) -> np.ndarray:
    """Per pose change (S,3): below ``tol_m`` in translation and ``tol_rad`` in yaw?"""
    return (np.hypot(moved[:, 0], moved[:, 1]) < tol_m) & (np.abs(moved[:, 2]) < tol_rad)


def optimize(
    evaluate: Evaluator, p0: np.ndarray, cfg: OptimizerConfig, cell_size: float
) -> BatchResult:
    """Run ``cfg.method`` from every start in ``p0`` (S,3); see the module docstring."""
    p = np.array(p0, dtype=np.float64).reshape(-1, 3)
    n = len(p)
    acc = evaluate(p)
    evaluations = n
    best_p = p.copy()
    best = acc[:, SCORE].copy()
    iters = np.zeros(n, dtype=np.int64)
    stall = np.zeros(n, dtype=np.int64)
    tiny = np.zeros(n, dtype=bool)
    active = np.ones(n, dtype=bool)
    alpha = np.ones(n)
    lam = (cfg.lm_lambda if cfg.method == "lm_fixed" else 1e-2) * _mean_diag(acc)
    max_t = cfg.max_step * cell_size
    max_r = np.radians(cfg.max_rotation_step_deg)
    trace = []
    history = []  # best pose of every start after each iteration
    path = []
    while active.any():
        idx = np.flatnonzero(active)
        a = acc[idx]
        if cfg.method == "newton":
            steps = _newton_steps(a) * alpha[idx, None]
        else:
            steps = _lm_steps(a, lam[idx])
        step = _cap(steps, max_t, max_r)
        prop = p[idx] + step
        new = evaluate(prop)
        evaluations += len(idx)
        iters[idx] += 1
        if cfg.method == "newton":
            accept = new[:, SCORE] > a[:, SCORE]
            alpha[idx] = np.where(accept, 1.0, 0.5 * alpha[idx])
        elif cfg.method == "lm":
            accept = new[:, ERR] < a[:, ERR]
            lam[idx] = np.where(accept, lam[idx] / 10.0, lam[idx] * 10.0)
        else:
            accept = np.ones(len(idx), dtype=bool)
        p[idx[accept]] = prop[accept]
        acc[idx[accept]] = new[accept]
        improved = new[:, SCORE] > best[idx] + _REL_IMPROVEMENT * np.abs(best[idx])
        best[idx[improved]] = new[improved, SCORE]
        best_p[idx[improved]] = prop[improved]
        stall[idx] = np.where(improved, 0, stall[idx] + 1)
        active[idx] = (stall[idx] < cfg.patience) & (iters[idx] < cfg.max_iterations)
        history.append(best_p.copy())
        # a step that moves the pose by less than 0.1 mm / 1e-6 rad changes nothing more
        tiny[idx] = _still(step, _STEP_M, _STEP_RAD)
        active[idx] &= ~tiny[idx]
        row = np.full(n, np.nan)
        row[idx] = best[idx]
        trace.append(row)
        state = np.full((n, 4), np.nan)
        state[idx, :3] = p[idx]
        state[idx, 3] = acc[idx, SCORE]
        path.append(state)
    # converged: the score stopped improving, or the best pose stopped moving (creeping gains
    # of cell-boundary effects can keep the score rising by tiny amounts until max_iterations)
    converged = stall >= cfg.patience
    converged |= tiny  # stopped by a vanishing step
    if len(history) > cfg.patience:
        converged |= _still(history[-1] - history[-1 - cfg.patience], _STILL_M, _STILL_RAD)
    return BatchResult(
        params=best_p,
        score=best,
        iterations=iters,
        converged=converged,
        trace=np.array(trace).reshape(len(trace), n),
        evaluations=evaluations,
        path=np.array(path).reshape(len(path), n, 4),
    )
