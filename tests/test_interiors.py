"""Interiors: a simulated office floor registered as a campaign. No scan may come out ok and
wrong; a link the data cannot decide names its rival; the interior settings are chosen from
what the scans see."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli import io
from ndt_cli.analysis import trust
from ndt_cli.config import Config
from ndt_cli.pipeline.chain import run_chain, scene_of
from ndt_cli.pipeline.verify import NodeStatus
from ndt_cli.sim.indoor import FloorWorld, scan_floor

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def office(tmp_path_factory):
    """A double-loaded corridor of rooms of one size, half the doors closed, scanned every
    5-8 m and in one room: the scans as LAS files and their true poses."""
    world = FloorWorld(
        seed=12, length=30.0, closed=0.5, spacing=(5.0, 8.0), room_scans=1, rays=(900, 120)
    )
    _, scans, poses = scan_floor(world)
    folder = tmp_path_factory.mktemp("office")
    files = [folder / f"scan_{k:02d}.las" for k in range(len(scans))]
    for f, pts in zip(files, scans, strict=True):
        io.write(f, pts)
    return files, poses


def test_the_campaign_takes_the_interior_settings_from_its_first_scan(office):
    files, _ = office
    cfg = scene_of(Config(), files)
    assert cfg.scene.kind == "indoor" and cfg.quality.trust_bridges is False
    assert max(cfg.slices.heights) < 2.7  # below the ceiling


def test_no_scan_of_an_office_floor_is_ok_and_wrong(office, tmp_path):
    """Whatever the floor lets the method find out, nothing it calls ok is wrong, and every
    scan it does not call ok says why."""
    files, truth = office
    result = run_chain(files, Config(), tmp_path, jobs=2)
    scans = trust.scan_truths(result, truth)
    ok = [s for s in scans if s.status is NodeStatus.OK]
    assert all(s.correct for s in ok), [(s.index, s.rot_deg, s.trans_m) for s in ok]
    for scan in result.solution.scans:
        assert scan.status is NodeStatus.OK or scan.reason  # every other one says why
    named = [k for k in result.links if k.result is not None and k.result.rivals]
    assert all("turned" in r.text and "m away" in r.text for k in named for r in k.result.rivals)
    assert np.isfinite([k.result.free_space_around for k in result.links if k.result]).all()
