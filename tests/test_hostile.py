"""Hostile sweeps: random configs (every key, non-finite and extreme values, wrong types) and
random files through the command, holding it to its contract only: exit code 0, 1 or 2; an
error is one line without a traceback; a failed run writes nothing; and a run that says ok is
right (ground truth of the simulated street), whatever the config."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from ndt_cli import io, sim
from ndt_cli.cli import register_app
from ndt_cli.config import Config
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_matrix

runner = CliRunner()
DEFAULTS = Config().to_dict()
WEIRD = [math.nan, math.inf, -math.inf, 1e300, -1.0, 0, "five", [1, 2], None, True]


def _values(default: object) -> st.SearchStrategy:
    """Values for a key: near its default, far from it, or of the wrong kind."""
    if isinstance(default, bool) or not isinstance(default, int | float | list):
        return st.sampled_from([default, *WEIRD, "lm", "icp", "none", "x,-y,z", "z,z,z"])
    if isinstance(default, list):
        item = st.one_of(st.floats(-20, 300), st.sampled_from([math.nan, math.inf, 0.0]))
        return st.one_of(st.lists(item, max_size=6), st.sampled_from(WEIRD))
    scaled = st.sampled_from([0.0, 0.01, 0.3, 0.7, 1.5, 3.0, 100.0]).map(
        lambda f: type(default)(default * f) if default else f
    )
    return st.one_of(scaled, st.sampled_from(WEIRD))


def _configs() -> st.SearchStrategy:
    keys = [(s, k) for s, section in DEFAULTS.items() for k in section]
    pick = st.lists(st.sampled_from(keys), min_size=1, max_size=3, unique=True)

    def build(chosen: list[tuple[str, str]]) -> st.SearchStrategy:
        parts = [_values(DEFAULTS[s][k]).map(lambda v, s=s, k=k: (s, k, v)) for s, k in chosen]
        return st.tuples(*parts)

    def nest(triples: tuple) -> dict:
        out: dict = {}
        for s, k, v in triples:
            out.setdefault(s, {})[k] = v
        return out

    return pick.flatmap(build).map(nest)


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hostile")
    _, scans, poses = sim.make_sequence(
        seed=21, n_scans=2, spacing=(13.0, 15.0), scan_kwargs={"n_azimuth": 600}
    )
    files = [folder / "a.laz", folder / "b.laz"]
    for f, pts in zip(files, scans, strict=True):
        io.write(f, pts)
    return files, np.linalg.inv(poses[0]) @ poses[1]


@pytest.mark.slow
@settings(
    max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=_configs())
def test_no_config_ends_in_a_traceback_or_a_confident_wrong_answer(pair, tmp_path, data):
    files, truth = pair
    here = Path(tempfile.mkdtemp(dir=tmp_path))  # hypothesis reuses tmp_path across examples
    cfg = here / "c.yaml"
    cfg.write_text(yaml.safe_dump(data))
    out = here / "out"
    res = runner.invoke(register_app, [*map(str, files), "-c", str(cfg), "-o", str(out), "-q"])
    assert res.exit_code in (0, 1, 2), (data, res.output)
    assert "Traceback" not in res.output and isinstance(res.exception, SystemExit | type(None))
    if res.exit_code == 2:
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("ndt-register: error:"), (data, lines)
        assert not out.exists()  # nothing written
        return
    T = read_matrix(out / "T_target_source.txt")
    if res.exit_code == 0:  # ok means right
        rot, trans = transform_errors(T, truth)
        assert rot < 0.3 and trans < 0.15, (data, rot, trans)


SUFFIXES = [".ply", ".las", ".laz", ".pcd", ".xyz", ".csv", ".e57", ".3d"]


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.binary(max_size=3000), suffix=st.sampled_from(SUFFIXES))
def test_random_files_are_one_line_and_write_nothing(pair, tmp_path, data, suffix):
    files, _ = pair
    here = Path(tempfile.mkdtemp(dir=tmp_path))
    bad = here / f"fuzz{suffix}"
    bad.write_bytes(data)
    out = here / "out"
    res = runner.invoke(register_app, [str(files[0]), str(bad), "-o", str(out), "-q"])
    assert res.exit_code in (1, 2), res.output  # a few random bytes may parse as points
    if res.exit_code == 2:
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and bad.name in lines[0] and "Traceback" not in res.output
        assert not out.exists()
