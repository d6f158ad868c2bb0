"""The values each configuration key may take, each violation reported with its key.

Ranges keep every run finite in time and memory (a search of at most 100,000 starts, at most 1000
iterations per level) and physically meaningful (slices within 500 m of the ground, cells of 0.1
to 1000 m). The quality gate may be made stricter than the defaults, never looser: a looser gate
would report wrong registrations as ok.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from ndt_cli.errors import ConfigError

# key: (lowest, highest) allowed value, both inclusive (None: no bound)
RANGES: dict[str, tuple[float | None, float | None]] = {
    "scene.radius_factor": (1.0, 20.0),
    "input.scale": (1e-6, 1e3),
    "input.min_range": (0.0, 1e5),
    "input.max_range": (1e-3, 1e5),
    "input.chunk_points": (10_000, 1_000_000_000),
    "input.memory_mb": (0, 1_000_000),
    "ground.z": (-1e7, 1e7),
    "slices.thickness": (1e-3, 10.0),
    "grid.min_points": (3, 10_000),
    "grid.min_eigen_ratio": (1e-9, 1.0),
    "grid.min_variance": (1e-9, 100.0),
    "source.voxel": (0.0, 10.0),
    "source.points_per_slice": (10, 10_000_000),
    "optimizer.max_iterations": (1, 1000),
    "optimizer.patience": (1, 100),
    "optimizer.lm_lambda": (1e-9, 1e6),
    "optimizer.max_step": (1e-3, 10.0),
    "optimizer.max_rotation_step_deg": (1e-3, 180.0),
    "search.yaw_starts": (1, 360),
    "search.translation_range": (0.0, 500.0),
    "search.translation_step": (0.1, 1000.0),
    "search.points_per_slice": (10, 1_000_000),
    "search.keep_candidates": (2, 64),
    "search.bnb_resolution": (0.1, 10.0),
    "search.bnb_window": (1.0, 500.0),
    "search.bnb_candidates": (2, 64),
    "search.bnb_exclusion": (0.1, 100.0),
    "search.bnb_start_cell": (0.5, 100.0),
    "search.fallback_ratio": (0.5, 1.0),
    "search.free_space_ratio": (0.0, 100.0),
    "search.free_space_share": (0.0, 1.0),
    "search.free_space_penalty": (0.0, 100.0),
    "refine.voxel": (0.01, 5.0),
    "refine.max_distance": (0.01, 50.0),
    "refine.min_distance": (0.001, 50.0),
    "refine.huber": (1e-4, 10.0),
    "refine.iterations": (1, 1000),
    "refine.max_correction": (1e-3, 10.0),
    "quality.overlap_distance": (0.01, 10.0),
    "quality.walk_vouch_free_space": (0.0, 0.005),  # at most what refutes a pose indoors
}
# the gate's thresholds: (default, how a stricter value goes: "up" or "down", the other bound)
GATE: dict[str, tuple[float, str, float]] = {
    "quality.min_score_per_point": (0.0, "up", 10.0),
    "quality.min_overlap": (0.0, "up", 1.0),
    "quality.max_ambiguity": (0.95, "down", 0.0),
    "quality.max_ambiguity_turned": (0.8, "down", 0.0),
    "quality.min_constraint_ratio": (0.01, "up", 1.0),
    "quality.min_constraint_ratio_icp": (0.02, "up", 1.0),
    "quality.max_free_space": (0.10, "down", 0.0),
    "quality.max_free_space_around": (0.05, "down", 0.0),
    "quality.min_kept_evidence": (0.7, "up", 1.0),
}
MAX_STARTS = 100_000  # search.yaw_starts times the translation grid
MAX_LEVELS = 12
HEIGHTS = (-50.0, 500.0)  # m above the ground
CELLS = (0.1, 1000.0)  # m


def _get(c: Any, key: str) -> Any:
    section, name = key.split(".")
    return getattr(getattr(c, section), name)


def _in_range(key: str, value: float, lo: float | None, hi: float | None) -> None:
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigError(f"'{key}' must be between {lo:g} and {hi:g}, got {value:g}")


def _gate(key: str, value: float, default: float, stricter: str, other: float) -> None:
    if (stricter == "up" and value < default) or (stricter == "down" and value > default):
        word = "below" if stricter == "up" else "above"
        raise ConfigError(
            f"'{key}' may not be {word} its default {default:g}, got {value:g}: a looser gate "
            "would report wrong registrations as ok"
        )
    if (stricter == "up" and value > other) or (stricter == "down" and value <= other):
        raise ConfigError(f"'{key}' = {value:g} would reject every registration")


def _lists(c: Any) -> None:
    heights = c.slices.heights
    if not 1 <= len(heights) <= 63:
        raise ConfigError("'slices.heights' must list between 1 and 63 heights")
    for i, h in enumerate(heights):
        _in_range(f"slices.heights[{i}]", h, *HEIGHTS)
    cells = c.grid.cell_sizes
    if not 1 <= len(cells) <= MAX_LEVELS:
        raise ConfigError(f"'grid.cell_sizes' must list between 1 and {MAX_LEVELS} cell sizes")
    for i, s in enumerate(cells):
        _in_range(f"grid.cell_sizes[{i}]", s, *CELLS)
    if any(b >= a for a, b in itertools.pairwise(cells)):
        raise ConfigError("'grid.cell_sizes' must be strictly decreasing (coarse to fine)")


def _relations(c: Any) -> None:
    if c.input.max_range is not None and not c.input.max_range > c.input.min_range:
        raise ConfigError("'input.max_range' must be larger than 'input.min_range'")
    if c.refine.min_distance > c.refine.max_distance:
        raise ConfigError("'refine.min_distance' must not exceed 'refine.max_distance'")
    s = c.search
    if 0.0 < s.free_space_ratio < 1.0:
        raise ConfigError("'search.free_space_ratio' must be 0 (no check) or at least 1")
    if s.bnb_window / s.bnb_resolution > 2000:
        raise ConfigError("'search.bnb_window' over 'search.bnb_resolution' must be <= 2000")
    n = int(s.translation_range / s.translation_step + 1e-9)
    starts = s.yaw_starts * ((2 * n + 1) ** 2 + 1)
    if starts > MAX_STARTS:
        raise ConfigError(
            f"'search': {starts} starts (yaw_starts x the translation grid of translation_range"
            f" / translation_step) is more than {MAX_STARTS}"
        )


def validate(c: Any) -> None:
    """Raise :class:`ConfigError` naming the first key whose value is not allowed."""
    axes_matrix(c.input.axes)
    for key, (lo, hi) in RANGES.items():
        value = _get(c, key)
        if value is not None:
            _in_range(key, value, lo, hi)
    for key, rule in GATE.items():
        _gate(key, _get(c, key), *rule)
    _lists(c)
    _relations(c)


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
