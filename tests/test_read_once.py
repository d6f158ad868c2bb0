"""Reading a scan once: held in memory as blocks or streamed twice, the slice pass on a LAS
file's integers and the voxel merge; every path against the reading it replaced (coordinates
bit for bit, poses to 1e-9 m)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import laspy
import numpy as np
import pytest

from ndt_cli import io
from ndt_cli.config import Config
from ndt_cli.io.blocks import Block
from ndt_cli.io.formats import LasReader

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden" / "read_paths"


def _las(path: Path, pts: np.ndarray, scale: float, offset: np.ndarray) -> Path:
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales, header.offsets = np.full(3, scale), offset
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(path))
    return path


# --- the voxel merge -----------------------------------------------------------------------


def _groups(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    keys = np.unique(rng.integers(0, 3 * n, n))
    return keys, rng.normal(size=(len(keys), 3)), rng.integers(1, 9, len(keys)).astype(float)


def test_the_voxel_merge_equals_its_numpy_twin_bit_for_bit():
    from ndt_cli.core.merge import merge_groups, merge_groups_numpy

    rng = np.random.default_rng(7)
    for n_a, n_b in [(0, 0), (0, 50), (40, 0), (1000, 700), (5, 3000)]:
        a, b = _groups(rng, n_a), _groups(rng, n_b)
        fast, slow = merge_groups(a, b), merge_groups_numpy(a, b)
        for x, y in zip(fast, slow, strict=True):
            np.testing.assert_array_equal(x, y)
        assert len(fast[0]) == len(np.union1d(a[0], b[0]))


def test_a_thinner_fed_chunk_by_chunk_equals_one_fed_at_once():
    from ndt_cli.core.geometry import VoxelThinner, voxel_keys
    from ndt_cli.core.merge import merge_groups_numpy

    rng = np.random.default_rng(8)
    pts = rng.uniform(-5, 5, (20_000, 3))
    whole = VoxelThinner(0.5)
    whole.add(pts)
    for merge in (None, merge_groups_numpy):
        parts = VoxelThinner(0.5) if merge is None else VoxelThinner(0.5, merge)
        for chunk in np.array_split(pts, 7):
            parts.add(chunk)
        np.testing.assert_allclose(parts.result(), whole.result(), rtol=0, atol=1e-12)
    assert len(whole.result()) == len(np.unique(voxel_keys(pts, 0.5)))


# --- the slice pass on integers ------------------------------------------------------------


def test_the_slice_pass_on_integers_equals_it_on_their_coordinates():
    from ndt_cli.core.transforms import levelling_rotation
    from ndt_cli.ndt.passes import slice_pass, slice_pass_numpy
    from ndt_cli.ndt.terrain import Terrain

    rng = np.random.default_rng(9)
    values = rng.integers(-40_000, 40_000, (50_000, 3)).astype(np.int32)
    block = Block(values, np.array([0.001, 0.001, 0.0005]), np.array([512_000.3, 5e6, 41.0]))
    reduction = np.array([512_001.0, 5e6 + 2.0, 40.0])
    ground = Terrain(np.array([-50.0, -50.0]), 5.0, rng.uniform(-1, 1, (20, 20)), np.ones((20, 20)))
    args = (reduction, levelling_rotation(0.01, -0.02), [1.0, 3.0], 0.4, 0.1, ground, 60.0)
    ints, floats = slice_pass(block, *args), slice_pass(block.xyz(), *args)
    twin = slice_pass_numpy(block, *args)
    assert ints.far == floats.far == twin.far > 0
    for a, b, c in zip(ints.slices, floats.slices, twin.slices, strict=True):
        np.testing.assert_array_equal(a, b)  # the loop scales as numpy does, bit for bit
        np.testing.assert_allclose(a, c, rtol=0, atol=1e-9)
        assert len(a) > 100
    for a, b in zip(ints.grouped, floats.grouped, strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_slice_pass_on_single_precision_equals_it_on_their_widening():
    from ndt_cli.ndt.passes import slice_pass

    rng = np.random.default_rng(12)
    singles = rng.uniform(-60, 60, (40_000, 3)).astype(np.float32)
    args = (np.array([0.3, -0.2, -1.5]), np.eye(3), [1.0, 2.0], 0.4, 0.1, None, 50.0)
    a, b = slice_pass(Block(singles), *args), slice_pass(singles.astype(np.float64), *args)
    assert a.far == b.far > 0
    for x, y in zip([*a.slices, *a.grouped], [*b.slices, *b.grouped], strict=True):
        np.testing.assert_array_equal(x, y)
    assert sum(len(x) for x in a.slices) > 100


# --- a scan held or streamed twice ---------------------------------------------------------


def _pair(tmp_path: Path, suffix: str) -> tuple[Path, Path]:
    if suffix == ".laz":
        return ROOT / "sample_data" / "scan_00.laz", ROOT / "sample_data" / "scan_01.laz"
    if suffix == ".e57":
        pytest.importorskip("pye57", reason="the e57 extra is not installed")
    spec = importlib.util.spec_from_file_location("make_golden", GOLDEN / "make.py")
    make = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(make)  # type: ignore[union-attr]
    return make.copies(tmp_path)[suffix]


@pytest.mark.slow
@pytest.mark.parametrize("held", [True, False], ids=["held", "streamed twice"])
@pytest.mark.parametrize("suffix", [".laz", ".las", ".e57"])
def test_poses_equal_those_of_the_reading_before(tmp_path, suffix, held):
    import ndt_cli

    golden = json.loads((GOLDEN / "poses.json").read_text())
    cfg = Config().replace(input={"chunk_points": golden["chunk_points"]})
    if not held:
        cfg = cfg.replace(input={"memory_mb": 0})
    a, b = _pair(tmp_path, suffix)
    T = ndt_cli.register(a, b, cfg).T_target_source
    np.testing.assert_allclose(T, golden["poses"][suffix], rtol=0, atol=1e-9)


def test_a_laz_scan_that_fits_is_decoded_once_and_one_that_does_not_twice(monkeypatch):
    from ndt_cli.ndt.prepare import load_and_prepare

    decoded = []
    original = LasReader.iter_blocks

    def counting(self, path, chunk_size=None):
        decoded.append(path)
        yield from original(self, path, chunk_size)

    monkeypatch.setattr(LasReader, "iter_blocks", counting)
    path = ROOT / "sample_data" / "scan_00.laz"
    cfg = Config().replace(input={"chunk_points": 20_000})
    held = load_and_prepare(path, cfg)
    assert len(decoded) == 1
    streamed = load_and_prepare(path, cfg.replace(input={"memory_mb": 0}))
    assert len(decoded) == 3
    assert held.n_points == streamed.n_points == io.count(path)
    np.testing.assert_array_equal(held.reduction, streamed.reduction)
    for s, t in zip(held.slices, streamed.slices, strict=True):
        np.testing.assert_array_equal(s, t)
    np.testing.assert_array_equal(held.points3d, streamed.points3d)


def test_a_large_las_file_is_mapped_twice_rather_than_held(tmp_path):
    from ndt_cli.ndt.chunks import ScanChunks

    pts = np.random.default_rng(10).uniform(-50, 50, (30_000, 3))
    path = _las(tmp_path / "big.las", pts, 0.001, np.full(3, -51.0))
    cfg = Config().replace(input={"chunk_points": 10_000})
    scan = ScanChunks.of(path, cfg.input)
    assert not scan.held and scan.n_points == len(pts)
    first, again = list(scan.chunks()), list(scan.chunks())
    assert [len(b) for b in first] == [10_000] * 3
    for x, y in zip(first, again, strict=True):
        np.testing.assert_array_equal(x.values, y.values)
    small = ScanChunks.of(path, cfg.replace(input={"chunk_points": 40_000}).input)
    assert small.held and len(list(small.chunks())) == 1
