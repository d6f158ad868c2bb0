"""Tests of ndt_cli.io: reading and writing point files, and the errors on bad input."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import conftest
import laspy
import numpy as np
import plyfile
import pypcd4
import pytest
from conftest import shared_data

from ndt_cli import io as ndt_io
from ndt_cli.errors import InputError, OutputError
from ndt_cli.io import formats
from ndt_cli.io.formats import LasReader
from ndt_cli.io.multiscan_files import expand
from ndt_cli.io.points import READERS

ALL_SUFFIXES = (".ply", ".las", ".laz", ".pcd", ".xyz", ".txt", ".csv")


def _points(n: int = 300, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-80.0, 80.0, (n, 3))


def _ply(
    path: Path,
    pts: np.ndarray,
    text: bool = False,
    order: str = "<",
    dtype: str = "f4",
    names: str = "xyz",
) -> Path:
    vertex = np.zeros(
        len(pts),
        dtype=[
            (names[0], dtype),
            (names[1], dtype),
            (names[2], dtype),
            ("intensity", "u1"),
            ("nx", "f4"),
        ],
    )
    for i, name in enumerate(names):
        vertex[name] = pts[:, i]
    faces = np.array([([0, 1, 2],)], dtype=[("vertex_indices", "i4", (3,))])
    elements = [
        plyfile.PlyElement.describe(vertex, "vertex"),
        plyfile.PlyElement.describe(faces, "face"),
    ]
    plyfile.PlyData(elements, text=text, byte_order=order).write(str(path))
    return path


def _pcd(
    path: Path,
    pts: np.ndarray,
    encoding: str = "binary",
    dtype: type = np.float32,
    fields: tuple[str, str, str] = ("x", "y", "z"),
) -> Path:
    columns = [pts[:, 0], pts[:, 1], pts[:, 2], np.arange(len(pts), dtype=np.float32)]
    cloud = pypcd4.PointCloud.from_points(
        columns, (*fields, "intensity"), (dtype,) * 3 + (np.float32,)
    )
    cloud.save(path, encoding=pypcd4.Encoding(encoding))
    # pypcd4 silently writes "DATA binary" when LZF cannot shrink the data (e.g. random floats)
    assert len(pts) == 0 or f"DATA {encoding}\n".encode() in path.read_bytes()[:400]
    return path


def _pcd_points(n: int = 300, seed: int = 0) -> np.ndarray:
    """Quarter-metre values: exact in float32 and compressible, so binary_compressed is used."""
    return np.round(_points(n, seed) * 4) / 4


def _las(path: Path, pts: np.ndarray, scale: float = 0.001, offsets=(0.0, 0.0, 0.0)) -> Path:
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.scales = np.full(3, scale)
    header.offsets = np.asarray(offsets, dtype=np.float64)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(path))
    return path


def _cut(path: Path, keep: int | None = None) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2 if keep is None else keep])
    return path


def _text(path: Path, content: str) -> Path:
    path.write_text(content, encoding="utf-8")
    return path


# --- round trips and reading of each format ---------------------------------------------------


@pytest.mark.parametrize("suffix", [*ALL_SUFFIXES, ".LAZ", ".Ply"])
def test_round_trip(tmp_path: Path, suffix: str) -> None:
    pts = _points()
    path = tmp_path / f"cloud{suffix}"
    ndt_io.write(path, pts)
    cloud = ndt_io.read(path)
    assert (cloud.path, cloud.n_read, cloud.n_nonfinite, cloud.n_zero) == (path, len(pts), 0, 0)
    assert cloud.points.dtype == np.float64 and cloud.points.shape == pts.shape
    if suffix.lower() in (".las", ".laz"):
        np.testing.assert_allclose(cloud.points, pts, rtol=0, atol=0.0005 + 1e-9)
    else:  # float64 binary or shortest-repr text: exact
        np.testing.assert_array_equal(cloud.points, pts)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_georeferenced_keeps_millimetres(tmp_path: Path, suffix: str) -> None:
    rng = np.random.default_rng(1)
    pts = np.column_stack(
        [
            rng.uniform(4.5e5, 4.5e5 + 300, 1000),
            rng.uniform(5.4e6, 5.4e6 + 300, 1000),
            rng.uniform(90, 120, 1000),
        ]
    )
    pts = np.round(pts * 1000) / 1000  # exact millimetres
    path = tmp_path / f"geo{suffix}"
    ndt_io.write(path, pts)
    got = ndt_io.read(path).points
    assert np.abs(got - pts).max() < 1e-6  # float32 anywhere would cost ~0.25 m here
    las = laspy.read(path)
    np.testing.assert_array_equal(got, np.column_stack([las.x, las.y, las.z]))


@pytest.fixture
def las_chunks(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, int]]:
    """Records (requested chunk size, points in chunk) for every chunk laspy yields."""
    log: list[tuple[int, int]] = []
    real_open = laspy.open

    def spy_open(*args, **kwargs):
        reader = real_open(*args, **kwargs)
        real_iter = reader.chunk_iterator

        def chunk_iterator(size: int):
            for chunk in real_iter(size):
                log.append((size, len(chunk)))
                yield chunk

        reader.chunk_iterator = chunk_iterator
        return reader

    monkeypatch.setattr(laspy, "open", spy_open)
    return log


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_chunked_las_matches_one_shot_read(
    tmp_path: Path, suffix: str, las_chunks: list[tuple[int, int]]
) -> None:
    pts = _points(10_000, seed=2) + np.array([1000.0, 5e6, 0.0])
    path = _las(tmp_path / f"big{suffix}", pts, scale=0.01, offsets=(1000.0, 5e6, 0.0))
    las = laspy.read(path)
    expected = np.column_stack([las.x, las.y, las.z])
    chunks = list(LasReader().iter_xyz(path, 999))
    assert [len(c) for c in chunks] == [999] * 10 + [10]
    # LAZ is decompressed by laspy chunk by chunk; LAS records are mapped from the file, never
    # copied through laspy's reader
    assert las_chunks == ([(999, 999)] * 10 + [(999, 10)] if suffix == ".laz" else [])
    got = np.concatenate(chunks)
    np.testing.assert_array_equal(got, expected)
    assert np.abs(got - pts).max() <= 0.005 + 1e-9


@pytest.mark.parametrize(
    ("point_format", "extra"), [(0, False), (1, True), (3, False), (6, True), (7, False), (8, True)]
)
def test_mapped_las_records_scale_exactly_as_laspy(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, point_format: int, extra: bool
) -> None:
    """Records of every size (with extra bytes, after a variable-length record that moves the
    point data to an odd offset), georeferenced offsets, blocks smaller than the file: the
    coordinates are laspy's own, bit for bit, whole or in chunks."""
    monkeypatch.setattr(formats, "SCALE_BLOCK", 7)
    rng = np.random.default_rng(point_format)
    header = laspy.LasHeader(point_format=point_format, version="1.4")
    header.scales = np.array([0.001, 0.002, 0.0005])
    header.offsets = np.array([4.5e5 + 0.3, 5.4e6 - 0.7, 97.25])
    if extra:
        header.add_extra_dim(laspy.ExtraBytesParams(name="range", type=np.float32))
    header.vlrs.append(laspy.VLR("ndt", 1, "odd", b"x" * (14 if extra else 13)))
    las = laspy.LasData(header)
    n = 1000
    las.x = header.offsets[0] + rng.uniform(-300, 300, n)
    las.y = header.offsets[1] + rng.uniform(-300, 300, n)
    las.z = header.offsets[2] + rng.uniform(-20, 20, n)
    las.intensity = rng.integers(0, 65535, n)
    path = tmp_path / "records.las"
    las.write(str(path))
    ref = laspy.read(path)
    assert ref.header.offset_to_point_data % 8 != 0
    expected = np.column_stack([ref.x, ref.y, ref.z])
    np.testing.assert_array_equal(LasReader().read_xyz(path), expected)
    np.testing.assert_array_equal(np.concatenate(list(LasReader().iter_xyz(path, 333))), expected)


