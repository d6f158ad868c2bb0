"""What a surveyor hands over, end to end: georeferenced scans chained, then exported as one
LAZ and as an E57 with every point, its attributes and the CRS, where ground truth puts them; a
report.html per run; scan names that never overwrite one another."""

from __future__ import annotations

import json
import re

import laspy
import numpy as np
import pytest
from typer.testing import CliRunner

from ndt_cli import sim
from ndt_cli.cli import chain_app, export_app
from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.io.matrices import read_matrix

runner = CliRunner()
WKT = (
    'PROJCS["ETRS89 / UTM zone 32N",GEOGCS["ETRS89",DATUM["European_Terrestrial_Reference_'
    'System_1989",SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT['
    '"degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_'
    'origin",0],PARAMETER["central_meridian",9],PARAMETER["scale_factor",0.9996],PARAMETER['
    '"false_easting",500000],PARAMETER["false_northing",0],UNIT["metre",1],AUTHORITY["EPSG",'
    '"25832"]]'
)


def _georeferenced_las(path, points: np.ndarray, scan: int) -> None:
    """A LAS 1.4 point format 6 file: coordinates near 5.7e6 m, intensity, GPS time and a WKT
    CRS, as a scanner's georeferenced export would be."""
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.full(3, 0.001)
    header.offsets = np.floor(points.min(axis=0))
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(WKT))
    header.global_encoding.wkt = True
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.T
    n = len(points)
    las.intensity = (np.arange(n) * 7 + 1000 * scan) % 65535
    las.gps_time = 1.0e8 + scan * 1000.0 + np.arange(n) * 1e-5
    las.write(str(path))


@pytest.fixture(scope="module")
def georeferenced(tmp_path_factory):
    """Three scans of a street, each in a georeferenced frame G_k (UTM-like, a rough heading),
    chained; returns the folder, files, the frames and the true scanner poses."""
    folder = tmp_path_factory.mktemp("geo")
    _, scans, poses = sim.make_sequence(
        seed=21, n_scans=3, spacing=(13.0, 15.0), scan_kwargs={"n_azimuth": 800}
    )
    frames = [
        pose2d_matrix(512_000.0 + 40 * k, 5_700_000.0 - 25 * k, 0.3 * k, tz=87.0) for k in range(3)
    ]
    files = []
    for k, pts in enumerate(scans):
        files.append(folder / f"station_{k}.las")
        _georeferenced_las(files[-1], pts @ frames[k][:3, :3].T + frames[k][:3, 3], k)
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(folder / "out"), "-q", "-j", "2"])
    assert res.exit_code == 0, res.output
    return folder, files, frames, poses


def _truth_in_anchor_file_frame(k, frames, poses):
    """4x4 from scan k's file frame into the anchor's (scan 0's) file frame, by ground truth."""
    T_scan0_scank = np.linalg.inv(poses[0]) @ poses[k]
    return frames[0] @ T_scan0_scank @ np.linalg.inv(frames[k])


@pytest.mark.slow
def test_the_chain_exports_every_point_with_its_attributes_and_crs(georeferenced, tmp_path):
    folder, files, frames, poses = georeferenced
    out = tmp_path / "street.laz"
    res = runner.invoke(export_app, [str(folder / "out"), "--out", str(out), "-q"])
    assert res.exit_code == 0, res.output
    merged = laspy.read(out)
    inputs = [laspy.read(f) for f in files]
    assert merged.header.point_count == sum(len(i.points) for i in inputs)
    wkt = [v for v in merged.header.vlrs if v.record_id == 2112]
    assert wkt and WKT in wkt[0].string
    xyz = np.column_stack([merged.x, merged.y, merged.z])
    assert 5.69e6 < xyz[:, 1].min() < xyz[:, 1].max() < 5.71e6  # georeferenced, as the anchor
    for k, src in enumerate(inputs):
        mine = np.asarray(merged.scan_index) == k
        assert mine.sum() == len(src.points)
        np.testing.assert_array_equal(np.asarray(merged.intensity)[mine], np.asarray(src.intensity))
        np.testing.assert_allclose(np.asarray(merged.gps_time)[mine], np.asarray(src.gps_time))
        T = _truth_in_anchor_file_frame(k, frames, poses)
        file_xyz = np.column_stack([src.x, src.y, src.z])
        expected = file_xyz @ T[:3, :3].T + T[:3, 3]
        near = np.linalg.norm(xyz[mine] - expected, axis=1) < 0.02
        assert near.mean() >= 0.95, (k, near.mean())


