"""Every format of the one table of readers, end to end: a pair of simulated scans written in
it (by writers that are not the readers: the project's writers, pye57, or plain text), read,
registered and exported. Expected points and poses come from the simulator's ground truth."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest

from ndt_cli import io, register, sim
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.export import ExportScan, export
from ndt_cli.io.points import READERS, SUPPORTED_SUFFIXES
from ndt_cli.io.records import format_of, iter_records, summary


def _write_e57(path: Path, points: np.ndarray) -> None:
    pye57 = pytest.importorskip("pye57")
    e57 = pye57.E57(str(path), mode="w")
    e57.write_scan_raw({f"cartesian{a}": points[:, k].copy() for k, a in enumerate("XYZ")})
    e57.close()


def _write_ptx(path: Path, points: np.ndarray) -> None:
    """One scan of ``len(points)`` columns and one row, identity header pose, intensity 0.5."""
    head = [str(len(points)), "1", "0 0 0", "1 0 0", "0 1 0", "0 0 1"]
    head += ["1 0 0 0", "0 1 0 0", "0 0 1 0", "0 0 0 1"]
    body = "\n".join(f"{x:.6f} {y:.6f} {z:.6f} 0.5" for x, y, z in points)
    path.write_text("\n".join(head) + "\n" + body + "\n", encoding="ascii")


def _write_3d(path: Path, points: np.ndarray) -> None:
    np.savetxt(path, points, fmt="%.6f")


WRITERS = {".e57": _write_e57, ".ptx": _write_ptx, ".3d": _write_3d}
TOLERANCE = {".las": 1e-3, ".laz": 1e-3}  # m: LAS stores millimetres; text 1e-6 m, others exact


@pytest.fixture(scope="module")
def pair():
    _, scans, poses = sim.make_sequence(
        seed=5, n_scans=2, spacing=(14.0, 16.0), scan_kwargs={"n_azimuth": 900}
    )
    return scans, poses


def test_every_readable_suffix_is_covered_here():
    """A format added to the table must be added to this test too (a writer for it)."""
    writable = set(io.WRITE_SUFFIXES) | set(WRITERS)
    assert set(SUPPORTED_SUFFIXES) == writable
    names = {r.name for r in READERS}
    assert len(names) == len(READERS) and "" not in names  # one name per reader


@pytest.mark.parametrize("suffix", SUPPORTED_SUFFIXES)
@pytest.mark.slow
def test_a_pair_in_each_format_is_read_registered_and_exported(pair, suffix, tmp_path):
    scans, poses = pair
    files = [tmp_path / f"scan_{k}{suffix}" for k in range(2)]
    for f, pts in zip(files, scans, strict=True):
        WRITERS.get(suffix, io.write)(f, pts)
    tol = TOLERANCE.get(suffix, 1e-5)

    # read: x, y, z and the header, through the same reader
    for f, pts in zip(files, scans, strict=True):
        assert np.abs(io.read(f).points - pts).max() < tol
        head = summary(f)
        assert head.format == format_of(f) and head.count in (None, len(pts))
        got = np.concatenate([c["x"] for c in iter_records(f, chunk_points=5_000)])
        assert np.abs(got - pts[:, 0]).max() < tol

    # registered: right against the truth
    truth = np.linalg.inv(poses[0]) @ poses[1]
    res = register(files[0], files[1])
    rot, trans = transform_errors(res.T_target_source, truth)
    assert res.status.value == "ok" and rot < 0.05 and trans < 0.02, (res.status, rot, trans)

    # exported: the source scan's points where the truth puts them in the target's frame
    out = tmp_path / "both.las"
    chosen = [
        ExportScan.from_pose(files[0], files[0].name, 0, np.eye(4)),
        ExportScan.from_pose(files[1], files[1].name, 1, res.T_target_source),
    ]
    export(chosen, out)
    cloud = laspy.read(out)
    xyz, index = np.column_stack([cloud.x, cloud.y, cloud.z]), np.asarray(cloud.scan_index)
    moved = scans[1] @ truth[:3, :3].T + truth[:3, 3]
    assert (index == 1).sum() == len(moved)
    assert np.percentile(np.linalg.norm(xyz[index == 1] - moved, axis=1), 99) < 0.03
