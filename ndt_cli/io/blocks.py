"""Coordinates of a chunk of a point file, kept compact: a LAS/LAZ file's integers with its
scale and offset (12 bytes a point), an E57 file's single-precision floats (12 bytes), or
float64 (24 bytes a point).

A block gives the same float64 coordinates as the readers (:meth:`Block.xyz`): for LAS/LAZ
``X * scale + offset`` per axis in float64, as laspy computes them. Holding a scan as blocks
of integers halves its memory and loses nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.core.records import rows_within

INT32 = (-(2**31), 2**31 - 1)


@dataclass(frozen=True)
class Block:
    """(m,3) coordinates: ``values`` int32 with per-axis ``scale`` and ``offset`` (metres or
    the file's unit: ``x = X * scale + offset``), or float64 or float32 (a file's single
    precision, exact) with ``scale`` None."""

    values: np.ndarray
    scale: np.ndarray | None = None
    offset: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.values)

    @property
    def scaled(self) -> bool:
        return self.scale is not None

    @property
    def nbytes(self) -> int:
        return int(self.values.nbytes)

    def xyz(self) -> np.ndarray:
        """(m,3) float64 coordinates (``values`` itself when they are float64)."""
        if self.scale is None or self.offset is None:
            return self.values.astype(np.float64, copy=False)
        out = np.empty(self.values.shape, np.float64)
        for k in range(3):
            np.multiply(self.values[:, k], self.scale[k], out=out[:, k])
            np.add(out[:, k], self.offset[k], out=out[:, k])
        return out

    def rows(self, index: np.ndarray | slice) -> Block:
        """The block of the rows ``index`` (a slice: a view; an index array or mask: a copy)."""
        return Block(self.values[index], self.scale, self.offset)


def _scaled(X: int, scale: float, offset: float) -> float:
    return float(np.float64(X) * np.float64(scale) + np.float64(offset))


def _first(pred: object, lo: int, hi: int) -> int:
    """The least integer in [lo, hi] where the monotone ``pred`` holds (hi + 1: none)."""
    while lo <= hi:
        mid = (lo + hi) // 2
        if pred(mid):  # type: ignore[operator]
            hi = mid - 1
        else:
            lo = mid + 1
    return lo


def zero_interval(scale: float, offset: float) -> tuple[int, int] | None:
    """The int32 values X for which ``X * scale + offset`` (float64) is exactly 0, as an
    inclusive interval, or None. The scaled value is monotone in X (rounding keeps order), so
    two bisections find the interval exactly."""
    lo, hi = INT32
    if scale == 0.0:
        return (lo, hi) if offset == 0.0 else None
    sign = 1.0 if scale > 0 else -1.0
    start = _first(lambda X: sign * _scaled(X, scale, offset) >= 0.0, lo, hi)
    stop = _first(lambda X: sign * _scaled(X, scale, offset) > 0.0, lo, hi) - 1
    return (start, stop) if start <= stop else None


FINITE_BOUND = 1e300  # an axis whose largest scaled integer stays below this is finite


def unusable_integers(block: Block) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the rows of an integer block whose coordinates are not finite (a scale so large
    that ``X * scale`` overflows), and of those exactly (0,0,0). Without scaling the integers
    themselves (12 bytes a point), unless some axis could overflow."""
    scale, offset = np.abs(block.scale), np.abs(block.offset)  # type: ignore[arg-type]
    if np.all(2.0**31 * scale + offset < FINITE_BOUND):
        return np.zeros(len(block), bool), zero_rows(block)
    xyz = block.xyz()
    with np.errstate(invalid="ignore"):
        return ~np.isfinite(xyz).all(axis=1), (xyz == 0.0).all(axis=1)


def zero_rows(block: Block) -> np.ndarray:
    """Mask of the rows of an integer block whose coordinates are exactly (0,0,0)."""
    if block.scale is None or block.offset is None:
        raise ValueError("zero_rows needs a block of integers")
    spans = [zero_interval(float(block.scale[k]), float(block.offset[k])) for k in range(3)]
    if any(s is None for s in spans) or len(block) == 0:
        return np.zeros(len(block), bool)
    lo, hi = zip(*spans, strict=True)  # type: ignore[misc]
    return rows_within(block.values, np.array(lo), np.array(hi))