def test_read_chunks_streams_las_and_drops_unusable_points(tmp_path: Path) -> None:
    pts = _points(5000, seed=3)
    pts[[10, 4000]] = 0.0  # "no return" rows
    path = _las(tmp_path / "c.las", pts)
    assert ndt_io.count(path) == 5000 and ndt_io.count(_written(tmp_path / "w.ply")) is None
    chunks = list(ndt_io.read_chunks(path, chunk_size=2000))
    assert [len(c) for c in chunks] == [1999, 2000, 999]
    np.testing.assert_array_equal(np.concatenate(chunks), ndt_io.read(path).points)
    whole = list(ndt_io.read_chunks(_written(tmp_path / "w.xyz"), chunk_size=10))
    assert len(whole) == 1 and len(whole[0]) == 2000  # formats without streaming: one chunk


def test_unusable_rows_are_exactly_the_non_finite_and_the_all_zero_ones() -> None:
    from ndt_cli.io.points import unusable

    rows = np.array(
        [
            [1e-200, 0.0, 0.0],  # squares to 0 but is a point
            [0.0, -1e200, 0.0],  # squares to inf but is finite
            [np.nan, 1.0, 2.0],
            [3.0, -np.inf, 0.0],
            [0.0, 0.0, 0.0],
            [-0.0, 0.0, -0.0],
            [4.0, 5.0, 6.0],
        ]
    )
    data = np.vstack([rows, _points(1000, seed=9)])
    nonfinite, zero = unusable(data)
    want_nonfinite = [not all(np.isfinite(v) for v in r) for r in data]  # row by row
    want_zero = [all(v == 0.0 for v in r) for r in data]
    assert nonfinite.tolist() == want_nonfinite and zero.tolist() == want_zero
    assert nonfinite[:7].tolist() == [False, False, True, True, False, False, False]
    assert zero[:7].tolist() == [False, False, False, False, True, True, False]


