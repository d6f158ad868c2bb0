"""A first look at a file that landed where scans are expected (:mod:`ndt_cli.io.probe`):
real LAS, LAZ, E57, PTX, PLY, PCD and text files, whole, cut short at several places, being
written by laspy, and files that are no scan."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest
from conftest import shared_data

from ndt_cli.io.probe import FileKind, probe

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data"


def _cut(src: Path, dst: Path, share: float) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * share)])
    return dst


@pytest.mark.parametrize("suffix", [".laz", ".las"])
def test_a_las_or_laz_file_cut_short_is_incomplete_and_whole_it_is_a_scan(tmp_path, suffix):
    src = tmp_path / f"whole{suffix}"
    cloud = laspy.read(SAMPLE / "scan_01.laz")
    cloud.write(src)
    n = len(cloud.points)
    for share in (0.0005, 0.01, 0.5, 0.999):
        look = probe(_cut(src, tmp_path / f"cut{suffix}", share))
        assert look.kind is FileKind.INCOMPLETE, (share, look)
    assert probe(src).kind is FileKind.SCAN and probe(src).points == n


def test_a_las_file_still_being_written_by_a_writer_is_incomplete(tmp_path):
    cloud = laspy.read(SAMPLE / "scan_01.laz")
    path = tmp_path / "scan.las"
    kinds = []
    with laspy.open(path, mode="w", header=cloud.header) as writer:
        for start in range(0, len(cloud.points), 60_000):
            writer.write_points(cloud.points[start : start + 60_000])
            kinds.append(probe(path).kind)
    assert set(kinds) == {FileKind.INCOMPLETE}  # its header counts the points at the end
    assert probe(path).kind is FileKind.SCAN


def test_an_e57_file_cut_short_is_incomplete_and_its_scans_are_counted(tmp_path):
    pytest.importorskip("pye57", reason="the e57 extra is not installed")
    from ndt_cli.io import e57

    rng = np.random.default_rng(1)
    scans = [rng.normal(size=(500, 3)), rng.normal(size=(700, 3))]
    path = tmp_path / "two.e57"
    e57.write(path, scans, [None, None])
    look = probe(path)
    assert (look.kind, look.scans, look.points) == (FileKind.SCAN, 2, 1200)
    for share in (0.001, 0.3, 0.99):
        assert probe(_cut(path, tmp_path / "cut.e57", share)).kind is FileKind.INCOMPLETE


def test_a_whole_ptx_file_is_a_scan_of_its_scans():
    folder = shared_data("ptx_samples")
    src = folder / "multiple-and-transform.ptx"
    assert probe(src).kind is FileKind.SCAN and probe(src).scans == 2


def test_a_ptx_file_cut_in_its_points_is_incomplete(tmp_path):
    src = shared_data("ptx_samples") / "multiple-and-transform.ptx"
    assert probe(_cut(src, tmp_path / "cut.ptx", 0.75)).kind is FileKind.INCOMPLETE


def test_files_that_are_no_scan_are_told_so(tmp_path):
    rng = np.random.default_rng(0)
    cases = {
        "poses.txt": (SAMPLE / "poses_T_world_scan.txt").read_bytes(),
        "control.csv": b"scan,x,y,z,sigma_xy,sigma_z\nscan_00.laz,1.0,2.0,3.0,,\n",
        "garbage.laz": rng.bytes(5000),
        "garbage.e57": rng.bytes(5000),
        "garbage.ply": b"solid cube\n" + rng.bytes(100),
        "notes.pcd": b"hello, this is no point cloud\n" * 20,
    }
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        assert probe(tmp_path / name).kind is FileKind.NOT_A_SCAN, name
    (tmp_path / "dir.laz").mkdir()
    assert probe(tmp_path / "dir.laz").kind is FileKind.NOT_A_SCAN
    (tmp_path / "empty.laz").write_bytes(b"")
    assert probe(tmp_path / "empty.laz").kind is FileKind.INCOMPLETE


def test_text_ply_and_pcd_scans_are_scans_once_their_header_is_there(tmp_path):
    from ndt_cli import io as ndt_io

    pts = np.random.default_rng(2).normal(size=(300, 3))
    for suffix in (".xyz", ".csv", ".ply", ".pcd"):
        path = tmp_path / f"scan{suffix}"
        ndt_io.write(path, pts)
        look = probe(path)
        assert look.kind is FileKind.SCAN, (suffix, look)
        assert look.points in (None, 300)
    head = (tmp_path / "scan.ply").read_bytes()[:40]  # its header not whole yet
    (tmp_path / "cut.ply").write_bytes(head)
    assert probe(tmp_path / "cut.ply").kind is FileKind.INCOMPLETE
