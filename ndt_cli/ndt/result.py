"""Result objects of a registration (frozen; arrays are float64, metres and degrees)."""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from enum import StrEnum
from typing import Any

import numpy as np

from ndt_cli.core.transforms import yaw_of


class Status(StrEnum):
    """Outcome of one registration; the value is what CSV and JSON files hold.

    ``ok``; ``degenerate`` (converged, but a translation direction is weakly constrained, as
    along a straight corridor); ``suspect`` (converged, but below a quality threshold);
    ``not_converged``; ``no_overlap`` (score zero); ``failed`` (a link of a chain that could not
    be registered at all, e.g. an unreadable scan).
    """

    OK = "ok"
    DEGENERATE = "degenerate"
    SUSPECT = "suspect"
    NOT_CONVERGED = "not_converged"
    NO_OVERLAP = "no_overlap"
    FAILED = "failed"


class Deeper(StrEnum):
    """Whether the global search's next distinct poses were refined (see
    :func:`ndt_cli.ndt.register.register_prepared`): ``none`` (not needed: the free space did
    not doubt the refined candidates, or the search did not run), ``skipped`` (doubted, but not
    asked for: a campaign's placement probe), ``done``."""

    NONE = "none"
    SKIPPED = "skipped"
    DONE = "done"


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

    def describe(self) -> str:
        """One line for logs: cell size, iterations, score and time."""
        return (
            f"{self.cell_size:g} m: {self.iterations} it, score {self.score:.0f}, "
            f"{self.time_s:.2f} s"
        )


@dataclass(frozen=True)
class Candidate:
    """A distinct solution of the start search, refined to the finest cell size."""

    tx: float  # m, reduced frames
    ty: float
    yaw_deg: float
    score: float  # at the finest cell size
    evidence: float  # fit-weighted score over the finest levels; the kept pose's is highest
    # unless the free-space check refuted those of more (ndt_cli.ndt.rivals)
    free_space: float = float("nan")  # share of the points it puts into free space (NaN:
    # not measured)