def test_read_uses_module_chunk_size(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, las_chunks: list[tuple[int, int]]
) -> None:
    pts = _points(5000, seed=3)
    path = _las(tmp_path / "c.laz", pts)  # LAZ: laspy decompresses it chunk by chunk
    monkeypatch.setattr(formats, "LAS_CHUNK_SIZE", 2000)
    cloud = ndt_io.read(path)
    assert las_chunks == [(2000, 2000), (2000, 2000), (2000, 1000)]
    np.testing.assert_allclose(cloud.points, pts, atol=0.0005 + 1e-9, rtol=0)


@pytest.mark.parametrize("dtype", ["f4", "f8", "i2"])
@pytest.mark.parametrize(
    ("text", "order"),
    [(True, "="), (False, ">"), (False, "<")],
    ids=["ascii", "binary_big_endian", "binary_little_endian"],
)
def test_read_ply_variants(tmp_path: Path, text: bool, order: str, dtype: str) -> None:
    pts = np.round(_points(50, seed=4)) if dtype == "i2" else _points(50, seed=4)
    path = _ply(tmp_path / "v.ply", pts, text=text, order=order, dtype=dtype)
    assert plyfile.PlyData.read(str(path)).text == text
    got = ndt_io.read(path).points
    np.testing.assert_array_equal(got, pts.astype(dtype).astype(np.float64))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_read_pcd_variants(tmp_path: Path, encoding: str, dtype: type) -> None:
    pts = _pcd_points(60, seed=5)
    path = _pcd(tmp_path / "v.pcd", pts, encoding=encoding, dtype=dtype)
    np.testing.assert_array_equal(ndt_io.read(path).points, pts)


def test_read_pcd_float64_full_precision(tmp_path: Path) -> None:
    pts = _points(60, seed=7) + np.array([4.5e5, 5.4e6, 0.0])
    path = _pcd(tmp_path / "geo.pcd", pts, dtype=np.float64)
    np.testing.assert_array_equal(ndt_io.read(path).points, pts)


def test_read_one_point_ascii_pcd(tmp_path: Path) -> None:
    path = _pcd(tmp_path / "one.pcd", np.array([[1.5, -2.0, 3.25]]), encoding="ascii")
    np.testing.assert_array_equal(ndt_io.read(path).points, [[1.5, -2.0, 3.25]])


