"""A result is bound to its inputs: ndt-export and ndt-eval refuse, in one line with exit 2, a
result folder that is not as its run wrote it, a scan file that is not the one registered, and
a reference that is not a set of rigid poses; they never give a wrong answer with exit 0."""

from __future__ import annotations

import csv
import io
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import laspy
import numpy as np
import pytest
from conftest import unmatched_pair
from typer.testing import CliRunner

from ndt_cli.cli import chain_app, eval_app, export_app, register_app
from ndt_cli.io.matrices import read_pose_list

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
GT = SAMPLE / "poses_T_world_scan.txt"
MANIFEST = ".ndt-cli-outputs"
runner = CliRunner()


def one_error_line(res, prog: str) -> str:
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error:"), res.output
    assert "Traceback" not in res.output and isinstance(res.exception, SystemExit)
    return lines[0]


@pytest.fixture(scope="module")
def chain_result(tmp_path_factory) -> Path:
    """An ndt-chain result of copies of the five sample scans (in ``scans/`` beside it)."""
    root = tmp_path_factory.mktemp("chain")
    (root / "scans").mkdir()
    files = [Path(shutil.copy(f, root / "scans")) for f in sorted(SAMPLE.glob("scan_*.laz"))]
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(root / "res"), "-q", "-j", "2"])
    assert res.exit_code == 0, res.output
    return root / "res"


