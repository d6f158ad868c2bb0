"""Hostile sweeps: random configs (every key, non-finite and extreme values, wrong types) and
random files through the command, holding it to its contract only: exit code 0, 1 or 2; an
error is one line without a traceback; a failed run writes nothing; and a run that says ok is
right (ground truth of the simulated street), whatever the config."""

from __future__ import annotations

import json
import math
import shutil
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


# --- damaged result folders through ndt-export and ndt-eval ----------------------------------

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data"
GT = SAMPLE / "poses_T_world_scan.txt"
OPS = ["delete", "truncate", "edit", "swap lines", "another scan", "append"]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A chain result of three sample scans and a pair result of two (copies in ``scans/``),
    each scan's usable points in the world of ground truth, and ndt-eval's verdict on them."""
    from ndt_cli.cli import chain_app, eval_app
    from ndt_cli.io.matrices import read_pose_list

    root = tmp_path_factory.mktemp("results")
    (root / "scans").mkdir()
    names = ["scan_00.laz", "scan_01.laz", "scan_02.laz"]
    files = [root / "scans" / n for n in names]
    for f in files:
        f.write_bytes((SAMPLE / f.name).read_bytes())
    chain = runner.invoke(chain_app, [*map(str, files), "-o", str(root / "chain"), "-q", "-j", "2"])
    pair = runner.invoke(register_app, [*map(str, files[:2]), "-o", str(root / "pair"), "-q"])
    assert chain.exit_code == 0 and pair.exit_code == 0, chain.output + pair.output
    gt = read_pose_list(GT)
    world = []
    for f in files:
        pts = io.read(f).points
        T = np.linalg.inv(gt[names[0]]) @ gt[f.name]
        world.append(pts @ T[:3, :3].T + T[:3, 3])
    evals = {}
    for kind in ("chain", "pair"):
        res = runner.invoke(eval_app, [str(root / kind), "--gt", str(GT), "--json"])
        assert res.exit_code == 0, res.output
        evals[kind] = json.loads(res.stdout)
    return root, files, world, evals


def _mutate(path: Path, op: str, where: float, data: bytes, other: Path) -> None:
    """Damage one file as a careless user, a full disk or an editor would."""
    if op == "delete":
        path.unlink()
        return
    raw = path.read_bytes()
    at = int(where * len(raw))
    if op == "truncate":
        raw = raw[:at]
    elif op == "edit":
        raw = raw[:at] + data + raw[at + len(data) :]
    elif op == "swap lines":
        lines = raw.split(b"\n")
        i, j = int(where * (len(lines) - 1)), len(lines) - 1 - int(where * (len(lines) - 1))
        lines[i], lines[j] = lines[j], lines[i]
        raw = b"\n".join(lines)
    elif op == "another scan":
        raw = other.read_bytes()
    else:
        raw += data
    path.write_bytes(raw)


def _cloud_is_right(ply: Path, world: list[np.ndarray], scans: list[str]) -> None:
    """Every exported scan holds its scan's points where ground truth puts them."""
    import plyfile

    v = plyfile.PlyData.read(str(ply))["vertex"].data
    xyz = np.column_stack([v["x"], v["y"], v["z"]])
    for k in {int(s) for s in v["scan_index"]}:
        mine = xyz[v["scan_index"] == k]
        assert len(mine) == len(world[k]), (scans, k)
        assert np.linalg.norm(mine.mean(axis=0) - world[k].mean(axis=0)) < 0.05, (scans, k)


def _one_line_or_ok(res, prog: str) -> None:
    assert res.exit_code in (0, 1, 2), res.output
    assert "Traceback" not in res.output and isinstance(res.exception, SystemExit | type(None))
    if res.exit_code:
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"{prog}: error:"), lines


