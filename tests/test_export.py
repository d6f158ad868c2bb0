"""Exporting the registered cloud: real LAS/LAZ, PLY and E57 files through laspy, plyfile and
pye57, no mocks. Three simulated scans are stored as LAS 1.4 files in rough georeferenced
coordinates (each scan's own frame shifted to near (500000, 5.7e6)) with intensity, GPS time,
RGB, classification, an extra-bytes dimension and a WKT CRS; the export with the ground-truth
poses must put every point where ground truth says, with every attribute intact."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import laspy
import numpy as np
import pytest
from laspy.vlrs.known import WktCoordinateSystemVlr

from ndt_cli import sim
from ndt_cli.core.transforms import pose2d_matrix, translation
from ndt_cli.errors import InputError, OutputError
from ndt_cli.io import records
from ndt_cli.io.export import ExportScan, export
from ndt_cli.io.names import per_scan_file_names

pytest.importorskip("lazrs")

WKT = (
    'PROJCS["ETRS89 / UTM zone 32N",GEOGCS["ETRS89",DATUM["European_Terrestrial_Reference_System'
    '_1989",SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT["degree",'
    '0.0174532925199433]],PROJECTION["Transverse_Mercator"],PARAMETER["central_meridian",9],'
    'PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],UNIT["metre",1],'
    'AUTHORITY["EPSG","25832"]]'
)
G = translation(np.array([500123.0, 5700456.0, 87.0])) @ pose2d_matrix(0.0, 0.0, np.radians(30))
"""World (simulator) frame to the georeferenced frame."""


@dataclass(frozen=True)
class Campaign:
    files: list[Path]
    scans: list[ExportScan]  # T_world_file maps each file into the georeferenced frame
    truth: list[np.ndarray]  # each scan's simulated points in the georeferenced frame, m
    local: list[np.ndarray]  # each scan's simulated points in its scanner frame, m
    poses: list[np.ndarray]  # T_world_scan (simulator world)


def write_las(
    path: Path,
    xyz: np.ndarray,
    point_format: int,
    seed: int,
    *,
    wkt: str | None = WKT,
    extra: tuple[str, str] | None = ("reflectance", "int16"),
    version: str = "1.4",
) -> laspy.LasData:
    """A LAS/LAZ file of ``xyz`` with random attributes (1 mm scale)."""
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.full(3, 0.001)
    header.offsets = np.floor(xyz.min(axis=0))
    if extra is not None:
        scaled = extra[1].startswith("int")
        header.add_extra_dim(
            laspy.ExtraBytesParams(
                extra[0],
                extra[1],
                "test attribute",
                scales=np.array([0.01]) if scaled else None,
                offsets=np.array([0.0]) if scaled else None,
            )
        )
    if wkt is not None:
        header.vlrs.append(WktCoordinateSystemVlr(wkt))
        header.global_encoding.wkt = True
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    n = len(xyz)
    las.intensity = rng.integers(0, 65536, n, dtype=np.uint16)
    las.classification = rng.integers(0, 20, n, dtype=np.uint8)
    las.point_source_id = np.full(n, 100 + seed, dtype=np.uint16)
    dims = set(las.point_format.dimension_names)
    if "gps_time" in dims:
        las.gps_time = 1.4e9 + np.cumsum(rng.uniform(0, 1e-5, n))
    if "red" in dims:
        for c in ("red", "green", "blue"):
            las[c] = rng.integers(0, 65536, n, dtype=np.uint16)
    if extra is not None:
        las.points.array[extra[0]] = rng.integers(-3000, 3000, n).astype(extra[1])
    las.write(str(path))
    return las


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Campaign:
    folder = tmp_path_factory.mktemp("campaign")
    _, local, poses = sim.make_sequence(
        seed=21, n_scans=3, spacing=(13.0, 17.0), scan_kwargs={"n_azimuth": 500}
    )
    files, scans, truth = [], [], []
    for k, (pts, T) in enumerate(zip(local, poses, strict=True)):
        c = np.round(G[:3, :3] @ T[:3, 3] + G[:3, 3])  # rough georeferenced scanner position
        files.append(folder / f"scan_{k}.las")
        write_las(files[-1], pts + c, 6 if k == 1 else 7, seed=k)
        T_world_file = G @ T @ translation(-c)
        scans.append(ExportScan(files[-1], files[-1].name, k, T_world_file, anchor=k == 0))
        truth.append(pts @ (G @ T)[:3, :3].T + (G @ T)[:3, 3])
    return Campaign(files, scans, truth, local, poses)


def world_of(scan: ExportScan, xyz: np.ndarray) -> np.ndarray:
    T = scan.T_world_file
    return xyz @ T[:3, :3].T + T[:3, 3]


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_merged_laz_keeps_every_point_attribute_and_the_crs(campaign: Campaign, tmp_path: Path):
    calls = []
    out = tmp_path / "merged.laz"
    result = export(
        campaign.scans, out, chunk_points=50_000, progress=lambda d, t: calls.append((d, t))
    )
    inputs = [laspy.read(f) for f in campaign.files]
    merged = laspy.read(out)
    assert len(merged.points) == sum(len(i.points) for i in inputs) == result.points_written
    assert merged.header.point_format.id == 7 == result.point_format
    assert str(merged.header.version) == "1.4"
    assert np.allclose(merged.header.scales, 0.001)
    assert calls[-1][0] == calls[-1][1] == result.points_read
    done = [d for d, _ in calls]
    assert done == sorted(done)
    scan_index = np.asarray(merged.points.array["scan_index"])
    assert merged.points.array.dtype["scan_index"] == np.uint16
    xyz = np.column_stack([merged.x, merged.y, merged.z])
    assert np.abs(merged.header.mins - xyz.min(axis=0)).max() < 1e-6
    for k, las in enumerate(inputs):
        sel = scan_index == k
        assert sel.sum() == len(las.points)
        for name in ("intensity", "gps_time", "classification", "point_source_id"):
            assert np.array_equal(np.asarray(merged[name])[sel], np.asarray(las[name])), name
        for c in ("red", "green", "blue"):
            expected = np.asarray(las[c]) if k != 1 else np.zeros(sel.sum())
            assert np.array_equal(np.asarray(merged[c])[sel], expected)
        raw = merged.points.array["reflectance"][sel]
        assert np.array_equal(raw, las.points.array["reflectance"])
        error = np.linalg.norm(xyz[sel] - campaign.truth[k], axis=1)
        assert (error < 0.02).all() and error.max() < 0.002  # mm rounding of input and output
    assert np.abs(xyz).max() > 5e6  # georeferenced, millimetres kept
    crs_in = [v for v in records.raw_vlrs(campaign.files[0]) if v.record_id == 2112]
    crs_out = [v for v in records.raw_vlrs(out) if v.record_id == 2112]
    assert crs_out == crs_in and crs_out[0].data == WKT.encode() + b"\0"
    assert merged.header.global_encoding.wkt
    assert leftovers(tmp_path) == ["merged.laz"]


def test_header_summary_without_reading_points(campaign: Campaign):
    s = records.summary(campaign.files[0])
    las = laspy.read(campaign.files[0])
    assert s.count == len(las.points) and s.point_format == 7 and s.version == "1.4"
    assert np.allclose(s.bounds[0], las.header.mins) and np.allclose(s.bounds[1], las.header.maxs)
    assert [(v.user_id, v.record_id) for v in s.crs] == [("LASF_Projection", 2112)]
    assert s.wkt
    refl = s.dimension("reflectance")
    assert refl.kind == "extra" and refl.dtype == np.int16 and refl.scales == (0.01,)
    assert s.dimension("gps_time").dtype == np.float64 and "red" in s.names
    chunks = list(records.iter_records(campaign.files[0], chunk_points=25_000))
    assert len(chunks) == -(-len(las.points) // 25_000)
    assert set(chunks[0]) == {"x", "y", "z", *s.names}
    assert np.array_equal(np.concatenate([c["x"] for c in chunks]), las.x)


def test_mixed_legacy_formats_give_a_format_holding_both(campaign: Campaign, tmp_path: Path):
    a, b = tmp_path / "a.las", tmp_path / "b.las"
    pts = campaign.local[0][:5000]
    las_a = write_las(a, pts, 1, seed=5, extra=None, version="1.2")  # GPS time
    las_b = write_las(b, pts[::-1].copy(), 2, seed=6, extra=None, version="1.2")  # RGB
    scans = [ExportScan(a, "a", 0, np.eye(4)), ExportScan(b, "b", 1, translation([1.0, 2, 3]))]
    out = tmp_path / "out.las"
    export(scans, out)
    merged = laspy.read(out)
    assert merged.header.point_format.id == 3
    sel = np.asarray(merged.points.array["scan_index"]) == 0
    assert np.array_equal(merged.gps_time[sel], las_a.gps_time)
    assert not merged.gps_time[~sel].any()
    assert np.array_equal(merged.red[~sel], las_b.red) and not merged.red[sel].any()
    assert np.array_equal(merged.classification[~sel], las_b.classification)
    assert np.abs(merged.z[~sel] - (las_b.z + 3)).max() < 1e-6


def test_legacy_and_14_inputs_give_a_14_format(campaign: Campaign, tmp_path: Path):
    a, b = tmp_path / "a.las", tmp_path / "b.laz"
    pts = campaign.local[1][:3000]
    las_a = write_las(a, pts, 1, seed=7, extra=None, version="1.2")
    las_a.scan_angle_rank = np.full(len(pts), -12, dtype=np.int8)
    las_a.write(str(a))
    write_las(b, pts, 7, seed=8, extra=None)
    scans = [ExportScan(a, "a", 0, np.eye(4)), ExportScan(b, "b", 1, np.eye(4))]
    merged = laspy.read(export(scans, tmp_path / "out.las").paths[0])
    assert merged.header.point_format.id == 7
    sel = np.asarray(merged.points.array["scan_index"]) == 0
    assert np.array_equal(merged.scan_angle[sel], np.full(sel.sum(), round(-12 / 0.006)))
    assert np.array_equal(merged.classification[sel], las_a.classification)


def test_extra_bytes_union_and_conflicts(campaign: Campaign, tmp_path: Path):
    pts = campaign.local[2][:2000]
    a, b, c = tmp_path / "a.las", tmp_path / "b.las", tmp_path / "c.las"
    write_las(a, pts, 6, 1, extra=("range", "float32"))
    las_b = write_las(b, pts, 6, 2, extra=("range", "float64"))
    write_las(c, pts, 6, 3, extra=("range", "int16"))  # scaled: cannot merge with floats
    out = tmp_path / "out.las"
    export([ExportScan(a, "a", 0, np.eye(4)), ExportScan(b, "b", 1, np.eye(4))], out)
    merged = laspy.read(out)
    assert merged.points.array.dtype["range"] == np.float64
    sel = np.asarray(merged.points.array["scan_index"]) == 1
    assert np.array_equal(merged.points.array["range"][sel], las_b.points.array["range"])
    bad = [ExportScan(a, "a", 0, np.eye(4)), ExportScan(c, "c", 1, np.eye(4))]
    with pytest.raises(OutputError, match="'range'") as info:
        export(bad, tmp_path / "bad.las")
    assert info.value.path == c and "\n" not in str(info.value)
    assert not (tmp_path / "bad.las").exists() and leftovers(tmp_path) == sorted(
        ["a.las", "b.las", "c.las", "out.las"]
    )


def test_other_crs_is_a_warning(
    campaign: Campaign, tmp_path: Path, caplog: pytest.LogCaptureFixture
):
    other = tmp_path / "other.las"
    write_las(other, campaign.truth[1][:1000], 6, 3, wkt=WKT.replace("32N", "33N"))
    scans = [campaign.scans[0], ExportScan(other, "other", 1, np.eye(4))]
    with caplog.at_level(logging.WARNING):
        export(scans, tmp_path / "out.las")
    assert any("CRS differs" in r.getMessage() for r in caplog.records)
    crs = [v.data for v in records.raw_vlrs(tmp_path / "out.las") if v.record_id == 2112]
    assert crs == [WKT.encode() + b"\0"]  # the anchor's
    first = campaign.scans[0]
    first = ExportScan(first.path, first.name, first.index, first.T_world_file)
    scans = [first, ExportScan(other, "other", 1, np.eye(4), anchor=True)]
    export(scans, tmp_path / "out.las")
    crs = [v.data for v in records.raw_vlrs(tmp_path / "out.las") if v.record_id == 2112]
    assert crs == [WKT.replace("32N", "33N").encode() + b"\0"]


def test_e57_scans_into_las(tmp_path: Path):
    """Scans K of a multi-scan E57: 8-bit colours become 16-bit, float intensities are mapped
    from the scan's intensity limits onto 0..65535."""
    pye57 = pytest.importorskip("pye57")
    rng = np.random.default_rng(4)
    src = tmp_path / "two.e57"
    e57 = pye57.E57(str(src), mode="w")
    data = []
    for k in range(2):
        n = 800 + 100 * k
        d = {f"cartesian{a}": rng.uniform(-20, 20, n) for a in "XYZ"}
        d["intensity"] = rng.uniform(0.1, 0.9, n).astype(np.float32)
        for c in ("Red", "Green", "Blue"):
            d[f"color{c}"] = rng.integers(0, 256, n, dtype=np.uint8)
        e57.write_scan_raw(d)
        data.append(d)
    e57.close()
    scans = [
        ExportScan(f"{src}#{k}", f"two.e57#{k}", k, translation([k, 0.0, 0.0])) for k in (0, 1)
    ]
    merged = laspy.read(export(scans, tmp_path / "out.las").paths[0])
    assert merged.header.point_format.id == 2 and len(merged.points) == 1700
    scan_index = np.asarray(merged.points.array["scan_index"])
    for k, d in enumerate(data):
        sel = scan_index == k
        assert np.array_equal(merged.red[sel], d["colorRed"].astype(np.uint16) * 257)
        v = d["intensity"]
        expected = np.round((v - v.min()) / (v.max() - v.min()) * 65535)
        assert np.abs(merged.intensity[sel].astype(float) - expected).max() <= 1
        assert np.abs(merged.x[sel] - d["cartesianX"] - k).max() < 0.001


