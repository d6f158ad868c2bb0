"""Real scans from other projects, registered from no guess and compared with their references.

The scans are read from the shared data folder (skipped when it is absent, failing under CI);
each dataset's conventions (units, axes, sensor noise) come from a config file in ``configs/``,
never from special cases in the code.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_data
from typer.testing import CliRunner

import ndt_cli
from ndt_cli import config
from ndt_cli.cli import chain_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_pose_list

CONFIGS = Path(__file__).resolve().parents[1] / "configs"


@pytest.mark.slow
def test_3dtk_scans_in_centimetres_and_a_left_handed_frame_chain_onto_their_reference(tmp_path):
    folder = shared_data("3dtk_example_scans")
    files = [folder / f"scan00{k}.3d" for k in range(3)]
    res = CliRunner().invoke(
        chain_app,
        [
            *map(str, files),
            "--config",
            str(CONFIGS / "3dtk.yaml"),
            "--out",
            str(tmp_path),
            "--quiet",
            "--jobs",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    # the reference maps scan points (cm, 3DTK's left-handed y-up frame) into scan000's frame;
    # S takes such a point into the configured frame (m, right-handed, z up)
    cfg = config.load(CONFIGS / "3dtk.yaml")
    S = np.eye(4)
    S[:3, :3] = cfg.input.scale * config.axes_matrix(cfg.input.axes)
    refs = np.loadtxt(folder / "reference_poses_4x4.txt").reshape(-1, 4, 4)
    poses = read_pose_list(tmp_path / "poses.txt")
    base = np.linalg.inv(poses[files[0].name])  # the world is scan000's frame, levelled
    for k, f in enumerate(files):
        rot, trans = transform_errors(base @ poses[f.name], S @ refs[k] @ np.linalg.inv(S))
        assert rot < 1.0 and trans < 0.03, (f.name, rot, trans)


def test_libpointmatcher_car_pair_matches_its_reference_in_6dof():
    folder = shared_data("libpointmatcher_car_scans")
    with open(folder / "carCloudList.csv", newline="") as fh:
        rows = {r[0].strip(): r[1:] for r in csv.reader(fh)}
    ref = np.array([float(v) for v in rows["car_cloud401.csv"]]).reshape(4, 4)
    # both clouds carry a synthetic tilt of about 10 degrees: levelling must find it
    result = ndt_cli.register(
        folder / "car_cloud400.csv",
        folder / "car_cloud401.csv",
        config.load(CONFIGS / "noisy_sensor.yaml"),
    )
    rot, trans = transform_errors(result.T_target_source, ref)
    assert result.status == "ok", result.warnings
    assert rot < 0.5 and trans < 0.02, (rot, trans)
