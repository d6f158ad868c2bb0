"""Coordinate blocks of the readers: a LAS/LAZ chunk as its integers with scale and offset,
(0,0,0) rows found among integers exactly, E57 streamed in chunks; each against the whole read
it replaces, bit for bit."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest
from conftest import shared_data

from ndt_cli import io
from ndt_cli.io.blocks import Block, zero_interval, zero_rows


def _las(path: Path, pts: np.ndarray, scale: float, offset: np.ndarray, fmt: int = 0) -> Path:
    header = laspy.LasHeader(point_format=fmt, version="1.4" if fmt >= 6 else "1.2")
    header.scales, header.offsets = np.full(3, scale), offset
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(path))
    return path


# --- blocks --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "scale, offset",
    [(0.001, -120.0), (0.001, 0.0), (-0.01, 3.7), (1e-12, 1e6), (0.0, 0.0), (0.0, 2.0), (3.0, 1.0)],
)
def test_zero_interval_holds_exactly_the_integers_that_scale_to_zero(scale, offset):
    span = zero_interval(scale, offset)
    centre = 0 if scale == 0 else int(np.clip(round(-offset / scale), -(2**31), 2**31 - 1))
    X = np.arange(centre - 300_000, centre + 300_000, dtype=np.int64)
    X = X[(X >= -(2**31)) & (X < 2**31)]
    zero = X.astype(np.float64) * scale + offset == 0.0
    if span is None:
        assert not zero.any()
        return
    lo, hi = span
    np.testing.assert_array_equal(zero, (lo <= X) & (hi >= X))
    assert scale != 0 or (lo, hi) == (-(2**31), 2**31 - 1)
    assert zero.any() or lo < X[0] or hi > X[-1]


def test_zero_rows_are_the_rows_that_scale_to_the_origin():
    rng = np.random.default_rng(3)
    scale, offset = np.array([0.001, 0.002, 0.01]), np.array([-12.0, 5.0, 0.5])
    values = rng.integers(-20_000, 20_000, (5000, 3)).astype(np.int32)
    values[::7] = [12_000, -2_500, -50]  # exactly (0,0,0)
    values[1::7, 0] = 12_000  # zero in x only
    block = Block(values, scale, offset)
    xyz = block.xyz()
    np.testing.assert_array_equal(zero_rows(block), (xyz == 0.0).all(axis=1))
    assert zero_rows(block).sum() == len(values[::7])
    reference = values * scale + offset  # laspy's scaling, axis by axis
    np.testing.assert_array_equal(xyz, reference)


@pytest.mark.parametrize("scale", [0.001, 1e300])
def test_integer_blocks_find_the_rows_a_whole_read_drops(scale):
    from ndt_cli.io.blocks import unusable_integers
    from ndt_cli.io.points import unusable

    values = np.random.default_rng(2).integers(-5, 5, (2000, 3)).astype(np.int32)
    values[:3] = 2_000_000_000  # overflows to inf at scale 1e300
    values[10:20] = 0
    block = Block(values, np.full(3, scale), np.zeros(3))
    with np.errstate(over="ignore", invalid="ignore"):
        expected = unusable(block.xyz())
        got = unusable_integers(block)
    for a, b in zip(got, expected, strict=True):
        np.testing.assert_array_equal(a, b)
    assert got[1].sum() > 5 and (got[0].sum() == 3) == (scale > 1)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_blocks_hold_a_las_files_integers_and_give_its_coordinates(tmp_path, suffix):
    rng = np.random.default_rng(4)
    pts = rng.uniform(-50, 50, (30_000, 3))
    pts[100:140] = 0.0  # dropped as (0,0,0)
    path = _las(tmp_path / f"a{suffix}", pts, 0.001, np.array([-51.0, -51.0, -51.0]))
    blocks = list(io.read_blocks(path, 7000))
    assert all(b.values.dtype == np.int32 and b.scaled for b in blocks)
    assert len(blocks) == 5 and sum(len(b) for b in blocks) == len(pts) - 40
    got = np.concatenate([b.xyz() for b in blocks])
    np.testing.assert_array_equal(got, io.read(path).points)  # bit for bit
    np.testing.assert_array_equal(np.concatenate(list(io.read_chunks(path, 7000))), got)


def test_a_laz_file_of_point_format_6_decompresses_its_coordinates_only(tmp_path):
    rng = np.random.default_rng(5)
    pts = rng.uniform(-50, 50, (20_000, 3))
    path = _las(tmp_path / "six.laz", pts, 0.001, np.zeros(3), fmt=6)
    las = laspy.read(path)
    got = np.concatenate([b.xyz() for b in io.read_blocks(path, 6000)])
    np.testing.assert_array_equal(got, np.column_stack([las.x, las.y, las.z]))


# --- E57 -----------------------------------------------------------------------------------


def _pye57_read(path: Path) -> np.ndarray:
    """The points pye57 reads of a file's only scan (the independent reference)."""
    import pye57

    data = pye57.E57(str(path)).read_scan(0, transform=False, ignore_missing_fields=True)
    if "cartesianX" in data:
        return np.column_stack([data["cartesianX"], data["cartesianY"], data["cartesianZ"]])
    r, az, el = data["sphericalRange"], data["sphericalAzimuth"], data["sphericalElevation"]
    cos_el = np.cos(el)
    return np.column_stack([r * cos_el * np.cos(az), r * cos_el * np.sin(az), r * np.sin(el)])


def test_e57_is_streamed_in_chunks_with_the_points_pye57_reads(tmp_path):
    pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli.io import e57

    pts = np.random.default_rng(6).uniform(-30, 30, (10_000, 3))
    path = tmp_path / "scan.e57"
    e57.write(path, [pts], [None])
    chunks = list(e57.iter_xyz(path, 3000))
    assert [len(c) for c in chunks] == [3000, 3000, 3000, 1000]
    np.testing.assert_array_equal(np.concatenate(chunks), _pye57_read(path))
    np.testing.assert_array_equal(e57.read_xyz(path), _pye57_read(path))
    assert io.record_count(path) == len(pts)
    assert next(e57.iter_blocks(path)).values.dtype == np.float32  # pye57 writes singles


@pytest.mark.parametrize(
    "name, dtype",
    [("e57_rust/bunnyFloat.e57", np.float32), ("e57_rust/bunnyDouble.e57", np.float64)],
)
def test_e57_coordinates_are_held_in_the_precision_the_file_stores(name, dtype):
    pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli.io import e57

    path = shared_data("e57_samples") / name
    blocks = list(e57.iter_blocks(path, 5000))
    assert {b.values.dtype for b in blocks} == {np.dtype(dtype)}
    np.testing.assert_array_equal(np.concatenate([b.xyz() for b in blocks]), _pye57_read(path))


@pytest.mark.parametrize(
    "name",
    [
        "e57_rust/cartesian_invalid_state_single.e57",
        "e57_rust/tiny_spherical.e57",
        "e57_python/pipeSpherical.e57",
        "e57_rust/bunnyInt19.e57",
        "pye57/pumpAVisualReferenceImage.e57",
    ],
)
def test_e57_files_of_other_writers_stream_the_points_pye57_reads(name):
    pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli.io import e57

    path = shared_data("e57_samples") / name
    reference = _pye57_read(path)
    streamed = np.concatenate(list(e57.iter_xyz(path, 997)))
    np.testing.assert_array_equal(streamed, reference)
    assert len(reference) <= io.record_count(path)