def test_e57_one_scan_per_station_in_its_own_frame(campaign: Campaign, tmp_path: Path):
    pye57 = pytest.importorskip("pye57")
    out = tmp_path / "out.e57"
    export(campaign.scans, out, chunk_points=40_000)
    e57 = pye57.E57(str(out))
    try:
        assert e57.scan_count == 3
        assert e57.root["coordinateMetadata"].value() == WKT  # the anchor's CRS
        for k, scan in enumerate(campaign.scans):
            header = e57.get_header(k)
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = header.rotation_matrix, header.translation
            assert np.abs(T - scan.T_world_scan).max() < 1e-9
            assert header["name"].value() == scan.name
            data = e57.read_scan(
                k, intensity=True, colors=k != 1, transform=False, ignore_missing_fields=True
            )
            las = laspy.read(campaign.files[k])
            own = np.column_stack([data[f"cartesian{a}"] for a in "XYZ"])
            assert np.abs(own - np.column_stack([las.x, las.y, las.z])).max() < 1e-9
            assert np.abs(world_of(scan, own) - campaign.truth[k]).max() < 0.002
            assert np.array_equal(data["intensity"], np.asarray(las.intensity, np.float32))
            if k != 1:
                assert np.array_equal(data["colorRed"], np.asarray(las.red) >> 8)
    finally:
        e57.close()


