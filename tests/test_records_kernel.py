"""The X, Y, Z of LAS point records and the rows within ranges (Numba, in threads) against
their numpy twins and laspy's own reading of the same records, for every point format."""

from __future__ import annotations

import laspy
import numpy as np
import pytest

from ndt_cli.core import threads
from ndt_cli.core.records import (
    record_bytes,
    rows_within,
    rows_within_numpy,
    xyz_integers,
    xyz_integers_numpy,
)


def _records(point_format: int, n: int, extra: int, seed: int) -> np.ndarray:
    """``n`` random records of ``point_format`` with ``extra`` extra bytes, as laspy types them."""
    fmt = laspy.PointFormat(point_format)
    if extra:
        fmt.add_extra_dimension(laspy.ExtraBytesParams("pad", f"{extra}u1"))
    raw = np.random.default_rng(seed).integers(0, 256, (n, fmt.size), dtype=np.uint8)
    return raw.view(fmt.dtype()).reshape(n)


@pytest.mark.parametrize("point_format", range(11))
@pytest.mark.parametrize("extra", [0, 3])
def test_xyz_of_every_point_format_equals_laspy_fields_and_the_twin(point_format, extra):
    records = _records(point_format, 5_001, extra, point_format)
    raw = record_bytes(records)
    got = xyz_integers(raw)
    expected = np.column_stack([records["X"], records["Y"], records["Z"]])  # laspy's typing
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(xyz_integers_numpy(raw), expected)
    assert got.dtype == np.int32 and (got < 0).any() and (got > 2**30).any()  # both signs met


def test_xyz_of_an_unaligned_memory_map_equals_the_file(tmp_path):
    records = _records(6, 20_000, 0, 1)
    path = tmp_path / "records.bin"
    path.write_bytes(b"\x00" * 7 + records.tobytes())  # an odd offset: unaligned integers
    mapped = np.memmap(path, np.uint8, "r", offset=7, shape=(len(records), records.itemsize))
    np.testing.assert_array_equal(xyz_integers(mapped), xyz_integers_numpy(record_bytes(records)))


@pytest.mark.parametrize("budget", [1, 2, 3])
def test_results_are_bit_identical_for_any_number_of_threads(budget):
    raw = record_bytes(_records(3, 30_001, 0, 5))
    lo, hi = np.array([-(2**20), -(2**31), 0]), np.array([2**30, 2**31 - 1, 2**31 - 1])
    before = threads.threads()
    threads.set_threads(budget)
    try:
        xyz = xyz_integers(raw)
        mask = rows_within(xyz, lo, hi)
    finally:
        threads.set_threads(before)
    np.testing.assert_array_equal(xyz, xyz_integers_numpy(raw))
    np.testing.assert_array_equal(mask, rows_within_numpy(xyz, lo, hi))
    assert 0 < mask.sum() < len(mask)


def test_rows_within_ranges_with_bounds_equal_to_values_and_empty_ranges():
    values = np.array([[0, 0, 0], [5, -5, 7], [5, -6, 7], [2**31 - 1, -(2**31), 0]], np.int32)
    lo, hi = np.array([0, -5, 0]), np.array([5, 0, 7])
    assert rows_within(values, lo, hi).tolist() == [True, True, False, False]
    assert rows_within(values, np.array([1, 0, 0]), np.array([0, 0, 0])).tolist() == [False] * 4
    full = np.array([-(2**31)] * 3), np.array([2**31 - 1] * 3)
    assert rows_within(values, *full).all()
    for lo_, hi_ in [(lo, hi), full]:
        np.testing.assert_array_equal(
            rows_within(values, lo_, hi_), rows_within_numpy(values, lo_, hi_)
        )
    assert rows_within(values[:0], lo, hi).shape == (0,)


def test_bad_records_are_refused():
    with pytest.raises(ValueError, match="uint8 records"):
        xyz_integers(np.zeros((3, 8), np.uint8))
