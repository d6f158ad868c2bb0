"""The ndt-register command: outputs, JSON, exit codes, one-line errors, nothing half-written."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from conftest import unmatched_pair
from typer.testing import CliRunner

from ndt_cli import io, sim
from ndt_cli.cli import register_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_matrix

runner = CliRunner()


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("scans")
    _, scans, poses = sim.make_sequence(seed=11, n_scans=2)
    io.write(d / "a.laz", scans[0])
    io.write(d / "b.ply", scans[1])
    return d / "a.laz", d / "b.ply", np.linalg.inv(poses[0]) @ poses[1]


def test_register_writes_all_outputs(pair, tmp_path):
    a, b, ref = pair
    out = tmp_path / "out"
    res = runner.invoke(register_app, [str(a), str(b), "--out", str(out)])
    assert res.exit_code == 0, res.output
    T = read_matrix(out / "T_target_source.txt")
    rot, trans = transform_errors(T, ref)
    assert rot < 0.3 and trans < 0.15
    data = json.loads((out / "result.json").read_text())
    assert data["status"] == "ok" and np.allclose(data["T_target_source"], T, atol=1e-12)
    lines = (out / "report.csv").read_text().splitlines()
    assert lines[0].startswith("target,source,tx,ty,tz,yaw_deg") and len(lines) == 2
    row = dict(zip(lines[0].split(","), lines[1].split(","), strict=True))
    assert 0 < float(row["icp_rms"]) < 0.03 and int(row["icp_inliers"]) > 1000
    assert 0.2 < float(row["overlap_3d"]) <= 1 and row["degenerate"] == "" and row["status"] == "ok"
    ndt_eig = [float(v) for v in row["hessian_eigenvalues"].split(";")]
    icp_eig = [float(v) for v in row["icp_hessian_eigenvalues"].split(";")]
    assert len(ndt_eig) == 3 and len(icp_eig) == 6 and min(ndt_eig) > 0 and min(icp_eig) > 0
    icp_h = np.array(data["icp_hessian"])
    np.testing.assert_allclose(icp_eig, np.linalg.eigvalsh(icp_h), rtol=1e-5)
    used = yaml.safe_load((out / "config_used.yaml").read_text())
    assert used["grid"]["cell_sizes"] == [20.0, 10.0, 5.0, 2.0, 1.0]
    assert not list(out.glob("*.tmp*"))


@pytest.mark.slow
def test_json_on_stdout_and_config_and_init(pair, tmp_path):
    a, b, ref = pair
    cfg = tmp_path / "c.yaml"
    cfg.write_text("optimizer:\n  method: lm\n")
    init = tmp_path / "init.txt"
    init.write_text("\n".join(" ".join(f"{v:.10f}" for v in row) for row in ref))
    res = runner.invoke(
        register_app,
        [str(a), str(b), "-c", str(cfg), "--init", str(init), "--json", "-o", str(tmp_path / "o")],
    )
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["converged"] is True
    assert [lv["cell_size"] for lv in data["levels"]] == [2.0, 1.0]  # no search, from 2 m cells
    assert "method: lm" in (tmp_path / "o" / "config_used.yaml").read_text()


@pytest.mark.slow
def test_init_sigma_sets_where_the_guess_starts_and_a_bad_one_is_one_line(pair, tmp_path):
    a, b, ref = pair
    init = tmp_path / "init.txt"
    init.write_text("\n".join(" ".join(f"{v:.10f}" for v in row) for row in ref))
    args = [str(a), str(b), "--init", str(init), "--json"]
    wide = runner.invoke(register_app, [*args, "--init-sigma", "4,1", "-o", str(tmp_path / "w")])
    assert wide.exit_code == 0, wide.output
    levels = json.loads(wide.stdout)["levels"]
    # 4 m: the first cell of at least 8 m; 1 degree: the guess's heading alone; then a local
    # search at 2 m cells within the 4 m, and every pose it found refined from 2 m on
    assert [lv["cell_size"] for lv in levels] == [10.0, 5.0, 2.0, 2.0, 1.0]
    for bad in ("1", "1,x", "0,5", "1,200", "nan,5"):
        res = runner.invoke(register_app, [*args, "--init-sigma", bad, "-o", str(tmp_path / "b")])
        assert res.exit_code == 2 and "--init-sigma" in res.output, (bad, res.output)
        assert "Traceback" not in res.output and not (tmp_path / "b").exists()


def _write(path, text):
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda d: d / "missing.ply", "not found"),
        (lambda d: _write(d / "scan.abc", "1 2 3\n"), "scan.abc"),
        (lambda d: _write(d / "empty.xyz", ""), "empty.xyz"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(pair, tmp_path, make, needle):
    a, _, _ = pair
    bad = make(tmp_path)
    out = tmp_path / "out"
    res = runner.invoke(register_app, [str(a), str(bad), "--out", str(out), "--quiet"])
    assert res.exit_code == 2
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ndt-register: error:") and needle in err[0]
    assert "Traceback" not in res.output
    assert not out.exists()


def test_bad_config_names_the_key(pair, tmp_path):
    a, b, _ = pair
    cfg = tmp_path / "c.yaml"
    cfg.write_text("grid:\n  cell_size: [4, 2]\n")
    res = runner.invoke(register_app, [str(a), str(b), "-c", str(cfg), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert "grid.cell_size" in res.stderr and "c.yaml" in res.stderr


def test_unwritable_output_is_exit_2(pair, tmp_path):
    a, b, _ = pair
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = runner.invoke(register_app, [str(a), str(b), "-o", str(blocker / "sub")])
    assert res.exit_code == 2 and "file" in res.stderr


def test_failed_registration_is_exit_1(tmp_path):
    a, b = unmatched_pair(tmp_path)
    res = runner.invoke(register_app, [str(a), str(b), "-o", str(tmp_path / "o")])
    assert res.exit_code == 1 and "no_overlap" in res.stderr
    assert json.loads((tmp_path / "o" / "result.json").read_text())["status"] == "no_overlap"


def test_help_names_target_and_source():
    res = runner.invoke(register_app, ["--help"])
    assert res.exit_code == 0
    assert "TARGET stays fixed" in res.output and "Exit codes" in res.output