TEXT_CASES = {
    "plain": ("1 2 3\n4 5 6\n", [[1, 2, 3], [4, 5, 6]]),
    "header": ("X Y Z\n1 2 3\n4 5 6\n", [[1, 2, 3], [4, 5, 6]]),
    "comments": (
        "# scan 1\n// exported\n\n1 2 3\n# mid comment\n\n4 5 6 # note\n",
        [[1, 2, 3], [4, 5, 6]],
    ),
    "count_line": ("2\n1 2 3\n4 5 6\n", [[1, 2, 3], [4, 5, 6]]),
    "comma": ("x,y,z\n1.5,2,3e2\n-4, 5 ,6\n", [[1.5, 2, 300], [-4, 5, 6]]),
    "semicolon": ("x;y;z\n1;2;3\n4;5;6\n", [[1, 2, 3], [4, 5, 6]]),
    "more_columns": ("1 2 3 10 20 30\n4 5 6 40 50 60\n", [[1, 2, 3], [4, 5, 6]]),
    "more_columns_csv": ("x,y,z,i\n1,2,3,0.5\n4,5,6,0.7\n", [[1, 2, 3], [4, 5, 6]]),
    "ragged_columns": ("1 2 3 9\n4 5 6\n", [[1, 2, 3], [4, 5, 6]]),
    "tabs_crlf": ("x\ty\tz\r\n1\t2\t3\r\n4\t5\t6\r\n", [[1, 2, 3], [4, 5, 6]]),
    "bom": ("\ufeffx y z\n1 2 3\n", [[1, 2, 3]]),
    "bom_no_header": ("\ufeff1 2 3\n", [[1, 2, 3]]),
    "mixed_separators": ("1 2 3\n4,5,6\n7;8;9\n", [[1, 2, 3], [4, 5, 6], [7, 8, 9]]),
    "full_precision": ("5400000.123456789 0.1 -1e-300\n", [[5400000.123456789, 0.1, -1e-300]]),
}


@pytest.mark.parametrize("case", list(TEXT_CASES))
def test_read_text_variants(tmp_path: Path, case: str) -> None:
    content, expected = TEXT_CASES[case]
    path = _text(tmp_path / "t.xyz", content)
    np.testing.assert_array_equal(ndt_io.read(path).points, np.array(expected, dtype=float))


@pytest.mark.parametrize("suffix", [".ply", ".pcd", ".xyz"])
def test_drops_nonfinite_and_zero_points(
    tmp_path: Path, suffix: str, caplog: pytest.LogCaptureFixture
) -> None:
    nan, inf = np.nan, np.inf
    pts = np.array(
        [
            [1, 2, 3],
            [nan, 0, 0],
            [0, 0, 0],
            [4, inf, 5],
            [0, 0, 1],
            [0, 0, 0],
            [-inf, nan, 1],
            [-0.0, 0, 0],
            [6, 7, 8],
            [0, 0, 0],
        ],
        dtype=np.float64,
    )
    path = tmp_path / f"d{suffix}"
    if suffix == ".pcd":
        _pcd(path, pts, dtype=np.float64)
    else:
        ndt_io.write(path, pts)
    with caplog.at_level(logging.INFO, logger="ndt_cli.io"):
        cloud = ndt_io.read(path)
    assert (cloud.n_read, cloud.n_nonfinite, cloud.n_zero) == (10, 3, 4)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [0, 0, 1], [6, 7, 8]])
    assert "dropped 3 non-finite and 4 (0,0,0)" in caplog.text


# --- bad input --------------------------------------------------------------------------------


def _dir(p: Path) -> Path:
    p.mkdir()
    return p


def _empty(p: Path) -> Path:
    p.write_bytes(b"")
    return p


def _written(p: Path) -> Path:
    ndt_io.write(p, _points(2000, seed=6))
    return p


