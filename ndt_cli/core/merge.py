"""Merging two sets of sums grouped by key (Numba), with a plain-numpy twin that the tests
compare: what accumulates a scan's voxels chunk by chunk in memory that grows with the voxels,
not with the sorting of all of them at once.

A set is (keys, sums, counts): int64 keys strictly ascending, (n,3) float64 sums and (n,)
float64 counts. The merge holds every key of either set, ascending; a key in both adds the
second set's sums to the first's (one addition per value, so the result is bit-identical to
grouping the two sets' rows together in order with ``np.bincount``).
"""

from __future__ import annotations

import numba
import numpy as np

Groups = tuple[np.ndarray, np.ndarray, np.ndarray]  # keys, (n,3) sums, counts


@numba.njit(cache=True, nogil=True)
def _merge(ak, asum, acount, bk, bsum, bcount, keys, sums, counts):  # pragma: no cover
    i = j = n = 0
    while i < ak.shape[0] or j < bk.shape[0]:
        take_a = j >= bk.shape[0] or (i < ak.shape[0] and ak[i] <= bk[j])
        take_b = i >= ak.shape[0] or (j < bk.shape[0] and bk[j] <= ak[i])
        if take_a and take_b:
            keys[n] = ak[i]
            for c in range(3):
                sums[n, c] = asum[i, c] + bsum[j, c]
            counts[n] = acount[i] + bcount[j]
            i += 1
            j += 1
        elif take_a:
            keys[n] = ak[i]
            for c in range(3):
                sums[n, c] = asum[i, c]
            counts[n] = acount[i]
            i += 1
        else:
            keys[n] = bk[j]
            for c in range(3):
                sums[n, c] = bsum[j, c]
            counts[n] = bcount[j]
            j += 1
        n += 1
    return n


def merge_groups(a: Groups, b: Groups) -> Groups:
    """The merge of two grouped sets (see the module docstring)."""
    size = len(a[0]) + len(b[0])
    keys, sums, counts = np.empty(size, np.int64), np.empty((size, 3)), np.empty(size)
    n = _merge(*a, *b, keys, sums, counts)
    return keys[:n], sums[:n], counts[:n]  # the rows past n are never touched


def merge_groups_numpy(a: Groups, b: Groups) -> Groups:
    """Plain-numpy twin of :func:`merge_groups`: both sets' rows grouped together."""
    keys = np.concatenate([a[0], b[0]])
    uniq, inverse = np.unique(keys, return_inverse=True)
    values = np.concatenate([a[1], b[1]])
    sums = np.column_stack([np.bincount(inverse, weights=values[:, k]) for k in range(3)])
    counts = np.bincount(inverse, weights=np.concatenate([a[2], b[2]]))
    return uniq, sums.reshape(len(uniq), 3), counts
