"""Scan names of every kind: the files written per scan and per link are portable, bounded and
never shared; names with spaces, long names and names that are not UTF-8 go through every
command; a scan given twice is refused."""

from __future__ import annotations

import csv
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from ndt_cli.cli import chain_app, eval_app, export_app, register_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.io.matrices import read_matrix, read_pose_list
from ndt_cli.io.names import link_file_names, per_scan_file_names, pose_file_names
from ndt_cli.io.outdir import publish

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
GT = read_pose_list(SAMPLE / "poses_T_world_scan.txt")
runner = CliRunner()
PORTABLE = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-/")


def renamed(folder: Path, names: dict[str, str]) -> list[Path]:
    """Copies of sample scans under new names (new name -> sample scan)."""
    folder.mkdir(parents=True, exist_ok=True)
    return [
        Path(shutil.copy(SAMPLE / src, folder / os.fsdecode(new))) for new, src in names.items()
    ]


def reference(path: Path, names: dict[str, str]) -> Path:
    """The sample's reference poses under the new names (quoted where they hold spaces)."""
    lines = [
        f'"{new}" ' + " ".join(f"{v:.17g}" for v in GT[src].ravel()) for new, src in names.items()
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def chain(files: list[Path], out: Path, *args: str):
    return runner.invoke(chain_app, [*map(str, files), "-o", str(out), "-q", "-j", "2", *args])


def test_output_names_are_portable_unique_and_bounded():
    names = [
        "a<1>.laz",
        "A<1>.laz",
        'b"c.las',
        "x&y'.ply",
        "CON.laz",
        "s.e57#0",
        "s_0.laz",
        "L" * 300 + ".laz",
    ]
    files = per_scan_file_names(names, ".laz") + pose_file_names(names)
    links = link_file_names(
        names, [(i, j) for i in range(len(names)) for j in range(len(names)) if i != j]
    )
    for group in (per_scan_file_names(names, ".laz"), pose_file_names(names), links):
        assert len({n.lower() for n in group}) == len(group)  # case-insensitively unique
    for name in files + links:
        assert set(name) <= PORTABLE and len(name.encode()) <= 255, name
        assert Path(name).stem.split(".")[0].lower() not in ("con", "prn", "aux", "nul")


@pytest.mark.slow
def test_links_whose_names_would_run_together_keep_their_own_files(tmp_path):
    names = {
        "a.laz": "scan_00.laz",
        "a_b.laz": "scan_01.laz",
        "b_c.laz": "scan_02.laz",
        "c.laz": "scan_03.laz",
    }
    files = renamed(tmp_path / "s", names)
    out = tmp_path / "out"
    res = chain(files, out)
    assert res.exit_code in (0, 1), res.output
    rows = list(csv.DictReader((out / "pairs.csv").read_text().splitlines()))
    written = [f for f in json.loads((out / "summary.json").read_text())["transform_files"] if f]
    assert len(set(written)) == len(written) == len(list(out.glob("T_*.txt")))
    gt = reference(tmp_path / "gt.txt", names)
    res = runner.invoke(eval_app, [str(out), "--gt", str(gt), "--json"])
    assert res.exit_code == 0, res.output
    evaluated = {(r["target"], r["source"]): r for r in json.loads(res.stdout)["links"]}
    assert len(evaluated) == len(rows)
    checked = 0
    for link in sorted((out / "links").glob("*.json")):  # each link's own transform
        data = json.loads(link.read_text())
        if not isinstance(data, dict) or not (data.get("result") or {}).get("T_target_source"):
            continue
        t, s = data["target_name"], data["source_name"]
        if (t, s) not in evaluated:  # registered while placing the scans, not a link of the network
            continue
        checked += 1
        T_ref = np.linalg.inv(GT[names[t]]) @ GT[names[s]]
        rot, trans = transform_errors(np.array(data["result"]["T_target_source"]), T_ref)
        assert evaluated[(t, s)]["rotation_error_deg"] == pytest.approx(rot, abs=1e-9)
        assert evaluated[(t, s)]["translation_error_m"] == pytest.approx(trans, abs=1e-9)
    assert checked == len(evaluated)


@pytest.mark.slow
def test_scans_of_one_stem_get_a_pose_file_each(tmp_path):
    import laspy

    files = renamed(
        tmp_path / "s",
        {"scan_00.laz": "scan_00.laz", "scan_01.laz": "scan_01.laz", "scan_02.laz": "scan_02.laz"},
    )
    laspy.read(SAMPLE / "scan_03.laz").write(tmp_path / "s" / "scan_02.las")
    truth = {
        "scan_00.laz": "scan_00.laz",
        "scan_01.laz": "scan_01.laz",
        "scan_02.laz": "scan_02.laz",
        "scan_02.las": "scan_03.laz",
    }
    out = tmp_path / "out"
    res = chain([*files, tmp_path / "s" / "scan_02.las"], out)
    assert res.exit_code == 0, res.output
    pose_files = json.loads((out / "summary.json").read_text())["pose_files"]
    assert len(set(pose_files.values())) == 4 == len(list((out / "poses").iterdir()))
    for name, file in pose_files.items():
        T_ref = np.linalg.inv(GT["scan_00.laz"]) @ GT[truth[name]]
        rot, trans = transform_errors(read_matrix(out / file), T_ref)
        assert rot < 0.1 and trans < 0.05, (name, rot, trans)


@pytest.mark.slow
def test_names_with_spaces_are_read_back_by_ndt_eval(tmp_path):
    names = {"Scan 00.laz": "scan_00.laz", "Scan 01.laz": "scan_01.laz"}
    out = tmp_path / "out"
    res = chain(renamed(tmp_path / "s", names), out)
    assert res.exit_code == 0, res.output
    poses = read_pose_list(out / "poses.txt")
    assert set(poses) == set(names)
    res = runner.invoke(
        eval_app, [str(out), "--gt", str(reference(tmp_path / "gt.txt", names)), "--json"]
    )
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["links"][0]["translation_error_m"] < 0.05


@pytest.mark.slow
def test_long_legal_names_never_fail_the_outputs(tmp_path):
    names = {f"{k}_" + "L" * 200 + ".laz": f"scan_0{k}.laz" for k in range(2)}
    out = tmp_path / "out"
    res = chain(renamed(tmp_path / "s", names), out)
    assert res.exit_code == 0, res.output
    assert all(len(p.name.encode()) <= 255 for p in out.rglob("*"))
    assert len(list(out.glob("T_*.txt"))) == 1


@pytest.mark.slow
def test_a_file_name_that_is_not_utf8_goes_through_register_and_export(tmp_path):
    odd = os.fsdecode(b"a_\xff\xfe.laz")
    files = renamed(tmp_path / "s", {odd: "scan_00.laz", "b.laz": "scan_01.laz"})
    out = tmp_path / "out"
    res = runner.invoke(register_app, [*map(str, files), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s"]  # no staging folder left
    res = runner.invoke(export_app, [str(out), "--out", str(tmp_path / "x.las"), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["points_written"] > 300_000


def test_the_same_scan_given_twice_is_refused_before_any_work(tmp_path):
    scan = SAMPLE / "scan_00.laz"
    res = chain(
        [scan, SAMPLE / ".." / "sample_data" / "scan_00.laz", SAMPLE / "scan_01.laz"],
        tmp_path / "o",
    )
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "the same scan as" in lines[0]
    assert not (tmp_path / "o").exists()


def test_a_failure_while_publishing_leaves_no_staging_folder(tmp_path):
    def broken(path: Path) -> None:
        raise RuntimeError("a bug while writing")

    with pytest.raises(RuntimeError):
        publish(tmp_path / "out", {"a.txt": "a", "b.txt": broken})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_bidi_controls_in_a_name_cannot_reverse_the_report(tmp_path):
    evil = "b_\u202eevil.laz"
    files = renamed(tmp_path / "s", {"a.laz": "scan_00.laz", evil: "scan_01.laz"})
    out = tmp_path / "out"
    res = runner.invoke(register_app, [*map(str, files), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    page = (out / "report.html").read_text(encoding="utf-8")
    assert not any(c in page for c in "\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")
    assert "b_\\u202eevil.laz" in page  # shown, escaped
