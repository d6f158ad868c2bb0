"""The configuration's sections: frozen dataclasses with defaults (units in the comments), how a
nested dict becomes a :class:`Config`, and the values each key may take.

``configs/default.yaml`` documents every key. Every invalid value raises
:class:`~ndt_cli.errors.ConfigError` naming its key.
"""

from __future__ import annotations

import dataclasses
import itertools
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from ndt_cli.errors import ConfigError

OptimizerName = Literal["newton", "lm_fixed", "lm"]


@dataclass(frozen=True)
class InputConfig:
    """How a file's coordinates become the scanner frame the method works in: metres,
    right-handed, z up (roughly along gravity)."""

    scale: float = 1.0  # file units to metres, e.g. 0.01 for centimetres
    axes: str = "x,y,z"  # file axis that becomes x, y, z, with a sign: "z,-x,y" for x-right y-up
    min_range: float = 0.0  # drop points nearer than this to the origin (tripod, vehicle), m
    max_range: float | None = None  # drop points farther than this from the origin, m (None: keep)
    chunk_points: int = 4_000_000  # LAS/LAZ with more points are streamed in chunks this big


@dataclass(frozen=True)
class GroundConfig:
    """How each scan's ground level is found (z in the scan's own frame, metres)."""

    z: float | None = None  # fixed ground level for both scans; None = estimate per scan
    bin_size: float = 0.05  # height histogram bin for the estimate, m
    level: bool = True  # estimate roll/pitch from the ground plane and level each scan


@dataclass(frozen=True)
class SlicesConfig:
    """Horizontal slices cut out of each scan and projected onto the ground plane."""

    heights: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0, 12.0)  # slice centres above ground, m
    thickness: float = 0.40  # m


@dataclass(frozen=True)
class GridConfig:
    """The NDT grid of the target: one per slice and cell size."""

    cell_sizes: tuple[float, ...] = (20.0, 10.0, 5.0, 2.0, 1.0)  # coarse to fine, m
    min_points: int = 3  # a cell needs this many points to get a normal distribution
    min_eigen_ratio: float = 1e-3  # small covariance eigenvalue clamped to >= ratio * large one
    min_variance: float = 1e-4  # absolute floor of the covariance eigenvalues, m^2
    overlap: bool = False  # Biber's 4 grids shifted by half a cell


@dataclass(frozen=True)
class SourceConfig:
    """How the moving scan's slice points are thinned before scoring."""

    voxel: float = 0.2  # 2D voxel filter of each slice, m (0 = off)
    points_per_slice: int = 20000  # cap per slice after the voxel filter (deterministic sample)


@dataclass(frozen=True)
class OptimizerConfig:
    """The local solver run at every cell size."""

    method: OptimizerName = "newton"
    max_iterations: int = 100  # per cell size and start
    patience: int = 5  # stop after this many iterations without a better score
    lm_lambda: float = 0.01  # lm_fixed: lambda as a multiple of mean diag(J^T J) at the level start
    max_step: float = 0.5  # largest translation step, in cell sizes
    max_rotation_step_deg: float = 15.0  # largest rotation step, degrees


@dataclass(frozen=True)
class SearchConfig:
    """Start search at the coarsest cell size (no initial guess needed)."""

    yaw_starts: int = 12  # start headings spread over 360 degrees
    translation_range: float = 40.0  # starts cover +-range around the aligned slice centroids, m
    translation_step: float = 10.0  # spacing of the translation starts, m
    points_per_slice: int = 1000  # source points per slice used during the search
    keep_candidates: int = 8  # distinct coarse solutions refined down to the finest cell
    refine_offsets: bool = True  # restart finer levels from +-1/2 and +-1 cell offsets too


@dataclass(frozen=True)
class RefineConfig:
    """3D refinement after NDT: robust point-to-plane ICP in full 6-DOF."""

    method: Literal["none", "icp"] = "icp"
    voxel: float = 0.1  # 3D thinning of both scans before ICP, m
    max_distance: float = 1.0  # first correspondence distance, m (shrinks by 0.7 per iteration)
    min_distance: float = 0.1  # final correspondence distance, m
    huber: float = 0.02  # Huber threshold of the point-to-plane residuals, m
    iterations: int = 40
    max_correction: float = 1.0  # larger ICP changes (m, or this many degrees) are not trusted


@dataclass(frozen=True)
class QualityConfig:
    """Thresholds below which a converged registration is reported as suspect."""

    min_score_per_point: float = 0.12  # final NDT score per source slice point
    min_overlap: float = 0.2  # share of source slice points inside a target cell
    max_ambiguity: float = 0.95  # second-best candidate's evidence over the best's
    min_constraint_ratio: float = 0.01  # weakest / strongest translation curvature of the score
    overlap_distance: float = 0.2  # 3D overlap: a source point needs a target point this near, m