def test_e57_and_las_apply_scale_and_axes(campaign: Campaign, tmp_path: Path):
    """A PLY in centimetres with x right, y up, z forward: E57 holds the scanner frame in metres
    with pose T_world_scan; the LAS holds the world frame."""
    pytest.importorskip("pye57")
    import plyfile
    import pye57

    from ndt_cli.config import axes_matrix

    pts, T = campaign.local[0][:4000], campaign.poses[0]
    A = axes_matrix("z,-x,y")
    raw = pts @ A / 0.01  # file = A^T p / scale, so that p = scale * A @ file
    vertex = np.zeros(len(raw), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("intensity", "f4")])
    vertex["x"], vertex["y"], vertex["z"] = raw.T
    vertex["intensity"] = np.linspace(0.0, 1.0, len(raw))
    src = tmp_path / "cm.ply"
    plyfile.PlyData([plyfile.PlyElement.describe(vertex, "vertex")]).write(str(src))
    scan = ExportScan.from_pose(src, "cm", 4, G @ T, scale=0.01, axes="z,-x,y")
    export([scan], tmp_path / "out.e57")
    e57 = pye57.E57(str(tmp_path / "out.e57"))
    data = e57.read_scan(0, intensity=True, transform=False, ignore_missing_fields=True)
    header = e57.get_header(0)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = header.rotation_matrix, header.translation
    e57.close()
    own = np.column_stack([data[f"cartesian{a}"] for a in "XYZ"])
    assert np.abs(own - pts).max() < 1e-9
    assert np.abs(pose - G @ T).max() < 1e-9
    assert np.allclose(data["intensity"], np.linspace(0.0, 1.0, len(raw)))
    las = laspy.read(export([scan], tmp_path / "out.las").paths[0])
    xyz = np.column_stack([las.x, las.y, las.z])
    assert np.abs(xyz - pts @ (G @ T)[:3, :3].T - (G @ T)[:3, 3]).max() < 0.001
    assert las.intensity.min() == 0 and las.intensity.max() == 65535  # float range -> 16 bits


