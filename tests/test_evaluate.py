"""ndt-eval: link errors, success rates and drift against reference poses."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from ndt_cli.analysis.accuracy import compare_with_reference
from ndt_cli.cli import eval_app
from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.io.matrices import format_matrix

runner = CliRunner()


def _chain_dir(tmp_path, poses, errors):
    """A fake ndt-chain folder whose links carry the given (dyaw rad, dx m) errors."""
    names = [f"s{k}.laz" for k in range(len(poses))]
    rows = ["link,target,source,status"]
    est = [poses[0]]
    for k in range(1, len(poses)):
        T = (
            np.linalg.inv(poses[k - 1])
            @ poses[k]
            @ pose2d_matrix(errors[k - 1][1], 0, errors[k - 1][0])
        )
        (tmp_path / f"T_s{k - 1}_s{k}.txt").write_text(format_matrix(T))
        rows.append(f"{k - 1},{names[k - 1]},{names[k]},ok")
        est.append(est[-1] @ T)
    (tmp_path / "pairs.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "poses.txt").write_text(
        "\n".join(
            f"{n} " + " ".join(f"{v:.17g}" for v in T.ravel())
            for n, T in zip(names, est, strict=True)
        )
    )
    gt = tmp_path / "gt.txt"
    gt.write_text(
        "\n".join(
            f"{n} " + " ".join(f"{v:.17g}" for v in T.ravel())
            for n, T in zip(names, poses, strict=True)
        )
    )
    return gt


def test_errors_success_rates_and_drift(tmp_path):
    poses = [pose2d_matrix(20.0 * k, 1.0, 0.3 * k) for k in range(4)]
    errors = [(np.radians(0.05), 0.01), (np.radians(1.0), 0.05), (0.0, 0.5)]
    gt = _chain_dir(tmp_path, poses, errors)
    ev = compare_with_reference(tmp_path, gt)
    rot = [r["rotation_error_deg"] for r in ev.links]
    trans = [r["translation_error_m"] for r in ev.links]
    np.testing.assert_allclose(rot, [0.05, 1.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(trans, [0.01, 0.05, 0.5], atol=1e-9)
    assert [s["success_rate"] for s in ev.success] == pytest.approx([2 / 3, 1 / 3])
    assert ev.drift["to"] == "s3.laz" and ev.drift["rotation_error_deg"] == pytest.approx(1.05)


def _tree(folder):
    return {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_cli_writes_eval_files_to_out_and_leaves_the_result_folder_alone(tmp_path):
    poses = [pose2d_matrix(15.0 * k, 0.0, 0.0) for k in range(3)]
    gt = _chain_dir(tmp_path, poses, [(0.0, 0.0), (0.0, 0.03)])
    before = _tree(tmp_path)
    out = tmp_path.parent / f"{tmp_path.name}_eval"
    res = runner.invoke(eval_app, [str(tmp_path), "--gt", str(gt), "--json", "--out", str(out)])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert len(data["links"]) == 2 and data["success"][0]["success_rate"] == 1.0
    assert (out / "eval.csv").read_text().startswith("target,source,rotation_error_deg")
    assert json.loads((out / "eval.json").read_text()) == data
    assert _tree(tmp_path) == before  # the result folder is only read
    quiet = runner.invoke(eval_app, [str(tmp_path), "--gt", str(gt), "--quiet"])
    assert quiet.exit_code == 0 and quiet.stdout == "" and quiet.stderr == ""
    assert _tree(tmp_path) == before
    bad = runner.invoke(eval_app, [str(tmp_path / "nope"), "--gt", str(gt)])
    assert bad.exit_code == 2 and "nope" in bad.stderr
