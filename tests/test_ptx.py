"""PTX (Leica Cyclone's text export) is read like a multi-scan E57: ``FILE.ptx#K`` names scan
K, points in the scanner's frame, the header's transform reported, never applied. Tested on
PDAL's PTX samples (``../shared/data/ptx_samples``, parsed here line by line as reference)
and on a simulated street written as one PTX file."""

from __future__ import annotations

import json
from pathlib import Path

import laspy
import numpy as np
import pytest
from conftest import shared_data
from typer.testing import CliRunner

from ndt_cli import sim
from ndt_cli.cli import chain_app, register_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import InputError
from ndt_cli.io import ptx, read
from ndt_cli.io.export import ExportScan, export
from ndt_cli.io.matrices import read_pose_list
from ndt_cli.io.multiscan_files import expand, header_pose
from ndt_cli.io.records import iter_records, summary

runner = CliRunner()


def parse(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """(transform as written, point rows) of every scan: the reference reading of a file."""
    lines = path.read_text().splitlines()
    out, k = [], 0
    while k < len(lines) and lines[k].strip():
        cols, rows = int(lines[k]), int(lines[k + 1])
        M = np.array([[float(v) for v in lines[k + j].split()] for j in range(6, 10)])
        n = cols * rows
        pts = np.array([[float(v) for v in lines[k + 10 + j].split()] for j in range(n)])
        out.append((M, pts))
        k += 10 + n
    return out


def samples() -> Path:
    return shared_data("ptx_samples")


def test_two_scans_of_one_file_are_file_0_and_file_1_in_their_own_frames():
    path = samples() / "multiple-and-transform.ptx"
    ref = parse(path)
    assert expand([path]) == [Path(f"{path}#0"), Path(f"{path}#1")]
    for k, (M, pts) in enumerate(ref):
        cloud = read(f"{path}#{k}")
        np.testing.assert_array_equal(cloud.points, pts[:, :3])
        np.testing.assert_array_equal(header_pose(Path(f"{path}#{k}")), M.T)
    with pytest.raises(
        InputError, match=r"holds 2 scans: name one as multiple-and-transform\.ptx#K"
    ):
        read(path)


def test_the_header_transform_maps_the_scan_onto_the_same_points_in_another_file():
    """Scan 0 of multiple-and-transform.ptx, moved by its header (z scaled by 2, then shifted),
    is the start of 1.2-with-color.ptx, which stores the same points with an identity."""
    moved = read(samples() / "multiple-and-transform.ptx#0").points
    T = ptx.header_pose(samples() / "multiple-and-transform.ptx#0")
    world = moved @ T[:3, :3].T + T[:3, 3]
    coloured = parse(samples() / "1.2-with-color.ptx")[0][1]
    np.testing.assert_allclose(world, coloured[:4, :3], atol=1e-6)


@pytest.mark.parametrize(
    ("name", "usable", "colours"),
    [
        ("complex-transform.ptx", 4, True),
        ("no-color.ptx", 15, False),
        ("1.2-with-color.ptx", 1065, True),
    ],
)
def test_single_scan_files_with_their_attributes(name, usable, colours):
    path = samples() / name
    (_, pts), *_ = parse(path)
    cloud = read(path)
    assert len(cloud.points) == usable and cloud.n_zero == len(pts) - usable  # 0 0 0: no return
    chunks = list(iter_records(path, chunk_points=100))
    got = {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]}
    np.testing.assert_array_equal(np.column_stack([got[a] for a in "xyz"]), pts[:, :3])
    np.testing.assert_allclose(got["intensity"], pts[:, 3], rtol=1e-6)
    assert ("red" in summary(path).names) == colours
    if colours:
        np.testing.assert_array_equal(got["blue"], pts[:, 6])


def test_a_ptx_scan_exports_with_its_colours(tmp_path):
    path = samples() / "1.2-with-color.ptx"
    (_, pts), *_ = parse(path)
    out = export([ExportScan(path, "c", 0, np.eye(4))], tmp_path / "c.las").paths[0]
    las = laspy.read(out)
    assert len(las.points) == 1065
    np.testing.assert_array_equal(
        np.sort(np.asarray(las.red)), np.sort(pts[:, 4].astype(np.uint16) * 257)
    )


DAMAGED = {
    "cut in a header": lambda t: "\n".join(t.splitlines()[:5]),
    "cut in the points": lambda t: "\n".join(t.splitlines()[:12]),
    "a word in the transform": lambda t: t.replace("0 1 0 0", "0 one 0 0", 1),
    "a point of five numbers": lambda t: t.replace(" 0.034912", " 0.034912 7", 1),
    "not a PTX file": lambda t: "hello\nworld\n",
}


@pytest.mark.parametrize("case", sorted(DAMAGED))
def test_a_damaged_ptx_is_one_line(tmp_path, case):
    bad = tmp_path / "bad.ptx"
    bad.write_text(DAMAGED[case]((samples() / "no-color.ptx").read_text()))
    res = runner.invoke(
        register_app, [str(bad), str(samples() / "no-color.ptx"), "-o", str(tmp_path / "o")]
    )
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.ptx" in lines[0] and "Traceback" not in res.output


def write_ptx(path: Path, scans: list[np.ndarray], poses: list[np.ndarray]) -> None:
    """Scans (scanner frame) as one PTX file, each with its pose as header transform."""
    with open(path, "w") as fh:
        for pts, T in zip(scans, poses, strict=True):
            fh.write(f"{len(pts)}\n1\n")
            fh.write(" ".join(f"{v:.6f}" for v in T[:3, 3]) + "\n")
            for row in T[:3, :3].T:
                fh.write(" ".join(f"{v:.9f}" for v in row) + "\n")
            for row in T.T:
                fh.write(" ".join(f"{v:.9f}" for v in row) + "\n")
            np.savetxt(fh, np.column_stack([pts, np.full(len(pts), 0.5)]), fmt="%.5f")


@pytest.mark.slow
def test_a_street_in_one_ptx_file_chains_onto_its_truth(tmp_path):
    _, scans, poses = sim.make_sequence(
        seed=21, n_scans=3, spacing=(13.0, 15.0), scan_kwargs={"n_azimuth": 600}
    )
    path = tmp_path / "street.ptx"
    write_ptx(path, scans, poses)
    out = tmp_path / "out"
    res = runner.invoke(chain_app, [str(path), "-o", str(out), "-q", "-j", "2"])
    assert res.exit_code == 0, res.output
    found = read_pose_list(out / "poses.txt")
    for k in range(3):
        T_ref = np.linalg.inv(poses[0]) @ poses[k]
        rot, trans = transform_errors(found[f"street.ptx#{k}"], T_ref)
        assert rot < 0.2 and trans < 0.05, (k, rot, trans)
    stored = (out / "e57_header_poses.txt").read_text()
    assert "street.ptx#1" in stored  # the header poses are reported
    assert json.loads((out / "summary.json").read_text())["scans"][1].endswith("street.ptx#1")
