"""Outputs never destroy what is not theirs: a result folder holds only what ndt-cli wrote, a
re-run never removes anything else, and no output is, or overwrites, an input."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ndt_cli.cli import chain_app, eval_app, export_app, register_app

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
GT = SAMPLE / "poses_T_world_scan.txt"
runner = CliRunner()


def tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative name -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def one_error_line(res, prog: str) -> str:
    """The single line a failed command prints on stderr."""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error:"), res.output
    assert "Traceback" not in res.output
    return lines[0]


def copies(folder: Path, *names: str) -> list[Path]:
    """Copies of sample scans in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    return [Path(shutil.copy(SAMPLE / n, folder / n)) for n in names]


@pytest.fixture(scope="module")
def pair_result(tmp_path_factory) -> Path:
    """An ndt-register result of two copies of the sample scans (the copies beside it)."""
    root = tmp_path_factory.mktemp("pair")
    scans = copies(root / "scans", "scan_00.laz", "scan_01.laz")
    res = runner.invoke(register_app, [*map(str, scans), "-o", str(root / "res"), "-q"])
    assert res.exit_code == 0, res.output
    return root / "res"


def _copy(result: Path, dst: Path) -> Path:
    shutil.copytree(result, dst)
    return dst


# --- a re-run into a result folder ---------------------------------------------------------


@pytest.mark.parametrize(
    ("kept", "needle"),
    [("scans", "must not be, hold or lie inside an input"), ("notes", "did not write")],
)
@pytest.mark.slow
def test_a_rerun_into_a_result_folder_never_deletes_the_users_files(
    pair_result, tmp_path, kept, needle
):
    out = _copy(pair_result, tmp_path / "res")
    (out / "notes.txt").write_text("my notes")
    where = out if kept == "scans" else tmp_path  # the user keeps the scans there, or not
    scans = copies(where, "scan_00.laz", "scan_01.laz")
    before = tree(out)
    res = runner.invoke(register_app, [*map(str, scans), "-o", str(out), "-q"])
    assert res.exit_code == 2
    assert needle in one_error_line(res, "ndt-register")
    assert tree(out) == before


@pytest.mark.slow
def test_a_file_added_inside_a_result_subfolder_is_foreign_too(tmp_path):
    scans = copies(tmp_path / "scans", "scan_00.laz", "scan_01.laz")
    out = tmp_path / "chain"
    res = runner.invoke(chain_app, [*map(str, scans), "-o", str(out), "-q", "--jobs", "1"])
    assert res.exit_code in (0, 1), res.output
    (out / "poses" / "my_pose.txt").write_text("1 0 0 0")
    before = tree(out)
    again = runner.invoke(chain_app, [*map(str, scans), "-o", str(out), "-q", "--jobs", "1"])
    assert again.exit_code == 2 and "my_pose.txt" in one_error_line(again, "ndt-chain")
    assert tree(out) == before


def test_a_rerun_of_the_same_command_still_replaces_its_own_result(pair_result, tmp_path):
    out = _copy(pair_result, tmp_path / "res")
    scans = copies(tmp_path / "other", "scan_01.laz", "scan_02.laz")
    res = runner.invoke(register_app, [*map(str, scans), "-o", str(out), "-q"])
    assert res.exit_code in (0, 1), res.output
    assert "scan_02.laz" in (out / "result.json").read_text()
    assert set(tree(out)) == set(tree(pair_result))


# --- ndt-eval --out ------------------------------------------------------------------------


@pytest.mark.parametrize("where", ["same", "inside"])
def test_eval_never_writes_into_the_result_it_reads(pair_result, tmp_path, where):
    result = _copy(pair_result, tmp_path / "res")
    before = tree(result)
    out = result if where == "same" else result / "eval"
    res = runner.invoke(eval_app, [str(result), "--gt", str(GT), "--out", str(out)])
    assert res.exit_code == 2, res.output
    one_error_line(res, "ndt-eval")
    assert tree(result) == before


# --- ndt-export onto the scans -------------------------------------------------------------


def test_export_onto_an_input_scan_is_refused(pair_result):
    scan = pair_result.parent / "scans" / "scan_01.laz"
    before = scan.read_bytes()
    res = runner.invoke(export_app, [str(pair_result), "--out", str(scan)])
    assert res.exit_code == 2
    assert "scan_01.laz" in one_error_line(res, "ndt-export")
    assert scan.read_bytes() == before


def test_per_scan_export_that_would_overwrite_a_scan_is_refused(pair_result):
    folder = pair_result.parent / "scans"
    before = tree(folder)
    res = runner.invoke(export_app, [str(pair_result), "--per-scan", str(folder)])
    assert res.exit_code == 2
    one_error_line(res, "ndt-export")
    assert tree(folder) == before


