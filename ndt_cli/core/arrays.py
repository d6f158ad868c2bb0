"""Array helpers in plain numpy (no compiled code: any module may import them)."""

from __future__ import annotations

import numpy as np


def column_bounds(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-column minimum and maximum of an (N,D) array (N >= 1), column by column: numpy
    reduces a strided column at memory speed, while a reduction over axis 0 of short rows is
    many times slower (20x for (N,2) floats). Exact: the values of ``min(axis=0)``."""
    cols = [rows[:, k] for k in range(rows.shape[1])]
    return np.array([c.min() for c in cols]), np.array([c.max() for c in cols])
