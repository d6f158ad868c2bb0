"""ndt-analyze: the paper's experiments, checked on a small simulated pair."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from typer.testing import CliRunner

from ndt_cli import io, sim
from ndt_cli.analysis import experiments as analyze
from ndt_cli.cli import analyze_app
from ndt_cli.config import Config
from ndt_cli.io.matrices import format_matrix
from ndt_cli.ndt.prepare import prepare

runner = CliRunner()


@pytest.fixture(scope="module")
def pair():
    _, scans, poses = sim.make_sequence(
        seed=21, n_scans=2, spacing=(13.0, 17.0), scan_kwargs={"n_azimuth": 1000}
    )
    cfg = Config()
    truth = np.linalg.inv(poses[0]) @ poses[1]
    p = analyze.Pair.make(prepare(scans[0], cfg), prepare(scans[1], cfg), cfg, truth)
    return cfg, p, scans, truth


@pytest.mark.slow
def test_rotation_profile_peaks_at_zero_for_every_slice_count(pair):
    cfg, p, _, _ = pair
    rows = analyze.rotation_profile(p, cfg, cell=5.0, step_deg=2.0)
    for k in range(1, len(cfg.slices.heights) + 1):
        mine = [r for r in rows if r["slices"] == k]
        assert len(mine) == 181
        best = max(mine, key=lambda r: r["score"])
        assert abs(best["rotation_deg"]) <= 2.0, (k, best)


def test_translation_profile_peaks_at_zero(pair):
    cfg, p, _, _ = pair
    rows = analyze.translation_profile(p, cfg, 5.0, (-20, 20), (-10, 10), 2.0)
    for k in (1, len(cfg.slices.heights)):
        best = max((r for r in rows if r["slices"] == k), key=lambda r: r["score"])
        assert abs(best["dx_m"]) <= 2.0 and abs(best["dy_m"]) <= 2.0


@pytest.mark.slow
def test_basin_multi_slice_succeeds_at_least_as_often_as_one_slice(pair):
    cfg, p, _, _ = pair
    offsets = analyze.basin_offsets(12.0, 12.0, 20.0, 10.0)  # 45 starts: 0-17 m, 0-20 deg off
    rows = analyze.basin(p, cfg, offsets, jobs=2)
    assert len(rows) == 3 * len(offsets)
    rate = {
        v: np.mean([r["success"] for r in rows if r["variant"] == v])
        for v in analyze.BASIN_VARIANTS
    }
    assert rate["all slices, single start"] >= rate["1 slice, single start"]
    assert rate["all slices, multi-start"] >= rate["all slices, single start"]
    assert rate["all slices, multi-start"] > 0.5
    zero = [r for r in rows if r["start_distance_m"] == 0 and r["start_dyaw_deg"] == 0]
    assert any(r["success"] for r in zero)
    rates = analyze.success_rates(rows, 6.0)
    assert {r["variant"] for r in rates} == set(analyze.BASIN_VARIANTS)


def test_optimizer_traces_cover_each_method_and_end_near_the_truth(pair):
    cfg, p, _, _ = pair
    cells = (5.0, 2.0, 1.0)
    rows = analyze.optimizer_traces(
        p, cfg, (1.0, -1.0, 2.0), dict.fromkeys(["newton", "lm_fixed", "lm"], cells)
    )
    for method in ("newton", "lm_fixed", "lm"):
        mine = [r for r in rows if r["method"] == method]
        assert mine and [r["iteration"] for r in mine] == list(range(1, len(mine) + 1))
        assert all(
            np.isfinite([r["score"], r["tx_m"], r["ty_m"], r["yaw_deg"]]).all() for r in mine
        )
        assert {r["cell_m"] for r in mine} == set(cells)
    ends = {m: [r for r in rows if r["method"] == m][-1] for m in ("newton", "lm_fixed", "lm")}
    assert abs(ends["newton"]["tx_m"] - p.aligned[0]) < 0.05
    assert abs(ends["newton"]["ty_m"] - p.aligned[1]) < 0.05
    from ndt_cli.ndt.kernels import accumulate
    from ndt_cli.ndt.levels import SourceSampler, TargetMaps

    start = p.aligned + np.array([1.0, -1.0, np.radians(2.0)])
    src = SourceSampler(p.source.slices, cfg.source).fine
    start_score = accumulate(TargetMaps(p.target.slices, cfg.grid)(cells[0]), src, start)[0, 0]
    for m in ("lm_fixed", "lm"):  # both raise the score of their start at the first level
        best = max(r["score"] for r in rows if r["method"] == m and r["cell_m"] == cells[0])
        assert best > start_score


@pytest.mark.slow
def test_cli_writes_csv_with_units_and_png(pair, tmp_path):
    _, _, scans, truth = pair
    io.write(tmp_path / "a.laz", scans[0])
    io.write(tmp_path / "b.laz", scans[1])
    (tmp_path / "T.txt").write_text(format_matrix(truth))
    out = tmp_path / "out"
    res = runner.invoke(
        analyze_app,
        [
            "score-profile",
            str(tmp_path / "a.laz"),
            str(tmp_path / "b.laz"),
            "--at",
            str(tmp_path / "T.txt"),
            "--out",
            str(out),
            "--step-deg",
            "10",
        ],
    )
    assert res.exit_code == 0, res.output
    with open(out / "score_rotation.csv") as fh:
        header = next(csv.reader(fh))
    assert header == ["slices", "rotation_deg", "score", "score_per_point"]
    assert (out / "score_rotation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = runner.invoke(analyze_app, ["basin", str(tmp_path / "a.laz"), str(tmp_path / "x.laz")])
    assert bad.exit_code == 2 and "x.laz" in bad.stderr


SAMPLE = __import__("pathlib").Path(__file__).resolve().parents[1] / "sample_data"


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["optimizers", "--start", "nan", "0", "0"], "--start dx"),  # was a segfault
        (["optimizers", "--start", "1e19", "0", "0"], "--start dx"),
        (["optimizers", "--start", "0", "0", "inf"], "--start dyaw"),
        (["score-profile", "--step-deg", "0"], "--step-deg"),  # was a ZeroDivisionError
        (["score-profile", "--step-deg", "nan"], "--step-deg"),
        (["score-profile", "--cell", "-1"], "--cell"),
        (["score-profile", "--cell", "0"], "--cell"),
        (["score-profile", "--translate", "--step", "0"], "--step"),
        (["score-profile", "--translate", "--x-range", "5", "-5"], "--x-range"),
        (["score-profile", "--translate", "--x-range", "nan", "1"], "--x-range"),
        (["score-profile", "--translate", "--x-range", "1e300", "1e300"], "--x-range"),
        (["basin", "--translation-step", "0"], "--translation-step"),
        (["basin", "--yaw-step", "0"], "--yaw-step"),
        (["basin", "--max-translation", "nan"], "--max-translation"),
        (["basin", "--max-translation", "1e300"], "--max-translation"),
    ],
)
def test_numeric_options_are_checked_before_any_work(tmp_path, args, option):
    scans = [str(SAMPLE / "scan_00.laz"), str(SAMPLE / "scan_01.laz")]
    res = runner.invoke(analyze_app, [args[0], *scans, *args[1:], "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and option in lines[0] and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()