def test_temporaries_of_a_killed_export_are_removed_by_the_next(pair_result, tmp_path):
    import subprocess
    import sys

    target = tmp_path / "street.laz"
    code = (
        "import os, signal, sys\n"
        "from ndt_cli.io.atomic import atomic_path\n"
        "with atomic_path(sys.argv[1]) as tmp:\n"
        "    tmp.write_bytes(b'half a file')\n"
        "    os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    run = subprocess.run([sys.executable, "-c", code, str(target)], check=False)
    assert run.returncode == -9
    assert len(list(tmp_path.iterdir())) == 1  # the killed writer's temporary file
    res = runner.invoke(export_app, [str(pair_result), "--out", str(target), "-q"])
    assert res.exit_code == 0, res.output
    assert [p.name for p in tmp_path.iterdir()] == ["street.laz"]


# --- ndt-export: what it writes and what it says ----------------------------------------------


def test_a_later_per_scan_export_replaces_the_earlier_files_and_only_those(pair_result, tmp_path):
    folder = tmp_path / "per_scan"
    res = runner.invoke(export_app, [str(pair_result), "--per-scan", str(folder), "-q"])
    assert res.exit_code == 0, res.output
    (folder / "notes.txt").write_text("mine")
    res = runner.invoke(export_app, [str(pair_result), "--per-scan", str(folder), "--scans", "0"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in folder.iterdir()) == [
        ".ndt-cli-outputs",
        "notes.txt",
        "scan_00.laz",
    ]
    (folder / "scan_01.laz").write_text("not an export")  # a file no export wrote
    res = runner.invoke(export_app, [str(pair_result), "--per-scan", str(folder), "-q"])
    assert res.exit_code == 2 and "no earlier export wrote it" in one_error_line(res, "ndt-export")
    assert (folder / "scan_01.laz").read_text() == "not an export"


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--out", "{tmp}"], "is a folder; --out names the file to write"),
        (
            ["--per-scan", "{tmp}/x", "--format", "xyz"],
            "--format must be las, laz or ply, got 'xyz'",
        ),
        (["--per-scan", "{tmp}/file.laz"], "file.laz: exists and is not a folder"),
        (["--out", "{tmp}/" + "x" * 300 + ".laz"], "the name is longer than 255 bytes"),
        (["--per-scan", "{tmp}/" + "x" * 300], "the name is longer than 255 bytes"),
    ],
)
def test_output_paths_are_refused_with_what_is_wrong(pair_result, tmp_path, args, needle):
    (tmp_path / "file.laz").write_text("x")
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    res = runner.invoke(export_app, [str(pair_result), *args])
    assert res.exit_code == 2
    assert needle in one_error_line(res, "ndt-export")


@pytest.mark.parametrize("suffix", [".laz", ".e57"])
def test_a_file_size_limit_during_an_export_is_one_line(pair_result, tmp_path, suffix):
    import resource
    import subprocess
    import sys

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    out = tmp_path / f"x{suffix}"
    code = "from ndt_cli.cli import export_app; export_app()"
    run = subprocess.run(
        [sys.executable, "-c", code, str(pair_result), "--out", str(out), "-q"],
        preexec_fn=limit,
        capture_output=True,
        text=True,
        check=False,
    )
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1, run.stderr
    assert lines[0].startswith(f"ndt-export: error: {out}: cannot write")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("mount"), reason="needs root")
def test_an_output_on_a_read_only_file_system_says_so(tmp_path):
    import subprocess

    mounted = tmp_path / "ro"
    mounted.mkdir()
    if subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(mounted)]
    ).returncode:
        pytest.skip("cannot mount a file system here")
    try:
        scans = [SAMPLE / "scan_00.laz", SAMPLE / "scan_01.laz"]
        res = runner.invoke(chain_app, [*map(str, scans), "-o", str(mounted / "out"), "-q"])
        assert res.exit_code == 2
        assert "(read-only file system)" in one_error_line(res, "ndt-chain")
    finally:
        subprocess.run(["umount", str(mounted)], check=True)


def test_ndt_watch_never_publishes_into_the_folder_it_watches(tmp_path):
    from ndt_cli.cli import watch_app

    (tmp_path / "scans").mkdir()
    for out in (tmp_path / "scans", tmp_path / "scans" / "result"):
        args = [str(tmp_path / "scans"), "--out", str(out), "--exit-when-idle", "1"]
        res = runner.invoke(watch_app, args)
        assert res.exit_code == 2, res.output
        assert "must not be, hold or lie inside an input" in one_error_line(res, "ndt-watch")
    assert list((tmp_path / "scans").iterdir()) == []