@dataclass(frozen=True)
class Config:
    """All settings of a registration."""

    input: InputConfig = field(default_factory=InputConfig)
    ground: GroundConfig = field(default_factory=GroundConfig)
    slices: SlicesConfig = field(default_factory=SlicesConfig)
    grid: GridConfig = field(default_factory=GridConfig)
    source: SourceConfig = field(default_factory=SourceConfig)
    optimizer: OptimizerConfig = field(default_factory=OptimizerConfig)
    search: SearchConfig = field(default_factory=SearchConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)
    quality: QualityConfig = field(default_factory=QualityConfig)

    def __post_init__(self) -> None:
        validate(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (lists instead of tuples), ready for YAML/JSON."""
        return _plain(dataclasses.asdict(self))

    def replace(self, **sections: dict[str, Any]) -> Config:
        """A copy with some keys of some sections changed: ``replace(grid={"overlap": True})``."""
        data = self.to_dict()
        for name, values in sections.items():
            if name not in data:
                raise ConfigError(f"unknown section '{name}'")
            data[name].update(values)
        return from_dict(data)


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj


def axes_matrix(axes: str) -> np.ndarray:
    """3x3 matrix A of an ``input.axes`` string: scanner-frame point = A @ file point.

    >>> axes_matrix("z,-x,y").astype(int).tolist()
    [[0, 0, 1], [-1, 0, 0], [0, 1, 0]]
    """
    parts = [p.strip().lower() for p in axes.split(",")]
    names = [p.lstrip("+-") for p in parts]
    if len(parts) != 3 or sorted(names) != ["x", "y", "z"] or any(len(p) > 2 for p in parts):
        raise ConfigError(
            f"'input.axes' must name x, y and z once each, with an optional sign "
            f'(e.g. "z,-x,y"), got {axes!r}'
        )
    A = np.zeros((3, 3))
    for row, (part, name) in enumerate(zip(parts, names, strict=True)):
        A[row, "xyz".index(name)] = -1.0 if part.startswith("-") else 1.0
    return A


def _convert(value: Any, tp: Any, key: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert (int->float, list->tuple)."""
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert(value, inner[0], key)
    if origin is Literal:
        choices = typing.get_args(tp)
        if value not in choices:
            raise ConfigError(
                f"'{key}' must be one of {', '.join(map(str, choices))}, got {value!r}"
            )
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"'{key}' must be a list, got {type(value).__name__}")
        item_tp = typing.get_args(tp)[0]
        return tuple(_convert(v, item_tp, f"{key}[{i}]") for i, v in enumerate(value))
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"'{key}' must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"'{key}' must be an integer, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"'{key}' must be a string, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"'{key}' must be a number, got {value!r}")
        return float(value)
    raise ConfigError(f"'{key}': unsupported type")  # pragma: no cover - programming error


def _section_from_dict(cls: type, data: Any, prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"'{prefix}' must be a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(
            f"unknown key '{prefix}.{unknown[0]}' (known: {', '.join(sorted(names))})"
            if prefix
            else f"unknown section '{unknown[0]}' (known: {', '.join(sorted(names))})"
        )
    kwargs = {}
    for name, value in data.items():
        key = f"{prefix}.{name}" if prefix else name
        tp = hints[name]
        if dataclasses.is_dataclass(tp):
            kwargs[name] = _section_from_dict(tp, value if value is not None else {}, key)
        else:
            kwargs[name] = _convert(value, tp, key)
    return kwargs if cls is Config else cls(**kwargs)


def from_dict(data: dict[str, Any] | None) -> Config:
    """Build a :class:`Config` from a nested dict; missing keys take their defaults."""
    return Config(**_section_from_dict(Config, data or {}, ""))


# config keys whose value must be > 0
POSITIVE = (
    "source.points_per_slice",
    "optimizer.max_iterations",
    "optimizer.patience",
    "optimizer.lm_lambda",
    "optimizer.max_step",
    "optimizer.max_rotation_step_deg",
    "search.yaw_starts",
    "search.translation_step",
    "search.points_per_slice",
    "search.keep_candidates",
    "refine.voxel",
    "refine.max_distance",
    "refine.min_distance",
    "refine.huber",
    "refine.max_correction",
    "refine.iterations",
    "quality.overlap_distance",
    "input.chunk_points",
)


def validate(c: Config) -> None:
    def positive(key: str, value: float) -> None:
        if not value > 0:
            raise ConfigError(f"'{key}' must be > 0, got {value}")

    positive("input.scale", c.input.scale)
    axes_matrix(c.input.axes)
    if c.input.min_range < 0 or (
        c.input.max_range is not None and not c.input.max_range > c.input.min_range
    ):
        raise ConfigError("'input': need 0 <= min_range < max_range")
    if c.ground.z is not None and not -1e7 < c.ground.z < 1e7:
        raise ConfigError(f"'ground.z' is implausible: {c.ground.z}")
    positive("ground.bin_size", c.ground.bin_size)
    if not 1 <= len(c.slices.heights) <= 63:
        raise ConfigError("'slices.heights' must list between 1 and 63 heights")
    positive("slices.thickness", c.slices.thickness)
    cells = c.grid.cell_sizes
    if not cells:
        raise ConfigError("'grid.cell_sizes' must list at least one cell size")
    for i, s in enumerate(cells):
        positive(f"grid.cell_sizes[{i}]", s)
    if any(b >= a for a, b in itertools.pairwise(cells)):
        raise ConfigError("'grid.cell_sizes' must be strictly decreasing (coarse to fine)")
    if c.grid.min_points < 3:
        raise ConfigError("'grid.min_points' must be >= 3 (a 2D covariance needs 3 points)")
    if not 0 < c.grid.min_eigen_ratio <= 1:
        raise ConfigError("'grid.min_eigen_ratio' must be in (0, 1]")
    positive("grid.min_variance", c.grid.min_variance)
    if c.source.voxel < 0:
        raise ConfigError("'source.voxel' must be >= 0")
    if c.search.translation_range < 0:
        raise ConfigError("'search.translation_range' must be >= 0")
    for key in POSITIVE:
        section, name = key.split(".")
        positive(key, getattr(getattr(c, section), name))
    q = c.quality
    if (
        q.min_score_per_point < 0
        or not 0 <= q.min_overlap <= 1
        or not 0 < q.max_ambiguity <= 1
        or not 0 <= q.min_constraint_ratio < 1
    ):
        raise ConfigError(
            "'quality' thresholds: min_score_per_point >= 0, min_overlap in [0, 1], "
            "max_ambiguity in (0, 1], min_constraint_ratio in [0, 1)"
        )
