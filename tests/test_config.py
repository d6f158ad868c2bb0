"""Config loading: defaults, YAML, unknown keys and wrong types fail loudly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from ndt_cli import config
from ndt_cli.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_default_yaml_equals_built_in_defaults():
    assert config.load(ROOT / "configs" / "default.yaml") == config.Config()


def test_every_shipped_config_loads():
    files = sorted((ROOT / "configs").glob("*.yaml"))
    assert len(files) >= 2
    for f in files:
        assert isinstance(config.load(f), config.Config)


def test_dump_round_trips(tmp_path):
    cfg = config.Config().replace(grid={"cell_sizes": [8, 4, 2]}, optimizer={"method": "lm"})
    p = tmp_path / "c.yaml"
    p.write_text(config.dump(cfg))
    back = config.load(p)
    assert back == cfg
    assert back.grid.cell_sizes == (8.0, 4.0, 2.0)


def test_partial_config_keeps_other_defaults(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("slices:\n  heights: [1, 3]\n")
    cfg = config.load(p)
    assert cfg.slices.heights == (1.0, 3.0)
    assert cfg.slices.thickness == config.SlicesConfig().thickness


@pytest.mark.parametrize(
    ("data", "needle"),
    [
        ({"grid": {"cel_sizes": [1]}}, "grid.cel_sizes"),
        ({"gridd": {}}, "gridd"),
        ({"grid": {"cell_sizes": "big"}}, "grid.cell_sizes"),
        ({"grid": {"cell_sizes": [10, 20]}}, "decreasing"),
        ({"grid": {"cell_sizes": [10, -1]}}, "grid.cell_sizes[1]"),
        ({"grid": {"overlap": "yes"}}, "grid.overlap"),
        ({"grid": {"min_points": 2.5}}, "grid.min_points"),
        ({"slices": {"thickness": 0}}, "slices.thickness"),
        ({"slices": {"heights": []}}, "slices.heights"),
        ({"optimizer": {"method": "gauss"}}, "optimizer.method"),
        ({"search": {"yaw_starts": 0}}, "search.yaw_starts"),
        ({"grid": 3}, "grid"),
        ({"input": {"axes": "x,y"}}, "input.axes"),
        ({"input": {"axes": "x,-x,z"}}, "input.axes"),
        ({"input": {"axes": 3}}, "input.axes"),
        ({"input": {"scale": 0}}, "input.scale"),
        ({"input": {"min_range": 5, "max_range": 2}}, "min_range"),
    ],
)
def test_bad_values_name_the_key(tmp_path, data, needle):
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as err:
        config.load(p)
    msg = str(err.value)
    assert needle in msg and "bad.yaml" in msg and "\n" not in msg


def test_missing_and_invalid_yaml(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        config.load(tmp_path / "nope.yaml")
    p = tmp_path / "broken.yaml"
    p.write_text("grid: [1, 2\n")
    with pytest.raises(ConfigError, match="invalid YAML"):
        config.load(p)
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="mapping"):
        config.load(p)


def test_axes_matrix_is_a_signed_permutation():
    A = config.axes_matrix("z,-x,y")
    p = A @ [1.0, 2.0, 3.0]  # x sideways, y up, z forward -> forward, left, up
    assert p.tolist() == [3.0, -1.0, 2.0]
    assert round(float(np.linalg.det(A))) == -1  # a left-handed frame becomes right-handed
    assert np.array_equal(config.axes_matrix(" X, y ,+z"), np.eye(3))
