"""Whether a scan was taken indoors (a ceiling over it), and the settings that follow."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_data

from ndt_cli.config import Config
from ndt_cli.config.scenes import INDOOR, for_scene
from ndt_cli.ndt.ceiling import ceiling_view
from ndt_cli.ndt.prepare import look, settle_scene
from ndt_cli.sim.indoor import FloorWorld, scan_floor
from ndt_cli.sim.worlds import StreetWorld, scan_street


def test_a_simulated_office_sees_a_ceiling_and_a_street_does_not():
    _, rooms, _ = scan_floor(FloorWorld(seed=1, rays=(600, 80)))
    _, street, _ = scan_street(StreetWorld(seed=1, n_scans=2, rays=(600, 80), trees=True))
    for pts in rooms[:3]:
        view = ceiling_view(pts, np.eye(3))
        assert view.indoors and 1.2 < view.height < 1.6 and view.sectors == 12
    for pts in street:
        view = ceiling_view(pts, np.eye(3))  # sky: few points look up, if any
        assert view is None or not view.indoors


def test_a_canopy_or_a_narrow_field_of_view_is_no_ceiling():
    rng = np.random.default_rng(2)
    d = rng.normal(size=(20_000, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1)[:, None]
    crowns = d * rng.uniform(3.0, 25.0, (len(d), 1))  # leaves at every height
    assert not ceiling_view(crowns, np.eye(3)).indoors
    lidar = d[d[:, 2] < 0.2] * 10.0  # +-12 degrees: nothing looks up
    assert ceiling_view(lidar, np.eye(3)) is None


def test_the_ceiling_is_found_along_the_vertical_of_a_tilted_scan():
    _, rooms, _ = scan_floor(FloorWorld(seed=1, rays=(600, 80)))
    tilt = np.radians(20.0)
    R = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    tilted = rooms[0] @ R.T  # the scan as a scanner tilted by 20 degrees records it
    assert ceiling_view(tilted, R.T).indoors  # levelled by its vertical, it does


def test_interior_settings_replace_only_the_keys_left_at_their_defaults():
    mine = Config().replace(slices={"heights": [0.7, 1.4]}, search={"bnb_window": 12.0})
    indoor = for_scene(mine, "indoor")
    assert indoor.scene.kind == "indoor"
    assert indoor.slices.heights == (0.7, 1.4) and indoor.search.bnb_window == 12.0
    assert indoor.grid.cell_sizes == tuple(INDOOR["grid.cell_sizes"])
    assert indoor.quality.trust_bridges is False
    assert for_scene(mine, "street").to_dict() == mine.replace(scene={"kind": "street"}).to_dict()


@pytest.mark.parametrize(("kind", "expect"), [("street", "street"), ("indoor", "indoor")])
def test_a_configured_scene_is_kept_whatever_the_scan_sees(kind, expect):
    cfg, why = settle_scene(Config().replace(scene={"kind": kind}), None)
    assert cfg.scene.kind == expect and "configured" in why


def test_real_scans_a_room_indoors_and_a_forest_outdoors():
    room = shared_data("pcl_ndt_room_scans")
    forest = shared_data("riegl_vz400i_forest_scan")
    cfg = Config()
    view = look(room / "room_scan1.pcd", cfg)
    assert view.indoors, view.describe()
    assert settle_scene(cfg, view)[0].scene.kind == "indoor"
    outdoors = look(forest / "TLS_scan.laz", cfg)
    assert not outdoors.indoors, outdoors.describe()
    assert settle_scene(cfg, outdoors)[0].scene.kind == "street"