@pytest.fixture(scope="module")
def pair_result(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("pair")
    res = runner.invoke(
        register_app,
        [str(SAMPLE / "scan_00.laz"), str(SAMPLE / "scan_01.laz"), "-o", str(root / "res"), "-q"],
    )
    assert res.exit_code == 0, res.output
    return root / "res"


def copy_of(result: Path, tmp_path: Path, manifest: bool = True) -> Path:
    out = Path(shutil.copytree(result, tmp_path / "res"))
    if not manifest:
        (out / MANIFEST).unlink()
    return out


def export(result: Path, out: Path, *args: str):
    return runner.invoke(export_app, [str(result), "--out", str(out), "-q", *args])


def refused(res, out: Path, needle: str = "") -> None:
    """Exit 2, one line (holding ``needle``), and no output file."""
    assert res.exit_code == 2, res.output
    assert needle in one_error_line(res, "ndt-export")
    assert not out.exists()


# --- D1: a scan file replaced after the registration -------------------------------------------


@pytest.mark.slow
def test_a_scan_file_swapped_after_registration_is_refused(chain_result, tmp_path):
    scans = chain_result.parent / "scans"
    a, b = scans / "scan_01.laz", scans / "scan_02.laz"
    keep = tmp_path / "keep.laz"
    shutil.move(a, keep)
    shutil.move(b, a)
    shutil.move(keep, b)
    try:
        out = tmp_path / "street.laz"
        refused(export(chain_result, out), out, "scan_01.laz: not the file that was registered")
    finally:
        shutil.move(a, keep)
        shutil.move(b, a)
        shutil.move(keep, b)


# --- D3, D31: a result folder that is not as its run wrote it ----------------------------------


def _csv(path: Path, edit: Callable[[list[list[str]]], None]) -> None:
    rows = list(csv.reader(path.read_text(encoding="utf-8").splitlines()))
    edit(rows)
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    path.write_text(buf.getvalue(), encoding="utf-8")


def _swap_rows(rows: list[list[str]]) -> None:
    rows[2], rows[3] = rows[3], rows[2]


def _cell(column: str, value: str, row: int = 2) -> Callable[[list[list[str]]], None]:
    def edit(rows: list[list[str]]) -> None:
        rows[row][rows[0].index(column)] = value

    return edit


def _shift(rows: list[list[str]]) -> None:
    k = rows[0].index("m03")
    rows[2][k] = str(float(rows[2][k]) + 10.0)


def _summary(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    def change(folder: Path) -> None:
        data = json.loads((folder / "summary.json").read_text())
        edit(data)
        (folder / "summary.json").write_text(json.dumps(data))

    return change


def _swap_files(data: dict) -> None:
    files = data["scan_files"]
    files[1], files[2] = files[2], files[1]


TAMPERED = {
    "rows swapped": lambda f: _csv(f / "poses.csv", _swap_rows),
    "a pose that is not a rotation": lambda f: _csv(f / "poses.csv", _cell("m00", "5")),
    "a pose moved by 10 m": lambda f: _csv(f / "poses.csv", _shift),
    "scan files swapped": _summary(_swap_files),
    "config deleted": lambda f: (f / "config_used.yaml").unlink(),
    "poses.txt edited": lambda f: (f / "poses.txt").write_text("scan_00.laz" + " 1" * 16 + "\n"),
}


@pytest.mark.parametrize("case", sorted(TAMPERED))
@pytest.mark.parametrize("suffix", [".laz", ".e57"])
def test_a_tampered_result_folder_is_refused(chain_result, tmp_path, case, suffix):
    folder = copy_of(chain_result, tmp_path)
    TAMPERED[case](folder)
    out = tmp_path / f"street{suffix}"
    refused(export(folder, out), out)


UNCAUGHT_WITHOUT_DIGESTS = {"a pose moved by 10 m", "poses.txt edited"}


@pytest.mark.parametrize("case", sorted(set(TAMPERED) - UNCAUGHT_WITHOUT_DIGESTS))
def test_without_its_manifest_the_folder_must_still_agree_with_itself(chain_result, tmp_path, case):
    folder = copy_of(chain_result, tmp_path, manifest=False)
    TAMPERED[case](folder)
    out = tmp_path / "street.e57"
    res = export(folder, out)
    refused(res, out)
    if case == "a pose that is not a rotation":  # names the file that holds it, before any work
        line = one_error_line(res, "ndt-export")
        assert "poses.csv: row 3 (scan_01.laz)" in line and "S_scan_file" not in line
        assert "exported" not in res.stderr


# --- D25: damaged result folders: one line, never a traceback ----------------------------------


def _json(name: str, text: str) -> Callable[[Path], None]:
    return lambda f: (f / name).write_text(text)


def _result(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    def change(folder: Path) -> None:
        data = json.loads((folder / "result.json").read_text())
        edit(data)
        (folder / "result.json").write_text(json.dumps(data))

    return change


DAMAGED_CHAIN = {
    "summary not JSON": _json("summary.json", "{not json"),
    "summary a list": _json("summary.json", "[1, 2]"),
    "summary empty": _json("summary.json", "{}"),
    "anchor a string": _summary(lambda d: d.update(anchor="abc")),
    "scan_files null": _summary(lambda d: d.update(scan_files=None, scans=None)),
    "scan_files integers": _summary(lambda d: d.update(scan_files=[1, 2, 3, 4, 5])),
    "a cell not a number": lambda f: _csv(f / "poses.csv", _cell("m01", "abc")),
    "a cell nan": lambda f: _csv(f / "poses.csv", _cell("m01", "nan")),
    "a cell inf": lambda f: _csv(f / "poses.csv", _cell("m13", "inf")),
    "no has_pose column": lambda f: _csv(f / "poses.csv", _cell("has_pose", "x", 0)),
    "two rows of one file": lambda f: _csv(f / "poses.csv", _cell("file", "scan_00.laz", 3)),
}
DAMAGED_PAIR = {
    "no status": _result(lambda d: d.pop("status")),
    "no transform": _result(lambda d: d.pop("T_target_source")),
    "transform nan": _result(lambda d: d["T_target_source"][0].__setitem__(3, float("nan"))),
    "transform 3x3": _result(lambda d: d.update(T_target_source=np.eye(3).tolist())),
    "transform a string": _result(lambda d: d["T_target_source"][0].__setitem__(0, "x")),
    "result a list": _json("result.json", "[]"),
}


@pytest.mark.parametrize("case", sorted(DAMAGED_CHAIN) + sorted(DAMAGED_PAIR))
@pytest.mark.slow
def test_a_damaged_result_folder_is_one_line(chain_result, pair_result, tmp_path, case):
    result, edit = (
        (chain_result, DAMAGED_CHAIN[case])
        if case in DAMAGED_CHAIN
        else (pair_result, DAMAGED_PAIR[case])
    )
    folder = copy_of(result, tmp_path, manifest=False)
    edit(folder)
    out = tmp_path / "x.laz"
    refused(export(folder, out), out)


# --- D7, D8, D18: what is exported -------------------------------------------------------------


def test_an_empty_scan_selection_is_refused(chain_result, tmp_path):
    out = tmp_path / "x.laz"
    refused(export(chain_result, out, "--scans", ""), out, "--scans is empty")


def test_a_source_without_overlap_is_never_exported_as_suspect(tmp_path):
    a, b = unmatched_pair(tmp_path)
    res = runner.invoke(register_app, [str(a), str(b), "-o", str(tmp_path / "r"), "-q"])
    assert res.exit_code == 1
    out = tmp_path / "x.ply"
    res = runner.invoke(
        export_app, [str(tmp_path / "r"), "--out", str(out), "--include-suspect", "--json"]
    )
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["scans"] == ["a.xyz"]
    assert data["left_out"][0].startswith("b.xyz: no_overlap")
    assert data["points_written"] == len(np.loadtxt(a))


@pytest.mark.slow
def test_two_scans_of_one_file_name_in_two_folders_export(tmp_path):
    for side, scan in (("north", "scan_00.laz"), ("south", "scan_01.laz")):
        (tmp_path / side).mkdir()
        shutil.copy(SAMPLE / scan, tmp_path / side / "scan.laz")
    files = [str(tmp_path / side / "scan.laz") for side in ("north", "south")]
    res = runner.invoke(register_app, [*files, "-o", str(tmp_path / "r"), "-q"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(
        export_app, [str(tmp_path / "r"), "--out", str(tmp_path / "x.laz"), "--json"]
    )
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["scans"] == ["north/scan.laz", "south/scan.laz"]
    n = sum(laspy.read(SAMPLE / s).header.point_count for s in ("scan_00.laz", "scan_01.laz"))
    assert laspy.read(tmp_path / "x.laz").header.point_count == n


# --- ndt-eval: D5, D17, D27 --------------------------------------------------------------------


def test_eval_of_a_chain_writes_its_files_with_the_network_column(chain_result, tmp_path):
    out = tmp_path / "ev"
    res = runner.invoke(eval_app, [str(chain_result), "--gt", str(GT), "--out", str(out), "-q"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader((out / "eval.csv").read_text().splitlines()))
    links = list(csv.DictReader((chain_result / "pairs.csv").read_text().splitlines()))
    files = json.loads((chain_result / "summary.json").read_text())["transform_files"]
    pairs = zip(links, files, strict=True)
    verdicts = {(k["target"], k["source"]): k["network"] for k, f in pairs if f}
    assert {(r["target"], r["source"]): r["network"] for r in rows} == verdicts


def _reference(tmp_path: Path, column: int, value: str) -> Path:
    lines = []
    for line in GT.read_text().splitlines():
        fields = line.split()
        if fields and fields[0] == "scan_01.laz":
            fields[column] = value
        lines.append(" ".join(fields))
    path = tmp_path / "gt.txt"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(("column", "value"), [(4, "nan"), (1, "5"), (16, "2")])
def test_a_reference_pose_that_is_not_rigid_is_refused(chain_result, tmp_path, column, value):
    gt = _reference(tmp_path, column, value)
    res = runner.invoke(eval_app, [str(chain_result), "--gt", str(gt)])
    assert res.exit_code == 2
    line = one_error_line(res, "ndt-eval")
    assert "gt.txt: line" in line


DAMAGED_EVAL = {
    "pairs.csv binary": lambda f: (f / "pairs.csv").write_bytes(b"\xff\xfe\x00garbage\x81"),
    "pairs.csv without target": lambda f: _csv(f / "pairs.csv", _cell("target", "x", 0)),
    "poses.txt edited": lambda f: (f / "poses.txt").write_text("scan_00.laz" + " 1" * 16 + "\n"),
    "a link file edited": lambda f: _swap_link_files(f),
}


def _swap_link_files(folder: Path) -> None:
    """One link's file given the transform of another."""
    a, b = sorted(folder.glob("T_*.txt"))[:2]
    a.write_text(b.read_text())


@pytest.mark.parametrize("case", sorted(DAMAGED_EVAL))
def test_eval_of_a_damaged_result_is_one_line(chain_result, tmp_path, case):
    manifest = case in ("poses.txt edited", "a link file edited")  # caught by the digests
    folder = copy_of(chain_result, tmp_path, manifest=manifest)
    DAMAGED_EVAL[case](folder)
    res = runner.invoke(eval_app, [str(folder), "--gt", str(GT)])
    assert res.exit_code == 2, res.output
    one_error_line(res, "ndt-eval")


def test_the_exported_cloud_is_where_the_reference_puts_it(chain_result, tmp_path):
    """The untouched result still exports: every scan lands on its reference pose."""
    out = tmp_path / "street.laz"
    res = export(chain_result, out, "--scans", "0,3")
    assert res.exit_code == 0, res.output
    las = laspy.read(out)
    ref = read_pose_list(GT)
    for k, name in ((0, "scan_00.laz"), (3, "scan_03.laz")):
        src = laspy.read(chain_result.parent / "scans" / name)
        xyz = np.column_stack([src.x, src.y, src.z])
        T = np.linalg.inv(ref["scan_00.laz"]) @ ref[name]
        want = xyz @ T[:3, :3].T + T[:3, 3]
        mine = las.points[las["scan_index"] == k]
        got = np.column_stack([mine.x, mine.y, mine.z])
        assert len(got) == len(want)
        assert np.median(np.linalg.norm(got - want, axis=1)) < 0.05