def test_ply_keeps_the_attributes(campaign: Campaign, tmp_path: Path):
    import plyfile

    out = tmp_path / "out.ply"
    export(campaign.scans, out, chunk_points=30_000)
    ply = plyfile.PlyData.read(str(out))
    assert not ply.text and ply.byte_order == "<"
    v = ply["vertex"].data
    assert v.dtype["x"] == np.float64 and v.dtype["scan_index"] == np.uint16
    for k, f in enumerate(campaign.files):
        las = laspy.read(f)
        sel = v["scan_index"] == k
        world = world_of(campaign.scans[k], np.column_stack([las.x, las.y, las.z]))
        assert np.abs(np.column_stack([v["x"], v["y"], v["z"]])[sel] - world).max() < 1e-6
        for name in ("intensity", "gps_time", "classification", "return_number"):
            assert np.array_equal(v[name][sel], np.asarray(las[name])), name
        assert np.allclose(v["reflectance"][sel], las.reflectance)  # scaled: real values


def test_voxel_keeps_the_first_point_of_every_occupied_voxel(campaign: Campaign, tmp_path: Path):
    import plyfile

    voxel = 0.5
    out = tmp_path / "thin.ply"
    result = export(campaign.scans, out, voxel=voxel, chunk_points=20_000)
    v = plyfile.PlyData.read(str(out))["vertex"].data
    kept = np.column_stack([v["x"], v["y"], v["z"]])
    world = np.concatenate(
        [
            world_of(s, np.column_stack([las.x, las.y, las.z]))
            for s, las in zip(campaign.scans, (laspy.read(f) for f in campaign.files), strict=True)
        ]
    )
    key_of = lambda p: [tuple(r) for r in np.floor(p / voxel).astype(np.int64)]  # noqa: E731
    kept_keys = key_of(kept)
    assert len(set(kept_keys)) == len(kept_keys)  # at most one point per voxel
    _, first = np.unique(np.floor(world / voxel).astype(np.int64), axis=0, return_index=True)
    assert len(kept) == len(first) == result.points_written  # one per occupied voxel
    assert np.array_equal(kept, world[np.sort(first)])  # the first met, in scan order
    assert result.points_thinned == len(world) - len(kept)