@pytest.mark.slow
def test_the_e57_export_holds_one_scan_per_station_with_its_pose(georeferenced, tmp_path):
    pye57 = pytest.importorskip("pye57", reason="the e57 extra is not installed")
    folder, files, _, _ = georeferenced
    out = tmp_path / "street.e57"
    assert runner.invoke(export_app, [str(folder / "out"), "--out", str(out), "-q"]).exit_code == 0
    e57 = pye57.E57(str(out))
    try:
        assert e57.scan_count == len(files)
        poses = read_matrix(folder / "out" / "poses" / "T_world_station_2.txt")
        header = e57.get_header(2)
        np.testing.assert_allclose(header.translation, poses[:3, 3], atol=1e-6)
        np.testing.assert_allclose(header.rotation_matrix, poses[:3, :3], atol=1e-9)
    finally:
        e57.close()


@pytest.mark.slow
def test_the_chain_folder_holds_a_report_naming_every_scan(georeferenced):
    folder, files, _, _ = georeferenced
    html = (folder / "out" / "report.html").read_text()
    assert all(f.name in html for f in files)
    assert "<table" in html and 'src="data:image/png;base64,' in html
    assert "http://" not in html and "https://" not in html


def test_pose_files_are_what_cloudcompare_and_pdal_read(tmp_path):
    from ndt_cli.io.matrices import format_matrix

    T = pose2d_matrix(512_345.125, 5_700_123.5, 0.7, tz=87.25)
    text = format_matrix(T)
    rows = [line.split() for line in text.splitlines()]
    assert len(rows) == 4 and all(len(r) == 4 for r in rows)  # -APPLY_TRANS: 4 rows of 4
    values = np.array(" ".join(text.split()).split(), dtype=float)  # PDAL: 16 numbers
    np.testing.assert_array_equal(values.reshape(4, 4), T)


@pytest.mark.slow
def test_scans_of_one_e57_and_same_names_in_two_folders_never_overwrite(tmp_path):
    pye57 = pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli.io import e57, write

    _, scans, _ = sim.make_sequence(
        seed=21, n_scans=3, spacing=(13.0, 15.0), scan_kwargs={"n_azimuth": 600}
    )
    e57.write(tmp_path / "street3.e57", scans, [None, None, None])
    assert pye57  # the reader's library is there
    res = runner.invoke(chain_app, [str(tmp_path / "street3.e57"), "-o", str(tmp_path / "a"), "-q"])
    assert res.exit_code != 2, res.output  # the run completed (some scan may be suspect)
    links = sorted(p.name for p in (tmp_path / "a").glob("T_*.txt"))
    pairs = {frozenset(re.findall(r"street3_(\d)", n)) for n in links}  # either direction
    assert {frozenset({"0", "1"}), frozenset({"1", "2"})} <= pairs
    names = json.loads((tmp_path / "a" / "summary.json").read_text())["scans"]
    assert len(set(names)) == 3
    for side in ("north", "south"):
        (tmp_path / side).mkdir()
    write(tmp_path / "north" / "scan_1.laz", scans[0])
    write(tmp_path / "south" / "scan_1.laz", scans[1])
    write(tmp_path / "north" / "scan_2.laz", scans[2])
    files = [
        tmp_path / side / name
        for side, name in [
            ("north", "scan_1.laz"),
            ("south", "scan_1.laz"),
            ("north", "scan_2.laz"),
        ]
    ]
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(tmp_path / "b"), "-q"])
    assert res.exit_code != 2, res.output
    links = sorted(p.name for p in (tmp_path / "b").glob("T_*.txt"))
    assert {"T_north_scan_1_south_scan_1.txt", "T_south_scan_1_north_scan_1.txt"} & set(links)
    # the folder tells them apart
    assert len(links) == len(set(links)) == 3
    poses = sorted(p.name for p in (tmp_path / "b" / "poses").glob("*.txt"))
    assert len(poses) == len(set(poses))
