"""Every E57 file of the shared samples (a real scanner export, and the edge cases of three E57
libraries: spherical, scaled-integer, invalid-state, extension, empty and corrupt files) reads
correctly or fails with one line naming the file and the problem, never libE57's debug text.

The point counts and boxes checked come from each folder's SOURCE.md, not from ndt-cli."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_DATA, shared_data

from ndt_cli.errors import InputError
from ndt_cli.io import e57, read
from ndt_cli.io.export import ExportScan, export
from ndt_cli.io.records import iter_records, summary

pytest.importorskip("pye57")
FOLDER = SHARED_DATA / "e57_samples"
FILES = sorted(p.relative_to(FOLDER).as_posix() for p in FOLDER.rglob("*.e57"))
KNOWN = {  # file -> usable points of its scans (SOURCE.md)
    "pye57/pumpAVisualReferenceImage.e57": [155_201],
    "e57_rust/tinyCartesianFloatRgb.e57": [2090],
    "e57_rust/tiny_spherical.e57": [180],
    "e57_python/pipeSpherical.e57": [1220],
    "libe57format/3rdParty/las2e57/ColourRepresentation.e57": [153],
    **{f"e57_rust/bunny{k}.e57": [30_571] for k in ("Double", "Float", "Int19", "Int21", "Int24")},
    "e57_rust/bunnyInt32.e57": [30_571],
    "libe57format/reference/bunnyDouble.e57": [30_571],
    "libe57format/reference/bunnyInt32.e57": [30_571],
    "pdal/A_B.e57": [2, 4],
    "pdal/A_moved_B.e57": [2, 4],
}
MUST_FAIL = {  # corrupt or without points: one line
    "e57_rust/corrupt_crc.e57",
    "libe57format/self/bad-crc.e57",
    "e57_rust/empty.e57",
    "e57_rust/empty_pc.e57",
    "libe57format/self/empty.e57",
    "libe57format/self/ZeroPoints.e57",
    "libe57format/self/ZeroPointsInvalid.e57",
}


def _specs(path: Path) -> list[str]:
    try:
        n = e57.scan_count(path)
    except InputError:
        return [str(path)]
    return [f"{path}#{k}" for k in range(n)] if n > 1 else [str(path)]


def _one_line(exc: InputError, path: Path) -> None:
    text = str(exc)
    assert "\n" not in text and "****" not in text and len(text) < len(str(path)) + 200, text
    assert text.startswith(str(path)), text


@pytest.mark.parametrize("name", FILES or ["(none)"])
def test_every_sample_reads_or_fails_in_one_line(name, capfd):
    path = shared_data("e57_samples") / name
    counts = []
    for spec in _specs(path):
        try:
            cloud = read(spec)
        except InputError as exc:
            _one_line(exc, path)
            counts.append(None)
            continue
        chunks = list(iter_records(spec, chunk_points=1000))
        assert summary(spec).count >= sum(len(c["x"]) for c in chunks)  # invalid ones dropped
        xyz = np.column_stack([np.concatenate([c[a] for c in chunks]) for a in "xyz"])
        usable = np.isfinite(xyz).all(axis=1) & (xyz != 0).any(axis=1)
        np.testing.assert_array_equal(xyz[usable], cloud.points)  # both readers agree
        counts.append(len(cloud.points))
    if name in KNOWN:
        assert counts == KNOWN[name]
    if name in MUST_FAIL:
        assert counts == [None]
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # no library text on the terminal


def test_the_real_scanner_export_keeps_its_attributes_through_an_export(tmp_path):
    pye57 = pytest.importorskip("pye57")
    path = shared_data("e57_samples") / "pye57" / "pumpAVisualReferenceImage.e57"
    chunks = list(iter_records(path))
    xyz = np.column_stack([np.concatenate([c[a] for c in chunks]) for a in "xyz"])
    # SOURCE.md: bbox x[-2.904,1.722] y[-5.301,-0.793] z[-1.900,1.843], rows 0..1073, columns 0..344
    np.testing.assert_allclose(xyz.min(axis=0), [-2.904, -5.301, -1.900], atol=6e-4)
    np.testing.assert_allclose(xyz.max(axis=0), [1.722, -0.793, 1.843], atol=6e-4)
    rows = np.concatenate([c["row_index"] for c in chunks])
    columns = np.concatenate([c["column_index"] for c in chunks])
    assert (rows.min(), rows.max(), columns.min(), columns.max()) == (0, 1073, 0, 344)
    out = export([ExportScan(path, "pumpA", 0, np.eye(4))], tmp_path / "pump.e57").paths[0]
    data = pye57.E57(str(out)).read_scan_raw(0)
    np.testing.assert_array_equal(data["rowIndex"], rows)
    np.testing.assert_array_equal(data["columnIndex"], columns)
    np.testing.assert_allclose(data["cartesianX"], xyz[:, 0])