BAD: dict[str, tuple[str, Callable[[Path], Path], str | None]] = {
    "missing": ("missing.ply", lambda p: p, "not found"),
    "directory": ("scans.ply", _dir, "directory"),
    "unknown_extension": ("scan.abc", lambda p: _text(p, "1 2 3\n"), ".laz"),
    "no_extension": ("scan", lambda p: _text(p, "1 2 3\n"), "unknown extension"),
    **{f"empty{s}": (f"empty{s}", _empty, "empty") for s in ALL_SUFFIXES},
    "header_only.ply": ("h.ply", lambda p: _ply(p, np.empty((0, 3))), "no points"),
    "header_only_ascii.pcd": ("h.pcd", lambda p: _pcd(p, np.empty((0, 3)), "ascii"), "no points"),
    "header_only_binary.pcd": ("h.pcd", lambda p: _pcd(p, np.empty((0, 3))), "no points"),
    "header_only.xyz": ("h.xyz", lambda p: _text(p, "x y z\n# nothing\n"), "no points"),
    "header_only.csv": ("h.csv", lambda p: _text(p, "x,y,z\n"), "no points"),
    "header_only.las": ("h.las", lambda p: _las(p, np.empty((0, 3))), "no points"),
    "truncated.las": ("t.las", lambda p: _cut(_written(p)), "truncated"),
    "truncated_on_record.las": (
        "t.las",
        lambda p: _cut(_las(p, _points()), 375 + 34 * 20),
        "truncated",
    ),
    "truncated.laz": ("t.laz", lambda p: _cut(_written(p)), None),
    "truncated_binary.ply": ("t.ply", lambda p: _cut(_written(p)), "end-of-file"),
    "truncated_ascii.ply": ("t.ply", lambda p: _cut(_ply(p, _points(), text=True)), None),
    "truncated_binary.pcd": ("t.pcd", lambda p: _cut(_pcd(p, _points())), None),
    "truncated_compressed.pcd": (
        "t.pcd",
        lambda p: _cut(_pcd(p, _pcd_points(), "binary_compressed")),
        None,
    ),
    "truncated_on_record.pcd": (
        "t.pcd",
        lambda p: _cut_pcd_on_record(_pcd(p, _points())),
        "truncated",
    ),
    "truncated_ascii.pcd": ("t.pcd", lambda p: _cut(_pcd(p, _points(), "ascii")), None),
    "text_named.las": ("fake.las", lambda p: _text(p, "1 2 3\n4 5 6\n"), None),
    "text_named.laz": ("fake.laz", lambda p: _text(p, "1 2 3\n4 5 6\n"), None),
    "text_named.ply": ("fake.ply", lambda p: _text(p, "1 2 3\n4 5 6\n"), None),
    "text_named.pcd": ("fake.pcd", lambda p: _text(p, "1 2 3\n4 5 6\n"), "not a PCD"),
    "binary_named.xyz": ("fake.xyz", lambda p: _written(p.with_suffix(".las")).rename(p), "UTF-8"),
    "non_numeric_row.xyz": (
        "n.xyz",
        lambda p: _text(p, "x y z\n1 2 3\n4 5 6\nabc 7 8\n9 9 9\n"),
        "line 4",
    ),
    "short_row.csv": ("n.csv", lambda p: _text(p, "1,2,3\n4,5\n"), "line 2"),
    "all_nan.xyz": ("nan.xyz", lambda p: _text(p, "nan nan nan\n1 inf 2\n"), "no usable"),
    "all_zero.ply": ("zero.ply", lambda p: _ply(p, np.zeros((5, 3))), "no usable"),
    "no_xyz.ply": ("abc.ply", lambda p: _ply(p, _points(), names="abc"), "no x, y, z"),
    "no_vertex.ply": ("nov.ply", lambda p: _no_vertex_ply(p), "vertex"),
    "no_xyz.pcd": ("abc.pcd", lambda p: _pcd(p, _points(), fields=("a", "b", "c")), "no x, y, z"),
}


def _cut_pcd_on_record(path: Path) -> Path:
    data = path.read_bytes()
    start = data.index(b"DATA binary\n") + len(b"DATA binary\n")
    return _cut(path, keep=start + 16 * 100)  # x y z intensity float32: 16 bytes per point


def _no_vertex_ply(path: Path) -> Path:
    point = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    plyfile.PlyData([plyfile.PlyElement.describe(point, "point")]).write(str(path))
    return path


@pytest.mark.parametrize("streamed", [False, True], ids=["read", "read_chunks"])
@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_raises_one_line_input_error(tmp_path: Path, case: str, streamed: bool) -> None:
    name, make, fragment = BAD[case]
    path = make(tmp_path / name)
    with pytest.raises(InputError) as info:
        if streamed:
            list(ndt_io.read_chunks(path, chunk_size=500))
        else:
            ndt_io.read(path)
    message = str(info.value)
    assert path.name in message
    assert "\n" not in message and len(message) < 400
    assert info.value.exit_code == 2
    if fragment is not None:
        assert fragment in message


# --- writing ----------------------------------------------------------------------------------


def test_write_leaves_no_temp_file_and_replaces(tmp_path: Path) -> None:
    for suffix in ALL_SUFFIXES:
        out = tmp_path / suffix[1:] / f"out{suffix}"
        ndt_io.write(out, _points(10))
        ndt_io.write(out, _points(20, seed=9))  # overwrite an existing file
        assert [p.name for p in out.parent.iterdir()] == [out.name]
        assert ndt_io.read(out).n_read == 20


def test_failed_write_leaves_nothing(tmp_path: Path) -> None:
    pts = _points(10)
    pts[3, 1] = np.nan
    with pytest.raises(OutputError, match="NaN"):
        ndt_io.write(tmp_path / "bad.las", pts)
    assert list(tmp_path.iterdir()) == []