def test_per_scan_files_have_unique_names(campaign: Campaign, tmp_path: Path):
    names = ["north/scan_1.las", "south/scan_1.las", "a.las", "a.laz"]
    assert per_scan_file_names(names, ".laz") == [
        "north_scan_1.laz",
        "south_scan_1.laz",
        "a.laz",
        "a_2.laz",
    ]
    assert per_scan_file_names(["c.e57#0", "c.e57#1", "x y?.las"], ".ply") == [
        "c_0.ply",
        "c_1.ply",
        "x_y.ply",
    ]
    scans = [
        ExportScan(s.path, n, s.index, s.T_world_file, anchor=s.anchor)
        for s, n in zip(campaign.scans, ["north/s.las", "south/s.las", "s.las"], strict=True)
    ]
    result = export(scans, tmp_path / "unused.las", per_scan_dir=tmp_path / "per_scan")
    listed = [".ndt-cli-outputs", "north_s.las", "s.las", "south_s.las"]  # with their manifest
    assert leftovers(tmp_path / "per_scan") == listed
    assert not (tmp_path / "unused.las").exists()
    for path, f in zip(result.paths, campaign.files, strict=True):
        las, src = laspy.read(path), laspy.read(f)
        assert len(las.points) == len(src.points)
        assert las.header.point_format.id == src.header.point_format.id
        assert [v.data for v in records.raw_vlrs(path) if v.record_id == 2112] == [
            WKT.encode() + b"\0"
        ]