@pytest.mark.slow
@settings(max_examples=30, deadline=None, suppress_health_check=list(HealthCheck))
@given(
    kind=st.sampled_from(["chain", "pair"]),
    pick=st.floats(0, 1, exclude_max=True),
    op=st.sampled_from(OPS),
    where=st.floats(0, 1),
    data=st.binary(min_size=1, max_size=12),
)
def test_a_damaged_result_is_exported_right_or_refused_in_one_line(
    results, tmp_path, kind, pick, op, where, data
):
    from ndt_cli.cli import eval_app, export_app

    root, scans, world, evals = results
    here = Path(tempfile.mkdtemp(dir=tmp_path))
    folder = here / kind
    shutil.copytree(root / kind, folder)
    targets = sorted(p for p in folder.rglob("*") if p.is_file()) + scans
    target = targets[int(pick * len(targets))]
    kept = {f: f.read_bytes() for f in scans}
    try:
        _mutate(
            target,
            op,
            where,
            data,
            scans[(scans.index(target) + 1) % 3] if target in scans else scans[0],
        )
        out = here / "cloud.ply"
        res = runner.invoke(export_app, [str(folder), "--out", str(out), "-q", "--json"])
        _one_line_or_ok(res, "ndt-export")
        if res.exit_code == 0:  # never a wrong cloud with exit 0
            _cloud_is_right(out, world, json.loads(res.stdout)["scans"])
        else:
            assert not out.exists()
        res = runner.invoke(eval_app, [str(folder), "--gt", str(GT), "--json"])
        _one_line_or_ok(res, "ndt-eval")
        if res.exit_code == 0:  # never another verdict than the result's own
            assert json.loads(res.stdout) == evals[kind], (target, op)
    finally:
        for f, raw in kept.items():
            f.write_bytes(raw)


def _with_stray_point(src: Path, dst: Path, where: np.ndarray | None) -> None:
    """``src`` (LAS/LAZ) with one more point: at ``where`` (m, scanner frame), or, with None, a
    record at the int32 limit of the file's integer coordinates (a "no return" some scanners
    write)."""
    import laspy

    las = laspy.read(src)
    extra = laspy.ScaleAwarePointRecord.zeros(1, header=las.header)
    if where is None:
        extra.X = extra.Y = extra.Z = np.array([2**31 - 1], dtype=np.int32)
    else:
        extra.x, extra.y, extra.z = where
    las.points = laspy.ScaleAwarePointRecord(
        np.concatenate([las.points.array, extra.array]),
        las.header.point_format,
        las.header.scales,
        las.header.offsets,
    )
    las.header.scales = las.header.scales  # bounds are updated on write
    las.write(dst)


@pytest.mark.parametrize(
    "where",
    [(250_000.0, 3_000.0, 10.0), (20_000.0, -500.0, 2.0), (0.0, 1e6, -1e6), None, 1e12],
    ids=["250km", "20km", "1000km", "int32-max-record", "1e12m-xyz"],
)
@pytest.mark.slow
def test_one_stray_point_far_away_neither_hangs_nor_fails_a_good_pair(pair, tmp_path, where):
    """D15, D22: one point far from the scanner (a glitch, a "no return" record) is left out:
    the pair registers as without it, in bounded time, without a traceback."""
    import subprocess
    import sys

    files, truth = pair
    if where == 1e12:  # beyond what LAS holds: a text file
        stray = tmp_path / "b_stray.xyz"
        io.write(stray, np.vstack([io.read(files[1]).points, [1e12, 0.0, 0.0]]))
    else:
        stray = tmp_path / "b_stray.laz"
        _with_stray_point(files[1], stray, None if where is None else np.array(where))
    assert np.abs(io.read(stray).points).max() > 1e4  # the stray point is in the file
    out = tmp_path / "out"
    code = "from ndt_cli.cli import register_app; register_app()"
    res = subprocess.run(
        [sys.executable, "-c", code, str(files[0]), str(stray), "--out", str(out), "-q"],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    rot, trans = transform_errors(read_matrix(out / "T_target_source.txt"), truth)
    assert rot < 0.1 and trans < 0.05, (rot, trans)