def test_write_into_unwritable_folder_raises_output_error(tmp_path: Path) -> None:
    blocker = _text(tmp_path / "file.txt", "not a folder\n")
    with pytest.raises(OutputError) as info:
        ndt_io.write(blocker / "out.ply", _points(10))
    assert "out.ply" in str(info.value) and "\n" not in str(info.value)
    assert [p.name for p in tmp_path.iterdir()] == ["file.txt"]


def test_write_rejects_unknown_extension_and_bad_shape(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match="cannot write"):
        ndt_io.write(tmp_path / "out.e57", _points(5))
    with pytest.raises(ValueError, match="N,3"):
        ndt_io.write(tmp_path / "out.ply", np.zeros((5, 2)))
    assert list(tmp_path.iterdir()) == []


def test_readers_and_suffixes() -> None:
    assert all(isinstance(r, formats.PointReader) for r in READERS)
    read_only = {".e57", ".ptx", ".3d"}
    assert set(ndt_io.SUPPORTED_SUFFIXES) == {*ALL_SUFFIXES, *read_only}
    assert set(ndt_io.WRITE_SUFFIXES) == set(ALL_SUFFIXES)


# --- shared real data ---------------------------------------------------------------------------


def test_shared_data_helper(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(conftest, "SHARED_DATA", tmp_path)
    (tmp_path / "here").mkdir()
    assert shared_data("here") == tmp_path / "here"
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="absent"):
        shared_data("absent")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="absent"):
        shared_data("absent")


def test_real_velodyne_pcd_drops_zero_points() -> None:
    path = shared_data("koide3_velodyne_pair") / "251370668.pcd"
    cloud = ndt_io.read(path)
    assert (cloud.n_read, cloud.n_zero, cloud.n_nonfinite) == (69_088, 5_032, 0)
    assert cloud.points.shape == (69_088 - 5_032, 3)
    assert not (cloud.points == 0).all(axis=1).any()
    assert 70 < np.linalg.norm(cloud.points, axis=1).max() < 80  # extents up to about 75 m


def test_e57_scans_are_read_by_number_and_header_poses_reported(tmp_path: Path) -> None:
    pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli.io import e57

    rng = np.random.default_rng(0)
    scans = [rng.uniform(-20, 20, (500, 3)), rng.uniform(-20, 20, (700, 3))]
    pose = np.eye(4)
    pose[:3, 3] = [10.0, -5.0, 1.5]
    path = tmp_path / "campaign.e57"
    e57.write(path, scans, [pose, None])
    assert expand([path]) == [Path(f"{path}#0"), Path(f"{path}#1")]
    for k in range(2):
        cloud = ndt_io.read(f"{path}#{k}")
        np.testing.assert_allclose(cloud.points, scans[k], atol=1e-5)  # own frame: pose not applied
    np.testing.assert_allclose(e57.header_pose(f"{path}#0"), pose)
    with pytest.raises(InputError, match="holds 2 scans"):
        ndt_io.read(path)
    with pytest.raises(InputError, match="no scan #5"):
        ndt_io.read(f"{path}#5")
    single = tmp_path / "one.e57"
    e57.write(single, scans[:1], [None])
    assert len(ndt_io.read(single).points) == 500
    bad = tmp_path / "bad.e57"
    bad.write_bytes(b"not an e57 file at all" * 10)
    with pytest.raises(InputError, match=r"bad\.e57"):
        ndt_io.read(bad)


def test_points_are_brought_into_the_configured_scanner_frame(tmp_path):
    from ndt_cli.config import InputConfig
    from ndt_cli.ndt.chunks import load_points

    # centimetres, x sideways, y up, z forward (a left-handed frame, as 3DTK writes)
    cm = np.array([[100.0, 50.0, 200.0], [0.0, -160.0, 100.0], [3000.0, 0.0, 3000.0]])
    f = tmp_path / "scan.3d"
    f.write_text("".join(f"{x} {y} {z}\n" for x, y, z in cm))
    inp = InputConfig(scale=0.01, axes="z,-x,y", max_range=32.0)
    pts, path = load_points(f, inp)
    assert path == f
    np.testing.assert_allclose(pts, [[2.0, -1.0, 0.5], [1.0, 0.0, -1.6]])  # the 42 m point dropped
    near, _ = load_points(cm, InputConfig(scale=0.01, min_range=2.0))
    assert len(near) == 2  # the point 1.9 m from the scanner is dropped
    with pytest.raises(InputError, match="min_range"):
        load_points(f, InputConfig(min_range=1e6))