def test_failures_leave_nothing_behind(campaign: Campaign, tmp_path: Path):
    broken = tmp_path / "broken.las"
    data = campaign.files[2].read_bytes()
    broken.write_bytes(data[: len(data) - 5000])  # the header announces more points
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    scans = [*campaign.scans[:2], ExportScan(broken, "broken", 2, np.eye(4))]
    for out in (out_dir / "merged.laz", out_dir / "merged.ply", out_dir / "merged.e57"):
        with pytest.raises(InputError) as info:
            export(scans, out, chunk_points=20_000)
        assert info.value.path == broken
    with pytest.raises(InputError):
        export(scans, out_dir / "x.las", per_scan_dir=out_dir / "per_scan")
    assert leftovers(out_dir) == []
    with pytest.raises(OutputError, match="supported"):
        export(campaign.scans, out_dir / "merged.xyz")


def test_unwritable_output_is_an_output_error(campaign: Campaign, tmp_path: Path):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the output folder should be")
    for out in (blocker / "out.las", blocker / "out.e57"):
        with pytest.raises(OutputError) as info:
            export(campaign.scans[:1], out)
        assert info.value.path == out and "\n" not in str(info.value)
    with pytest.raises(OutputError):
        export(campaign.scans[:1], tmp_path / "x.las", per_scan_dir=blocker / "per_scan")
    assert leftovers(tmp_path) == ["not_a_folder"]


def test_other_formats_records(tmp_path: Path):
    """PCD fields (packed rgb unpacked), a multi-scan E57 named FILE.e57#K, text x, y, z."""
    pytest.importorskip("pye57")
    import pypcd4

    from ndt_cli.io import e57 as e57io

    pts = np.random.default_rng(3).normal(size=(500, 3))
    rgb = pypcd4.PointCloud.encode_rgb(np.tile(np.array([[10, 20, 30]], np.uint8), (500, 1)))
    cloud = pypcd4.PointCloud.from_points(
        [pts[:, 0], pts[:, 1], pts[:, 2], np.arange(500, dtype=np.float32), rgb.ravel()],
        ("x", "y", "z", "intensity", "rgb"),
        (np.float64, np.float64, np.float64, np.float32, np.float32),
    )
    cloud.save(tmp_path / "a.pcd", encoding=pypcd4.Encoding.BINARY_COMPRESSED)
    s = records.summary(tmp_path / "a.pcd")
    assert s.count == 500 and set(s.names) == {"intensity", "red", "green", "blue"}
    (chunk,) = records.iter_records(tmp_path / "a.pcd")
    assert (chunk["green"] == 20).all() and np.array_equal(chunk["intensity"], np.arange(500))
    e57io.write(tmp_path / "two.e57", [pts, pts[:100] + 1], [None, np.eye(4)])
    s1 = records.summary(f"{tmp_path / 'two.e57'}#1")
    assert s1.count == 100 and s1.pose is not None
    chunks = list(records.iter_records(f"{tmp_path / 'two.e57'}#1", chunk_points=30))
    assert [len(c["x"]) for c in chunks] == [30, 30, 30, 10]
    assert np.allclose(np.concatenate([c["x"] for c in chunks]), pts[:100, 0] + 1)
    with pytest.raises(InputError, match="2"):
        records.summary(tmp_path / "two.e57")
    np.savetxt(tmp_path / "p.xyz", pts)
    assert records.summary(tmp_path / "p.xyz").count is None
    (c,) = records.iter_records(tmp_path / "p.xyz")
    assert set(c) == {"x", "y", "z"} and np.allclose(c["z"], pts[:, 2])


def test_e57_colours_of_16_bit_las_are_judged_from_the_whole_scan(tmp_path: Path):
    """The first chunk holds 8-bit-looking values, the rest 16-bit ones: every value of the
    scan is shifted alike (value >> 8), whatever the chunk it comes in."""
    pye57 = pytest.importorskip("pye57")
    n = 3000
    las = laspy.LasData(laspy.LasHeader(point_format=2, version="1.2"))
    las.header.scales = np.full(3, 0.001)
    rng = np.random.default_rng(6)
    las.x, las.y, las.z = (rng.uniform(-10, 10, n) for _ in range(3))
    colour = np.where(np.arange(n) < 1000, 200, 60000).astype(np.uint16)
    las.red, las.green, las.blue = colour, colour, colour
    src = tmp_path / "rgb.las"
    las.write(str(src))
    scan = ExportScan(src, "rgb.las", 0, np.eye(4))
    out = export([scan], tmp_path / "rgb.e57", chunk_points=1000).paths[0]
    red = pye57.E57(str(out)).read_scan_raw(0)["colorRed"]
    np.testing.assert_array_equal(red, colour >> 8)