@dataclass(frozen=True, repr=False)
class Rival:
    """A second pose the data cannot tell from the kept one (:mod:`ndt_cli.ndt.rivals`):
    ``T_target_source`` (4x4, the scans' own frames; the slices' pose, before any ICP), the NDT
    Hessian there (3x3, -score in tx m, ty m, yaw rad, on the gate's cells), its share of the
    kept pose's evidence, its free-space share (NaN: not measured) and how it differs from the
    kept pose, in words."""

    T_target_source: np.ndarray
    hessian: np.ndarray
    evidence: float
    free_space: float
    text: str

    def __repr__(self) -> str:
        return f"Rival({self.text})"

    def to_dict(self) -> dict[str, Any]:
        return {
            "T_target_source": self.T_target_source.tolist(),
            "hessian": self.hessian.tolist(),
            "evidence": self.evidence,
            "free_space": self.free_space,
            "text": self.text,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Rival:
        return cls(
            np.array(d["T_target_source"], dtype=float),
            np.array(d["hessian"], dtype=float),
            float(d["evidence"]),
            float(d["free_space"]),
            str(d["text"]),
        )


def describe_direction(v: np.ndarray | None) -> str:
    """Text of a weakly constrained translation direction ('' when there is none)."""
    if v is None:
        return ""
    return f"translation along ({v[0]:.2f}, {v[1]:.2f}, {v[2]:.2f})"


@dataclass(frozen=True)
class RegistrationResult:
    """Outcome of registering SOURCE onto TARGET.

    ``T_target_source`` (4x4) maps source points into the target frame: ``p_t = T @ p_source``.
    ``status`` is a :class:`Status`; ``converged``: the finest level stopped because its score
    stopped improving. ``weak_direction`` is the unit translation direction (levelled target
    frame) that a degenerate result cannot determine, None when every direction is constrained.
    ``hessian`` is the 3x3 Hessian of f = -score in (tx [m], ty [m], yaw [rad]) at the solution;
    ``icp_hessian`` the 6x6 normal matrix of ICP (rotation vector [rad], translation [m]; target
    frame), None without ICP. ``overlap_3d``: share of the moving scan's thinned points with a
    target point within ``quality.overlap_distance`` after ICP (NaN without ICP).
    """

    T_target_source: np.ndarray
    status: Status
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
    target: str | None = None  # the scans' files as given (None: registered from an array)
    source: str | None = None
    warnings: tuple[str, ...] = field(default=())
    icp_rms: float = float("nan")  # RMS of the inlier point-to-plane distances after ICP, m
    icp_inliers: int = 0
    icp_hessian: np.ndarray | None = None
    icp_rejected: bool = False  # ICP ran but its correction was not applied (see warnings)
    overlap_3d: float = float("nan")
    weak_direction: np.ndarray | None = None
    timings: dict[str, float] = field(default_factory=dict)  # s: grid_s, ndt_s, refine_s
    # the frames the link's uncertainty refers to: each scan's reduction point (scan frame, m)
    # and levelling rotation (scan axes -> levelled axes); the ICP matches' centroid (target's
    # reduced frame, m; None without ICP)
    reduction_target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    reduction_source: np.ndarray = field(default_factory=lambda: np.zeros(3))
    level_target: np.ndarray = field(default_factory=lambda: np.eye(3))
    level_source: np.ndarray = field(default_factory=lambda: np.eye(3))
    icp_centroid: np.ndarray | None = None
    # the NDT result before the refinement (4x4 like T_target_source; None when not kept)
    T_ndt: np.ndarray | None = None
    # share of the checked points the final pose puts into space the other scanner saw empty
    # (ndt_cli.ndt.visibility; NaN when the check cannot run), and the slices' score per point
    # at the final pose (NaN without ICP)
    free_space: float = float("nan")
    score_per_point_final: float = float("nan")
    free_space_second: float = float("nan")  # that of the second-best pose
    free_space_around: float = float("nan")  # the final pose's, in front of all that was seen
    # around each direction (ndt_cli.ndt.visibility)
    notes: tuple[str, ...] = field(default=())  # what the gate checked and let pass
    refuted: bool = False  # the data contradict the pose (ndt_cli.ndt.quality.verdict_of)
    # how each scan's vertical was found (ndt_cli.ndt.vertical.VerticalSource; "given": ground.z)
    vertical_target: str = ""
    vertical_source: str = ""
    rivals: tuple[Rival, ...] = ()  # poses the data cannot tell from this one: ambiguous
    scene: str = "street"  # the settings it was registered with (ndt_cli.config.scenes)
    deeper: Deeper = Deeper.NONE  # whether the search's next poses were refined

    def __repr__(self) -> str:
        rot = f"yaw {self.yaw_deg:.4f} deg"
        tx, ty, tz = self.translation
        return (
            f"RegistrationResult({self.status.value}, t = ({tx:.4f}, {ty:.4f}, {tz:.4f}) m, "
            f"{rot}, score/point {self.score_per_point:.3f}, overlap {self.overlap:.2f}, "
            f"ambiguity {self.ambiguity:.2f}, {self.runtime_s:.2f} s)"
        )

    @property
    def ok(self) -> bool:
        return self.status is Status.OK

    @property
    def labels(self) -> tuple[str, str]:
        """The target's and source's names as the outputs show them (an array: ``<array>``)."""
        return _label(self.target), _label(self.source)

    @property
    def degenerate(self) -> str:
        """Text of :attr:`weak_direction` ('' when there is none)."""
        return describe_direction(self.weak_direction)

    @property
    def T_reduced(self) -> np.ndarray:
        """``T_target_source`` between the scans' reduced frames (each scan minus its
        reduction point): small numbers whatever the georeference."""
        A, B = np.eye(4), np.eye(4)
        A[:3, 3], B[:3, 3] = -self.reduction_target, self.reduction_source
        return A @ self.T_target_source @ B

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
        """Evidence of the weaker of the first two distinct candidates over the stronger's (0:
        unique, 1: a tie); the first is the kept pose, normally the one of most evidence."""
        if len(self.candidates) < 2:
            return 0.0
        weak, strong = sorted(c.evidence for c in self.candidates[:2])
        return float(weak / strong) if strong > 0 else 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: every field, plus values derived from them for readers of the file."""
        tx, ty, tz = self.translation
        return {
            "target": self.target,
            "source": self.source,
            "status": self.status.value,
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
            "icp_hessian": _list(self.icp_hessian),
            "icp_rejected": self.icp_rejected,
            "icp_hessian_eigenvalues": self.icp_hessian_eigenvalues.tolist(),
            "timings": dict(self.timings),
            "weak_direction": _list(self.weak_direction),
            "reduction_target": _list(self.reduction_target),
            "reduction_source": _list(self.reduction_source),
            "level_target": _list(self.level_target),
            "level_source": _list(self.level_source),
            "icp_centroid": _list(self.icp_centroid),
            "T_ndt": _list(self.T_ndt),
            "free_space": self.free_space,
            "free_space_second": self.free_space_second,
            "free_space_around": self.free_space_around,
            "score_per_point_final": self.score_per_point_final,
            "notes": list(self.notes),
            "refuted": self.refuted,
            "vertical_target": self.vertical_target,
            "vertical_source": self.vertical_source,
            "rivals": [r.to_dict() for r in self.rivals],
            "scene": self.scene,
            "deeper": self.deeper.value,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RegistrationResult:
        """The result that :meth:`to_dict` described (derived values are ignored)."""
        names = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in names}
        kw.update(
            T_target_source=np.array(d["T_target_source"], dtype=float),
            status=Status(d["status"]),
            deeper=Deeper(d.get("deeper", Deeper.NONE)),
            points_per_slice=tuple(d["points_per_slice"]),
            levels=tuple(LevelStats(**lv) for lv in d["levels"]),
            candidates=tuple(Candidate(**c) for c in d["candidates"]),
            hessian=np.array(d["hessian"], dtype=float),
            warnings=tuple(d["warnings"]),
            notes=tuple(d.get("notes", ())),
            icp_hessian=_array(d.get("icp_hessian")),
            weak_direction=_array(d.get("weak_direction")),
            timings=dict(d.get("timings", {})),
            reduction_target=np.array(d["reduction_target"], dtype=float),
            reduction_source=np.array(d["reduction_source"], dtype=float),
            level_target=np.array(d["level_target"], dtype=float),
            level_source=np.array(d["level_source"], dtype=float),
            icp_centroid=_array(d.get("icp_centroid")),
            T_ndt=_array(d.get("T_ndt")),
            rivals=tuple(Rival.from_dict(r) for r in d.get("rivals", ())),
        )
        return cls(**kw)


def _label(name: str | None) -> str:
    return "<array>" if name is None else name


def _list(a: np.ndarray | None) -> list | None:
    return None if a is None else np.asarray(a).tolist()


def _array(v: list | None) -> np.ndarray | None:
    return None if v is None else np.array(v, dtype=float)
