"""Failures that must stay impossible: a confident wrong answer, a folder of mixed old and new
outputs, a traceback instead of one line, a late error after seconds of work, a misread file."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import unmatched_pair
from typer.testing import CliRunner

import ndt_cli
from ndt_cli import io
from ndt_cli.cli import chain_app, register_app
from ndt_cli.config import Config, load
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import ConfigError, InputError
from ndt_cli.io.matrices import read_pose_list

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
runner = CliRunner()
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


def _truth(a: str, b: str) -> np.ndarray:
    poses = read_pose_list(SAMPLE / "poses_T_world_scan.txt")
    return np.linalg.inv(poses[a]) @ poses[b]


def _one_error_line(res, prog: str = "ndt-register") -> str:
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error:"), res.stderr
    assert "Traceback" not in res.output
    return lines[0]


# --- 1. no configuration gives a confident wrong answer ---------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(
    "schedule", [[5.0], [10.0], [20.0, 5.0], [200.0, 100.0, 50.0, 25.0], [8.0, 3.0]]
)
def test_a_coarse_schedule_is_right_or_flagged_never_confidently_wrong(schedule):
    cfg = Config().replace(grid={"cell_sizes": schedule})
    r = ndt_cli.register(SAMPLE / "scan_00.laz", SAMPLE / "scan_01.laz", cfg)
    rot, trans = transform_errors(r.T_target_source, _truth("scan_00.laz", "scan_01.laz"))
    assert (rot < 0.3 and trans < 0.15) or not r.ok, (schedule, r.status, rot, trans)


def test_a_key_given_twice_is_an_error(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("grid:\n  cell_sizes: [5]\nslices:\n  thickness: 0.3\ngrid:\n  overlap: true\n")
    with pytest.raises(ConfigError, match="key 'grid' given twice"):
        load(cfg)


@pytest.mark.parametrize(
    ("section", "values", "needle"),
    [
        ("quality", {"min_score_per_point": -0.05}, "may not be below its default"),
        ("quality", {"max_ambiguity": 1.0}, "may not be above its default"),
        ("quality", {"min_overlap": -0.1}, "may not be below its default"),
        ("quality", {"min_constraint_ratio": 0.0}, "may not be below its default"),
        ("quality", {"min_constraint_ratio_icp": 0.01}, "may not be below its default"),
        ("quality", {"max_free_space": 0.2}, "may not be above its default"),
        ("search", {"keep_candidates": 1}, "search.keep_candidates"),
    ],
)
def test_the_gate_cannot_be_loosened(section, values, needle):
    with pytest.raises(ConfigError, match=needle):
        Config().replace(**{section: values})
    stricter = {"min_score_per_point": 0.2, "max_ambiguity": 0.9}
    assert Config().replace(quality=stricter).quality.min_score_per_point == 0.2


# --- 2. outputs appear together or not at all -------------------------------------------------


@pytest.fixture(scope="module")
def first_result(tmp_path_factory):
    """A finished ndt-register result folder of the sample pair."""
    out = tmp_path_factory.mktemp("first") / "out"
    res = runner.invoke(
        register_app, [str(SAMPLE / "scan_00.laz"), str(SAMPLE / "scan_01.laz"), "-o", str(out)]
    )
    assert res.exit_code == 0, res.output
    return out


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


@pytest.mark.slow
def test_a_write_that_fails_midway_leaves_the_earlier_result_whole(
    first_result, tmp_path, monkeypatch
):
    out = _copy(first_result, tmp_path / "out")
    before = _tree(out)
    from ndt_cli.report import register_outputs

    real = register_outputs.register_files

    def disk_full(result, cfg):
        files = real(result, cfg)

        def no_space(path):
            raise OSError(28, "No space left on device")

        return {**files, "result.json": no_space}

    monkeypatch.setattr(register_outputs, "register_files", disk_full)
    res = runner.invoke(
        register_app, [str(SAMPLE / "scan_02.laz"), str(SAMPLE / "scan_03.laz"), "-o", str(out)]
    )
    assert res.exit_code == 2 and "No space left" in _one_error_line(res)
    assert _tree(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no temporary folder left


def _kill_during(where: str, out: Path, tmp: Path) -> None:
    """Run ndt-register in a child that stops (sleeps) at ``where`` of the publishing, and kill
    it there with SIGKILL."""
    code = (
        "import time, sys\n"
        "from ndt_cli.io import outdir\n"
        "MARK = sys.argv[-1] + '.ready'\n"
        f"real = outdir.{where}\n"
        "def stalled(*a, **k):\n"
        "    open(MARK, 'w').close(); time.sleep(60); return real(*a, **k)\n"
        f"outdir.{where} = stalled\n"
        "from ndt_cli.cli import register_app\n"
        "sys.argv = sys.argv[1:-1]  # program name first, marker last\n"
        "register_app()\n"
    )
    args = [str(SAMPLE / "scan_02.laz"), str(SAMPLE / "scan_03.laz"), "-o", str(out), "-q"]
    marker = tmp / "stalled"
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "ndt-register", *args, str(marker)], env=ENV, cwd=tmp
    )
    ready = Path(str(marker) + ".ready")
    deadline = time.monotonic() + 120
    while not ready.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert ready.exists(), f"the run never reached {where}"


@pytest.mark.slow
@pytest.mark.parametrize("where", ["_swap_in", "clean_stale"])
def test_kill_9_while_publishing_leaves_old_or_new_never_a_mix(first_result, tmp_path, where):
    out = _copy(first_result, tmp_path / "out")
    before = _tree(out)
    _kill_during(where, out, tmp_path)
    assert _tree(out) == before  # killed before the swap: the old result, whole
    res = runner.invoke(
        register_app, [str(SAMPLE / "scan_02.laz"), str(SAMPLE / "scan_03.laz"), "-o", str(out)]
    )
    assert res.exit_code == 0, res.output
    after = _tree(out)
    assert after["result.json"] != before["result.json"]
    assert json.loads(after["result.json"])["source"].endswith("scan_03.laz")
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".out.")]
    assert leftovers == []  # the next run removed what the killed one left


def test_a_run_ending_in_exit_1_replaces_the_earlier_result(first_result, tmp_path):
    out = _copy(first_result, tmp_path / "out")
    a, b = unmatched_pair(tmp_path)
    res = runner.invoke(register_app, [str(a), str(b), "-o", str(out)])
    assert res.exit_code == 1
    data = json.loads((out / "result.json").read_text())
    assert data["status"] == "no_overlap" and data["source"].endswith("b.xyz")
    assert set(_tree(out)) == set(_tree(first_result))  # the same files, all of the new run


def test_an_output_folder_with_foreign_files_is_refused_before_any_work(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.docx").write_text("precious")
    res = runner.invoke(
        register_app, [str(SAMPLE / "scan_00.laz"), str(SAMPLE / "missing.laz"), "-o", str(out)]
    )
    assert res.exit_code == 2 and "did not write" in _one_error_line(res)
    assert (out / "thesis.docx").read_text() == "precious"


# --- 3. and 5. one-line errors, checked before any work ----------------------------------------


@pytest.mark.parametrize(
    ("yaml_text", "needle"),
    [
        ("input:\n  scale: .inf\n", "input.scale"),
        ("input:\n  scale: 1.0e+300\n", "input.scale"),
        ("search:\n  translation_range: .nan\n", "search.translation_range"),
        ("slices:\n  heights: [1.0, .nan]\n", "slices.heights[1]"),
        ("input:\n  min_range: .nan\n", "input.min_range"),
        ("slices:\n  thickness: .inf\n", "slices.thickness"),
        ("grid:\n  cell_sizes: [.inf, 5]\n", "grid.cell_sizes[0]"),
        ("optimizer:\n  max_iterations: 100000000\n", "optimizer.max_iterations"),
        ("search:\n  translation_step: 0.2\n", "starts"),
    ],
)
def test_bad_numbers_in_the_config_are_one_line_naming_the_key(yaml_text, needle, tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml_text)
    res = runner.invoke(
        register_app,
        [
            str(SAMPLE / "scan_00.laz"),
            str(SAMPLE / "scan_01.laz"),
            "-c",
            str(cfg),
            "-o",
            str(tmp_path / "o"),
        ],
    )
    assert res.exit_code == 2 and needle in _one_error_line(res)
    assert not (tmp_path / "o").exists()


def test_nothing_is_read_before_the_output_and_both_inputs_are_checked(tmp_path, monkeypatch):
    from ndt_cli.ndt import register as reg

    calls = []
    monkeypatch.setattr(reg, "load_and_prepare_pair", lambda *a, **k: calls.append(a) or 1 / 0)
    a, b = str(SAMPLE / "scan_00.laz"), str(SAMPLE / "scan_01.laz")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    (tmp_path / "bad.laz").write_bytes(b"not a las file at all" * 10)
    cases = [
        ([a, b, "-o", str(blocker)], "not a folder"),
        ([a, b, "-o", ""], "folder of its own"),  # typer reads an empty path as "."
        ([a, b, "-o", "."], "folder of its own"),
        ([a, str(tmp_path / "bad.laz"), "-o", str(tmp_path / "o")], "bad.laz"),
        ([a, str(tmp_path / "none.laz"), "-o", str(tmp_path / "o")], "not found"),
    ]
    for args, needle in cases:
        res = runner.invoke(register_app, args)
        assert res.exit_code == 2 and needle in _one_error_line(res), (args, res.stderr)
    assert calls == []  # no scan was read or prepared


# --- 4. the Python API says what it expects --------------------------------------------------


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda p: p > 0, "bool"),
        (lambda p: np.zeros(len(p), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")]), "array of"),
        (lambda p: np.array([[1.0, 2.0, 3.0], [1.0, 2.0]], dtype=object), "array of object"),
        (lambda p: p.T.copy(), "transpose"),
        (lambda p: p.astype(complex), "complex"),
        (lambda p: p[:, :2], "shape"),
    ],
)
def test_the_api_rejects_arrays_it_cannot_use_with_an_input_error(make, needle):
    pts = np.random.default_rng(0).uniform(-5, 5, (200, 3))
    with pytest.raises(InputError, match="expected an \\(N,3\\) array") as info:
        ndt_cli.register(make(pts), pts)
    assert needle in str(info.value)


# --- 6. messages -------------------------------------------------------------------------------


def test_fifos_and_devices_are_not_called_empty(tmp_path):
    fifo = tmp_path / "pipe.xyz"
    os.mkfifo(fifo)
    for path in (fifo, Path("/dev/zero")):
        with pytest.raises(InputError, match=r"not a regular file|unknown extension"):
            io.read(path)
    with pytest.raises(InputError, match="not a regular file"):
        io.read(fifo)
    proc = tmp_path / "status.txt"
    proc.symlink_to("/proc/self/status")  # a size-0 file that is not empty
    with pytest.raises(InputError) as info:
        io.read(proc)
    assert "empty" not in str(info.value)


def test_a_header_line_that_starts_with_numbers_is_not_a_point(tmp_path):
    f = tmp_path / "h.xyz"
    f.write_text("2024 11 23 survey of the street\n1 2 3\n4 5 6\n7 8 9.5\n")
    np.testing.assert_array_equal(io.read(f).points, [[1, 2, 3], [4, 5, 6], [7, 8, 9.5]])


@pytest.mark.parametrize("text", ["x;y;z\n1,5;2,5;3,5\n1,6;2,5;3,5\n", "1,5 2,5 3,5\n1,6 2 3\n"])
def test_decimal_commas_are_reported_not_misread(text, tmp_path):
    f = tmp_path / "dc.csv"
    f.write_text(text)
    with pytest.raises(InputError, match="decimal commas"):
        io.read(f)


def test_a_pcd_with_a_long_leading_comment_is_read(tmp_path):
    pts = np.random.default_rng(1).uniform(-5, 5, (100, 3))
    f = tmp_path / "c.pcd"
    io.write(f, pts)
    body = f.read_bytes()
    f.write_bytes(b"# " + b"x" * 40_000 + b"\n" + b"# another comment\n" + body)
    np.testing.assert_allclose(io.read(f).points, pts)


def test_a_las_header_that_undercounts_is_reported(tmp_path, caplog):
    import laspy

    pts = np.random.default_rng(2).uniform(-5, 5, (1000, 3))
    f = tmp_path / "u.las"
    io.write(f, pts)
    las = laspy.read(f)
    data = bytearray(f.read_bytes())
    count_offset = 107  # legacy number of point records in a LAS 1.2 header
    data[count_offset : count_offset + 4] = (900).to_bytes(4, "little")
    f.write_bytes(bytes(data))
    assert las.header.point_count == 1000
    with caplog.at_level("WARNING", logger="ndt_cli"):
        assert io.count(f) == 900
    assert "100 more point records than its header's 900" in caplog.text


def test_notes_do_not_precede_an_error(tmp_path):
    pts = np.random.default_rng(3).uniform(0, 0.5, (500, 3))  # one cell: no slice points
    noisy = np.vstack([pts, np.full((20, 3), np.nan)])
    io.write(tmp_path / "n.xyz", noisy)
    res = runner.invoke(
        register_app,
        [str(SAMPLE / "scan_00.laz"), str(tmp_path / "n.xyz"), "-o", str(tmp_path / "o")],
    )
    assert res.exit_code == 2 and "no points in any slice" in _one_error_line(res)


# what makes root subject to file permissions: the capabilities that override them, dropped
WITHOUT_OVERRIDE = [
    "setpriv",
    "--inh-caps=-dac_override,-dac_read_search",
    "--bounding-set=-dac_override,-dac_read_search",
]


def test_unreadable_files_and_folders_are_one_line(tmp_path):
    """A file and a folder without read permission: one line naming the file, exit 2. The
    command runs as this user, and as root (whom permissions do not stop) without the
    capabilities that override them: no other user is needed, so the test passes from a
    clone in a private folder too (another user could not run its interpreter)."""
    if os.geteuid() == 0 and not shutil.which("setpriv"):
        pytest.skip("as root, setpriv (util-linux) drops the capabilities that read any file")
    prefix = WITHOUT_OVERRIDE if os.geteuid() == 0 else []
    locked = tmp_path / "locked"
    locked.mkdir()
    shutil.copy(SAMPLE / "scan_01.laz", locked / "s.laz")
    private = tmp_path / "private.laz"
    shutil.copy(SAMPLE / "scan_01.laz", private)
    locked.chmod(0o000)
    private.chmod(0o000)
    try:
        code = "from ndt_cli.cli import register_app; register_app()"
        for bad in (locked / "s.laz", private):
            args = [str(SAMPLE / "scan_00.laz"), str(bad), "-o", str(tmp_path / "o")]
            run = subprocess.run(
                [*prefix, sys.executable, "-c", code, *args],
                capture_output=True,
                text=True,
                env=ENV,
                check=False,
            )
            lines = run.stderr.strip().splitlines()
            assert run.returncode == 2 and len(lines) == 1, run.stderr
            assert "Permission denied" in lines[0] or "not readable" in lines[0], lines
            assert bad.name in lines[0]
            assert not (tmp_path / "o").exists()
    finally:
        locked.chmod(0o755)


# --- 8. no pose through a link that is not ok --------------------------------------------------


@pytest.mark.slow
def test_scans_behind_a_bad_link_get_no_pose(tmp_path):
    from conftest import street_files

    files, truth = street_files(tmp_path, n_scans=4)
    from ndt_cli import sim

    _, other, _ = sim.make_sequence(seed=77, n_scans=1, scan_kwargs={"n_azimuth": 1000})
    io.write(files[1], other[0])  # scan 1 is from another street
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(tmp_path / "o"), "-q"])
    assert res.exit_code == 1
    poses = read_pose_list(tmp_path / "o" / "poses.txt")
    rows = (tmp_path / "o" / "pairs.csv").read_text().splitlines()[1:]
    foreign = [r for r in rows if ",scan_1.laz," in r]
    assert not any(",ok," in r for r in foreign)  # no link of the foreign scan is ok
    assert "scan_1.laz" not in poses  # nothing is posed through them: the skip link around
    for name in set(poses) - {"scan_0.laz"}:  # the foreign scan poses the others, rightly
        k = int(name[5])
        rot, trans = transform_errors(poses[name], np.linalg.inv(truth[0]) @ truth[k])
        assert rot < 0.1 and trans < 0.05, (name, rot, trans)


def test_library_warnings_never_reach_the_terminal(tmp_path):
    """Coordinates that overflow a LAS file's scale: numpy warns while reading them; the command
    prints its one line, nothing else."""
    import laspy

    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales, header.offsets = np.full(3, 1e300), np.zeros(3)
    las = laspy.LasData(header)
    las.X = las.Y = las.Z = np.full(3, 2_000_000_000, np.int32)
    with pytest.warns(RuntimeWarning):  # laspy's header bounds overflow too
        las.write(str(tmp_path / "huge.las"))
    code = "from ndt_cli.cli import register_app; register_app()"
    args = [str(SAMPLE / "scan_00.laz"), str(tmp_path / "huge.las"), "-o", str(tmp_path / "o")]
    run = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, env=ENV, check=False
    )
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1, run.stderr
    assert "huge.las: the header's scales" in lines[0]
