"""The scans of an export: each one's file and pose, and what its header (or a first pass over
its points) says about it.

An :class:`ExportScan` is a point file with the pose that maps its raw coordinates to the world
frame; a :class:`ScanInput` adds its header summary and, when the format needs them and the
header lacks them, its point count, bounding box and attribute ranges from a first pass over
the points (:func:`scan_inputs`). Used by :mod:`ndt_cli.io.export` and its writers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.io.records import Chunk, Summary, iter_records, summary


@dataclass(frozen=True, eq=False)
class ExportScan:
    """One scan to export.

    ``path``: its point file (``FILE.e57#K`` for scan K of a multi-scan E57). ``name``: its
    unique name in the outputs (per-scan files are named after it). ``index``: its number, stored
    per point as ``scan_index`` (0..65535). ``T_world_file``: 4x4 mapping the file's raw
    coordinates (before ``input.scale`` / ``input.axes``) to the world frame, metres, i.e.
    ``T_world_scan @ S_scan_file``. ``S_scan_file``: 4x4 from raw file coordinates to the scanner
    frame (``input.scale`` times ``axes_matrix(input.axes)``; identity by default), used by the
    E57 output only. ``anchor``: the scan whose CRS the outputs carry (default: the first).
    """

    path: str | Path
    name: str
    index: int
    T_world_file: np.ndarray
    S_scan_file: np.ndarray = field(default_factory=lambda: np.eye(4))
    anchor: bool = False

    def __post_init__(self) -> None:
        for attr in ("T_world_file", "S_scan_file"):
            m = np.array(getattr(self, attr), dtype=np.float64)
            if m.shape != (4, 4) or not np.isfinite(m).all():
                raise ValueError(f"{attr} of scan {self.name!r} must be a finite 4x4 matrix")
            m.setflags(write=False)
            object.__setattr__(self, attr, m)
        if not 0 <= int(self.index) <= 65535:
            raise ValueError(f"scan index {self.index} of {self.name!r} is not in 0..65535")

    @classmethod
    def from_pose(
        cls,
        path: str | Path,
        name: str,
        index: int,
        T_world_scan: np.ndarray,
        *,
        scale: float = 1.0,
        axes: str = "x,y,z",
        anchor: bool = False,
    ) -> ExportScan:
        """A scan from its registered pose ``T_world_scan`` (scanner frame to world, metres) and
        the ``input.scale`` / ``input.axes`` its file needs (see ``InputConfig``)."""
        from ndt_cli.config import axes_matrix

        S = np.eye(4)
        S[:3, :3] = scale * axes_matrix(axes)
        return cls(path, name, index, np.asarray(T_world_scan, float) @ S, S, anchor)

    @property
    def T_world_scan(self) -> np.ndarray:
        """4x4 pose: scanner frame (metres) to world frame, ``T_world_file @ inv(S_scan_file)``."""
        return self.T_world_file @ np.linalg.inv(self.S_scan_file)


@dataclass(frozen=True)
class ScanInput:
    """A scan with its header summary and, after a first pass when the header has none, its
    bounding box (file frame, m) and the (min, max) of its float attributes."""

    scan: ExportScan
    summary: Summary
    count: int
    bounds: tuple[np.ndarray, np.ndarray] | None
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)

    def world_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Box around the 8 corners of ``bounds`` in the world frame (m), or None."""
        if self.bounds is None:
            return None
        lo, hi = self.bounds
        corners = np.array(
            [[a[0], b[1], c[2]] for a in (lo, hi) for b in (lo, hi) for c in (lo, hi)]
        )
        world = corners @ self.scan.T_world_file[:3, :3].T + self.scan.T_world_file[:3, 3]
        return world.min(axis=0), world.max(axis=0)


COLOURS = ("red", "green", "blue")


def _first_pass(scan: ExportScan, summ: Summary, chunk_points: int) -> ScanInput:
    """Count, bounding box (file frame, usable points) and the ranges of the float attributes
    and of the colours, from the points."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    ranges: dict[str, tuple[float, float]] = {}
    n = 0
    for chunk in iter_records(scan.path, chunk_points):
        n += len(chunk["x"])
        xyz = usable(chunk)
        if xyz.any():
            pts = np.column_stack([chunk[a][xyz] for a in "xyz"])
            low, high = column_bounds(pts)
            lo, hi = np.minimum(lo, low), np.maximum(hi, high)
        for name, values in chunk.items():
            if name in ("x", "y", "z") or (values.dtype.kind != "f" and name not in COLOURS):
                continue
            finite = values[np.isfinite(values)]
            if finite.size:
                a, b = ranges.get(name, (np.inf, -np.inf))
                ranges[name] = (min(a, float(finite.min())), max(b, float(finite.max())))
    bounds = (lo, hi) if np.isfinite(lo).all() else None
    return ScanInput(scan, summ, n, bounds, ranges)


def usable(chunk: Chunk) -> np.ndarray:
    """Mask of the points that are finite and not exactly (0,0,0) in the file."""
    x, y, z = chunk["x"], chunk["y"], chunk["z"]
    return np.isfinite(x + y + z) & ((x != 0.0) | (y != 0.0) | (z != 0.0))


def _wide_colours(summ: Summary) -> bool:
    """Whether the file stores colours in more than 8 bits (LAS: 16)."""
    d = summ.dimension("red")
    return d is not None and d.dtype.itemsize > 1


def scan_inputs(
    scans: Sequence[ExportScan], need_bounds: bool, chunk_points: int, need_colours: bool = False
) -> list[ScanInput]:
    """Summaries of the scans, with a first pass over those whose header lacks what is needed
    (``need_colours``: the range of colours stored in more than 8 bits)."""
    out = []
    for scan in scans:
        summ = summary(scan.path)
        wide = need_colours and _wide_colours(summ)
        if wide or summ.count is None or (need_bounds and summ.bounds is None):
            out.append(_first_pass(scan, summ, chunk_points))
        else:
            out.append(ScanInput(scan, summ, summ.count, summ.bounds))
    return out


def union_bounds(inputs: Sequence[ScanInput]) -> tuple[np.ndarray, np.ndarray]:
    boxes = [b for b in (i.world_bounds() for i in inputs) if b is not None]
    if not boxes:
        return np.zeros(3), np.zeros(3)
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
