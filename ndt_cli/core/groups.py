"""Grouping points by an integer key (a grid cell, a voxel): the keys present, each point's
group, and sums per group, in linear time where the key range allows it.

The results equal ``np.unique(..., return_inverse=True, return_counts=True)`` and
``np.add.at``: groups are in ascending key order and sums add the values in input order, so
they are bit-identical to those, only faster (``np.add.at`` is unbuffered and slow).
"""

from __future__ import annotations

import numpy as np

DENSE_RANGE_FACTOR = 8  # a dense count array is used up to this many slots per point


def group_keys(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unique keys ascending, group index of every input, count per group) of non-negative
    int64 ``keys``."""
    if len(keys) == 0:
        empty = np.zeros(0, np.int64)
        return empty, empty, empty
    top = int(keys.max()) + 1
    if top > DENSE_RANGE_FACTOR * len(keys) + 1024:
        return np.unique(keys, return_inverse=True, return_counts=True)
    dense = np.bincount(keys, minlength=top)
    present = np.flatnonzero(dense)
    rank = np.zeros(top, np.int64)
    rank[present] = np.arange(present.size)
    return present.astype(np.int64), rank[keys], dense[present]


def group_sums(inverse: np.ndarray, values: np.ndarray, n_groups: int) -> np.ndarray:
    """(n_groups, C) sums of the rows of (N, C) ``values`` per group (``inverse``: the group
    of each row), added in row order."""
    return np.column_stack(
        [
            np.bincount(inverse, weights=values[:, c], minlength=n_groups)
            for c in range(values.shape[1])
        ]
    ).reshape(n_groups, values.shape[1])
