"""Result objects of a registration (frozen; arrays are float64, metres and degrees)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ndt_cli.transforms import yaw_of


@dataclass(frozen=True)
class LevelStats:
    """One cell size of the coarse-to-fine schedule, for the winning start."""

    cell_size: float  # m
    starts: int  # poses optimised in parallel at this level
    iterations: int  # iterations of the winning start
    score: float  # final NDT score (sum over slices and points)
    score_per_point: float
    converged: bool  # stopped because the score stopped improving
    time_s: float


@dataclass(frozen=True)
class Candidate:
    """A distinct solution of the start search, refined to the finest cell size."""

    tx: float  # m, reduced frames
    ty: float
    yaw_deg: float
    score: float  # at the finest cell size
    evidence: float  # fit-weighted score summed over the finest levels (the winner's is highest)


@dataclass(frozen=True)
class RegistrationResult:
    """Outcome of registering SOURCE onto TARGET.

    ``T_target_source`` (4x4) maps source points into the target frame: ``p_t = T @ p_s``.
    ``status`` is ``ok``; ``degenerate`` (converged, but a translation direction is weakly
    constrained, as along a straight corridor: ``degenerate`` names it, in the levelled target
    frame); ``suspect`` (converged, but below a quality threshold: see ``warnings``);
    ``not_converged``; or ``no_overlap`` (score zero). ``converged``: the finest level stopped
    because its score stopped improving.
    ``hessian`` is the 3x3 Hessian of f = -score in (tx [m], ty [m], yaw [rad]) at the solution;
    ``icp_hessian`` the 6x6 normal matrix of ICP (rotation vector [rad], translation [m]; target
    frame), None without ICP. ``overlap_3d``: share of the moving scan's thinned points with a
    target point within ``quality.overlap_distance`` after ICP (NaN without ICP).
    """

    T_target_source: np.ndarray
    status: str
    converged: bool
    score: float
    score_per_point: float
    overlap: float  # share of source slice points inside a target cell at the finest level
    points_per_slice: tuple[int, ...]
    levels: tuple[LevelStats, ...]
    candidates: tuple[Candidate, ...]
    hessian: np.ndarray
    ground_z_target: float  # m, target frame
    ground_z_source: float  # m, source frame
    runtime_s: float
    target: str | None = None
    source: str | None = None
    warnings: tuple[str, ...] = field(default=())
    icp_rms: float = float("nan")  # RMS of the inlier point-to-plane distances after ICP, m
    icp_inliers: int = 0
    icp_hessian: np.ndarray | None = None
    overlap_3d: float = float("nan")
    degenerate: str = ""  # the weakly constrained direction, empty when there is none
    timings: dict[str, float] = field(default_factory=dict)  # s: grid_s, ndt_s, refine_s

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def iterations(self) -> int:
        return sum(level.iterations for level in self.levels)

    @property
    def translation(self) -> np.ndarray:
        return self.T_target_source[:3, 3].copy()

    @property
    def yaw_deg(self) -> float:
        return float(np.degrees(yaw_of(self.T_target_source)))

    @property
    def hessian_eigenvalues(self) -> np.ndarray:
        """Eigenvalues (ascending) of the NDT Hessian :attr:`hessian`."""
        return np.linalg.eigvalsh(self.hessian)

    @property
    def icp_hessian_eigenvalues(self) -> np.ndarray:
        """Eigenvalues (ascending) of :attr:`icp_hessian`; empty without ICP."""
        return np.zeros(0) if self.icp_hessian is None else np.linalg.eigvalsh(self.icp_hessian)

    @property
    def ambiguity(self) -> float:
        """Evidence of the second-best distinct candidate over the best (0: unique, 1: a tie)."""
        if len(self.candidates) < 2 or self.candidates[0].evidence <= 0:
            return 0.0
        return float(self.candidates[1].evidence / self.candidates[0].evidence)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        tx, ty, tz = self.translation
        return {
            "target": self.target,
            "source": self.source,
            "status": self.status,
            "converged": self.converged,
            "T_target_source": self.T_target_source.tolist(),
            "tx": tx,
            "ty": ty,
            "tz": tz,
            "yaw_deg": self.yaw_deg,
            "score": self.score,
            "score_per_point": self.score_per_point,
            "overlap": self.overlap,
            "ambiguity": self.ambiguity,
            "points_per_slice": list(self.points_per_slice),
            "iterations": self.iterations,
            "levels": [vars(level) for level in self.levels],
            "candidates": [vars(c) for c in self.candidates],
            "hessian": self.hessian.tolist(),
            "ground_z_target": self.ground_z_target,
            "ground_z_source": self.ground_z_source,
            "runtime_s": self.runtime_s,
            "warnings": list(self.warnings),
            "icp_rms": self.icp_rms,
            "icp_inliers": self.icp_inliers,
            "overlap_3d": self.overlap_3d,
            "degenerate": self.degenerate,
            "hessian_eigenvalues": self.hessian_eigenvalues.tolist(),
            "icp_hessian": None if self.icp_hessian is None else self.icp_hessian.tolist(),
            "icp_hessian_eigenvalues": self.icp_hessian_eigenvalues.tolist(),
            "timings": dict(self.timings),
        }
