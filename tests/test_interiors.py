"""Interiors: a simulated office floor registered as a campaign. No scan may come out ok and
wrong; a link the data cannot decide names its rival; the interior settings are chosen from
what the scans see."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli import io
from ndt_cli.analysis import trust
from ndt_cli.config import Config
from ndt_cli.config.scenes import for_scene
from ndt_cli.core.transforms import transform_errors
from ndt_cli.ndt.quality import Sights, in_bin_refutes
from ndt_cli.ndt.register import register
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.chain import run_chain, scene_of
from ndt_cli.pipeline.link_use import determined
from ndt_cli.pipeline.result import Dropped
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
    return _written(world, tmp_path_factory.mktemp("office"))


def _written(world: FloorWorld, folder):
    """The floor's scans written as LAS files in ``folder``, and their true poses."""
    _, scans, poses = scan_floor(world)
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
    left_out = [t.link for t in result.tried if t.why is Dropped.NOT_PLANNED]
    assert not [k for k in left_out if determined(k)]  # a cycle may confirm them: all kept


@pytest.fixture(scope="module")
def open_floor(tmp_path_factory):
    """The sweep's open-plan floor of seed 7 (a hall of desk islands beside a corridor 2 m
    wide, a ceiling at 2.7 m): the scans as LAS files and their true poses."""
    world = FloorWorld(
        seed=7, layout="open", corridor_width=2.0, ceiling=2.7, closed=0.1, furniture=0.3
    )
    return _written(world, tmp_path_factory.mktemp("open_floor"))


@pytest.mark.parametrize(("target", "source"), [(10, 11), (4, 8)])
def test_a_right_pose_indoors_is_judged_by_the_free_space_around_each_direction(
    open_floor, target, source
):
    """Two scans of the hall 9-11 m apart: the true pose puts over 10 % of the points in front
    of what the other scanner saw in their direction's bin alone (the ceiling and desk tops
    seen at grazing angles) and none in front of all it saw around them. Indoors the second
    share judges the pose: the link is right and ok, not refuted."""
    files, truth = open_floor
    r = register(files[target], files[source])
    T_true = np.linalg.inv(truth[target]) @ truth[source]
    rot_deg, trans_m = transform_errors(r.T_target_source, T_true)
    assert rot_deg <= trust.CORRECT[0] and trans_m <= trust.CORRECT[1], (rot_deg, trans_m)
    assert r.free_space > Config().quality.max_free_space  # the bin alone would refute it
    assert r.free_space_around < 0.001
    assert r.status is Status.OK and not r.refuted, r.warnings


def test_on_a_street_the_share_in_the_bin_alone_still_refutes():
    """The share around each direction forgives a wrong street pose too much (a scan of
    another street: 2.6 % around, 20 % in the bin alone): with the street's bound on it the
    share in the bin alone still counts; with the interior one (0.5 %) the share around
    refutes such a pose by itself, and the bin alone is not asked."""
    street, indoor = Config().quality, for_scene(Config(), "indoor").quality
    sights = Sights(final=0.2, around=0.026)
    assert in_bin_refutes(sights, street)
    assert not in_bin_refutes(sights, indoor)
    assert not in_bin_refutes(Sights(final=0.05, around=0.0), street)
