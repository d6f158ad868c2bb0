"""The X, Y, Z integers of LAS point records, and the rows whose integers lie in given ranges
(Numba, in threads), with the plain-numpy twins that the tests compare.

Every LAS point format (0 to 10) begins with X, Y, Z as little-endian int32 at bytes 0, 4
and 8 of its record. A record is 20 to 67 bytes plus any extra bytes, so the integers of a
mapped file lie unaligned, 20 to 100 bytes apart: numpy copies such a field at about a tenth
of the speed of memory, and a scan's three fields one after the other. The kernel reads each
record once, in the threads of the budget (a record's bytes are read in whatever order; the
copy is exact, so the result is the same for any number of threads).
"""

from __future__ import annotations

import numba
import numpy as np

from ndt_cli.core.threads import parallel_for

XYZ_BYTES = 12  # X, Y, Z: the first 12 bytes of every LAS point record


@numba.njit(cache=True, nogil=True)
def _copy_xyz(start, stop, raw, out):  # pragma: no cover
    for i in range(start, stop):
        for k in range(3):
            b = 4 * k
            u = (
                np.int64(raw[i, b])
                | (np.int64(raw[i, b + 1]) << 8)
                | (np.int64(raw[i, b + 2]) << 16)
                | (np.int64(raw[i, b + 3]) << 24)
            )
            out[i, k] = u - (np.int64(1) << 32) if u >= (np.int64(1) << 31) else u


def record_bytes(records: np.ndarray) -> np.ndarray:
    """(n, itemsize) uint8 view of a 1-D array of LAS point records (contiguous or mapped)."""
    records = np.ascontiguousarray(records)
    return records.view(np.uint8).reshape(len(records), records.dtype.itemsize)


def xyz_integers(raw: np.ndarray) -> np.ndarray:
    """(n,3) int32 X, Y, Z of (n, itemsize) uint8 LAS point records (see the module text)."""
    if raw.ndim != 2 or raw.shape[1] < XYZ_BYTES or raw.dtype != np.uint8:
        raise ValueError(f"need (n, >= {XYZ_BYTES}) uint8 records, got {raw.dtype} {raw.shape}")
    out = np.empty((len(raw), 3), np.int32)
    if len(raw):
        parallel_for(_copy_xyz, len(raw), raw, out)
    return out


def xyz_integers_numpy(raw: np.ndarray) -> np.ndarray:
    """Plain-numpy twin of :func:`xyz_integers`: the first 12 bytes of each record as int32."""
    return np.ascontiguousarray(raw[:, :XYZ_BYTES]).view("<i4").astype(np.int32).reshape(-1, 3)


@numba.njit(cache=True, nogil=True)
def _within(start, stop, values, lo, hi, out):  # pragma: no cover
    for i in range(start, stop):
        inside = True
        for k in range(3):
            v = values[i, k]
            if v < lo[k] or v > hi[k]:
                inside = False
                break
        out[i] = inside


def rows_within(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Mask of the rows of (n,3) int32 ``values`` with ``lo[k] <= values[:, k] <= hi[k]`` on
    every axis (int64 bounds, inclusive; an empty range: ``lo > hi``)."""
    out = np.empty(len(values), np.bool_)
    if len(values):
        parallel_for(
            _within,
            len(values),
            np.ascontiguousarray(values),
            np.asarray(lo, np.int64),
            np.asarray(hi, np.int64),
            out,
        )
    return out


def rows_within_numpy(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Plain-numpy twin of :func:`rows_within`."""
    v = values.astype(np.int64)
    return np.all((v >= np.asarray(lo)) & (v <= np.asarray(hi)), axis=1)
