"""When a scan was taken (``io.acquired``) and the walk a campaign follows (``Walk``): the scans'
time order when every scan has a time, else the order they were given in."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pye57
import pytest
from conftest import shared_data

from ndt_cli import io
from ndt_cli.io import e57
from ndt_cli.pipeline.walk import Walk

POINTS = np.random.default_rng(4).uniform(-20.0, 20.0, (500, 3))


def test_a_las_files_time_is_its_first_point_record_s(tmp_path):
    times = 300_000.25 + np.arange(len(POINTS)) * 0.01
    for suffix in (".las", ".laz"):
        f = tmp_path / f"timed{suffix}"
        io.write(f, POINTS, gps_time=times)
        assert laspy.read(f).header.point_format.id == 1
        assert io.acquired(f) == pytest.approx(300_000.25, abs=1e-9)


def test_files_without_times_have_none(tmp_path):
    io.write(plain := tmp_path / "plain.las", POINTS)  # point format 0: no GPS time
    io.write(zero := tmp_path / "zero.las", POINTS, gps_time=np.zeros(len(POINTS)))
    io.write(ply := tmp_path / "scan.ply", POINTS)
    (junk := tmp_path / "junk.las").write_bytes(b"not a LAS file at all")
    for f in (plain, zero, ply, junk, tmp_path / "missing.las"):
        assert io.acquired(f) is None, f


def test_times_are_written_to_las_only_one_per_point(tmp_path):
    with pytest.raises(ValueError):
        io.write(tmp_path / "scan.ply", POINTS, gps_time=np.ones(len(POINTS)))
    with pytest.raises(ValueError):
        io.write(tmp_path / "scan.las", POINTS, gps_time=np.ones(3))


class _Timed:
    """A scan header as pye57 writes it, with an acquisition start."""

    def __init__(self, base: object, start: float) -> None:
        self.base, self.acquisitionStart_dateTimeValue = base, start

    def __getattr__(self, name: str) -> object:
        return getattr(self.base, name)


def test_an_e57_scans_time_is_its_acquisition_start(tmp_path):
    e57.write(plain := tmp_path / "plain.e57", [POINTS, POINTS + 1.0], [None, None])
    assert io.acquired(plain) is None  # pye57 writes a start of 0: no time
    source = pye57.E57(str(plain))
    out = pye57.E57(str(timed := tmp_path / "timed.e57"), mode="w")
    for k, start in enumerate((5_000.0, 4_000.0)):
        data = {f"cartesian{a}": POINTS[:, i].copy() for i, a in enumerate("XYZ")}
        out.write_scan_raw(data, scan_header=_Timed(source.get_header(k), start))
    out.close()
    assert io.acquired(Path(f"{timed}#0")) == 5_000.0
    assert io.acquired(Path(f"{timed}#1")) == 4_000.0


def test_real_files_without_times_have_none():
    """The real RIEGL scan is point format 0; the sample E57 files keep no acquisition start."""
    assert io.acquired(shared_data("riegl_vz400i_forest_scan") / "TLS_scan.laz") is None
    pdal = shared_data("e57_samples") / "pdal"
    assert io.acquired(pdal / "A4.e57") is None
    assert io.acquired(Path(f"{pdal / 'A_B.e57'}#1")) is None


def test_the_walk_is_the_time_order_when_every_scan_has_a_time():
    walk = Walk()
    walk.add([30.0, 10.0, 20.0])
    assert walk.timed and walk.reordered
    assert walk.order == [1, 2, 0]
    assert walk.beside(2, (-2, -1, 1, 2)) == [1, 0]
    assert walk.beside(1, (-1, 1, 2)) == [2, 0]
    assert walk.sort([0, 1, 2]) == [1, 2, 0]
    walk.add([15.0])  # a scan copied late, taken second
    assert walk.order == [1, 3, 2, 0]
    walk.add([None])  # one scan without a time: the order given
    assert not walk.timed and not walk.reordered
    assert walk.order == [0, 1, 2, 3, 4]
    assert walk.beside(0, (-1, 1, 2)) == [1, 2]


def test_equal_times_keep_the_order_given():
    walk = Walk()
    walk.add([7.0, 7.0, 7.0])
    assert walk.order == [0, 1, 2] and not walk.reordered
