"""Reliability: bad input never gives a traceback or a partial file, faults never lose finished
work, wrong results are never reported as good, and results are bit-identical run to run."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures.process import _ExecutorManagerThread
from pathlib import Path

import numpy as np
import pytest
from conftest import during_ctrl_c
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from ndt_cli import config, io, sim
from ndt_cli.cli import chain_app, register_app
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import ConfigError, InputError, UserInterruptError
from ndt_cli.io.matrices import read_matrix, read_pose_list
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.chain import NetworkOptions, run_chain
from ndt_cli.pipeline.local_pool import WorkerPool

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
runner = CliRunner()


@pytest.fixture(scope="module")
def street6(tmp_path_factory):
    """Six scans of one street as LAZ files; every link of their chain is ok."""
    from conftest import street_files

    return street_files(tmp_path_factory.mktemp("street6"), n_scans=6)[0]


@pytest.fixture(scope="module")
def scans():
    _, pts, poses = sim.make_sequence(
        seed=21, n_scans=4, spacing=(13.0, 17.0), scan_kwargs={"n_azimuth": 1000}
    )
    return pts, poses


def _write_text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _truncated(path: Path, points: np.ndarray) -> Path:
    io.write(path, points)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def _points(path: Path, points: np.ndarray) -> Path:
    io.write(path, points)
    return path


rng = np.random.default_rng(5)
BAD_SOURCES = {
    "empty ply": lambda d: _write_text(d / "e.ply", ""),
    "empty las": lambda d: _write_text(d / "e.las", ""),
    "empty xyz": lambda d: _write_text(d / "e.xyz", ""),
    "header-only ply": lambda d: _write_text(
        d / "h.ply",
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
        "property float y\nproperty float z\nend_header\n",
    ),
    "truncated las": lambda d: _truncated(d / "t.las", rng.uniform(0, 9, (5000, 3))),
    "truncated laz": lambda d: _truncated(d / "t.laz", rng.uniform(0, 9, (5000, 3))),
    "truncated ply": lambda d: _truncated(d / "t.ply", rng.uniform(0, 9, (5000, 3))),
    "truncated pcd": lambda d: _truncated(d / "t.pcd", rng.uniform(0, 9, (5000, 3))),
    "text named las": lambda d: _write_text(d / "w.las", "1 2 3\n4 5 6\n"),
    "non-numeric row": lambda d: _write_text(d / "n.xyz", "1 2 3\n4 5 6\nfoo bar baz\n"),
    "all nan": lambda d: _write_text(d / "nan.xyz", "nan nan nan\ninf 1 2\n"),
    "one point": lambda d: _write_text(d / "p1.xyz", "1 2 3\n"),
    "two points": lambda d: _write_text(d / "p2.xyz", "1 2 3\n2 3 4\n"),
    "three points": lambda d: _write_text(d / "p3.xyz", "1 2 3\n2 3 4\n3 4 6\n"),
    "all in one cell": lambda d: _points(d / "cell.xyz", rng.uniform(0, 0.5, (2000, 3))),
    "missing file": lambda d: d / "missing.laz",
    "unknown extension": lambda d: _write_text(d / "scan.abc", "1 2 3\n"),
    "a directory": lambda d: (d / "folder.ply").mkdir() or d / "folder.ply",
}


@pytest.mark.parametrize("case", sorted(BAD_SOURCES))
def test_bad_input_is_one_line_exit_2_no_traceback_no_output(case, scans, tmp_path):
    target = _points(tmp_path / "target.laz", scans[0][0])
    bad = BAD_SOURCES[case](tmp_path)
    out = tmp_path / "out"
    res = runner.invoke(register_app, [str(target), str(bad), "-o", str(out), "-q"])
    assert res.exit_code == 2, (case, res.output)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ndt-register: error:"), lines
    assert bad.name in lines[0]
    assert "Traceback" not in res.output
    assert isinstance(res.exception, SystemExit)  # a clean exit, not an escaped exception
    assert not out.exists()


@pytest.mark.parametrize(
    ("yaml_text", "needle"),
    [
        ("grid:\n  cell_size: [4]\n", "grid.cell_size"),
        ("grid:\n  cell_sizes: four\n", "grid.cell_sizes"),
        ("grid:\n  cell_sizes: [4, -2]\n", "grid.cell_sizes[1]"),
        ("grid:\n  cell_sizes: [2, 4]\n", "decreasing"),
        ("slices:\n  thickness: 0\n", "slices.thickness"),
        ("slices:\n  heights: [500.0]\n", "no points in any slice"),
    ],
)
@pytest.mark.slow
def test_bad_config_is_exit_2_and_keeps_earlier_results(yaml_text, needle, scans, tmp_path):
    a = _points(tmp_path / "a.laz", scans[0][0])
    b = _points(tmp_path / "b.laz", scans[0][1])
    out = tmp_path / "out"
    assert runner.invoke(register_app, [str(a), str(b), "-o", str(out), "-q"]).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    cfg = _write_text(tmp_path / "c.yaml", yaml_text)
    res = runner.invoke(register_app, [str(a), str(b), "-c", str(cfg), "-o", str(out), "-q"])
    assert res.exit_code == 2 and needle in res.stderr and len(res.stderr.splitlines()) == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # untouched, no temp files


def test_a_line_of_points_is_degenerate_not_good(scans, tmp_path):
    target = _points(tmp_path / "target.laz", scans[0][0])
    line = _points(tmp_path / "line.xyz", np.outer(np.linspace(0, 50, 3000), [1.0, 0.3, 0.05]))
    res = runner.invoke(register_app, [str(target), str(line), "-o", str(tmp_path / "o"), "-q"])
    # never "ok": the line is its own ground, so nothing of it stands above the ground at a
    # slice's height (exit 2), levelled or not
    assert res.exit_code == 2 and "no points in any slice" in res.stderr, res.stderr
    assert "Traceback" not in res.output
    cfg = _write_text(tmp_path / "c.yaml", "ground:\n  level: false\n")
    res = runner.invoke(
        register_app, [str(target), str(line), "-c", str(cfg), "-o", str(tmp_path / "o"), "-q"]
    )
    assert res.exit_code == 2 and "no points in any slice" in res.stderr, res.stderr


@pytest.mark.slow
def test_nan_rows_are_dropped_and_the_rest_registers(scans, tmp_path):
    pts, poses = scans
    noisy = np.vstack([pts[0], np.full((50, 3), np.nan), np.zeros((30, 3))])
    a = _points(tmp_path / "a.xyz", noisy)
    b = _points(tmp_path / "b.ply", pts[1])
    res = runner.invoke(register_app, [str(a), str(b), "-o", str(tmp_path / "o")])
    assert res.exit_code == 0
    assert "dropped 50 non-finite and 30 (0,0,0)" in res.stderr
    T = read_matrix(tmp_path / "o" / "T_target_source.txt")
    rot, trans = transform_errors(T, np.linalg.inv(poses[0]) @ poses[1])
    assert rot < 0.3 and trans < 0.15


@pytest.mark.slow
def test_identical_scans_and_a_scan_10_km_away(scans, tmp_path):
    pts, _ = scans
    a = _points(tmp_path / "a.laz", pts[0])
    shift = np.array([10_000.0, -3_000.0, 0.0])
    far = _points(tmp_path / "far.laz", pts[0] + shift)
    for source, offset in [(a, np.zeros(3)), (far, shift)]:
        res = runner.invoke(register_app, [str(a), str(source), "-o", str(tmp_path / "o"), "-q"])
        assert res.exit_code == 0
        T = read_matrix(tmp_path / "o" / "T_target_source.txt")
        mapped = (pts[0] + offset) @ T[:3, :3].T + T[:3, 3]
        assert np.abs(mapped - pts[0]).max() < 0.01  # every point back in place within 1 cm


@pytest.mark.slow
def test_two_different_streets_are_never_reported_as_good(scans, tmp_path):
    _, other, _ = sim.make_sequence(seed=77, n_scans=1, scan_kwargs={"n_azimuth": 1000})
    a = _points(tmp_path / "a.laz", scans[0][0])
    b = _points(tmp_path / "b.laz", other[0])
    res = runner.invoke(register_app, [str(a), str(b), "-o", str(tmp_path / "o"), "--json"])
    assert res.exit_code == 1
    data = json.loads(res.stdout)
    assert data["status"] in ("suspect", "degenerate") and data["warnings"]


def _die_on_crash_sources() -> None:
    """Runs in every worker process: registering a source whose file name holds 'crash' kills
    the process, as a segfault in a library would."""
    from ndt_cli.pipeline import tasks

    real = tasks.register_prepared

    def dying(target, source, cfg, *args, **kwargs):
        if source.path is not None and "crash" in source.path.name:
            os._exit(3)
        return real(target, source, cfg, *args, **kwargs)

    tasks.register_prepared = dying


@pytest.mark.slow
def test_crashed_worker_fails_its_link_and_the_chain_completes(scans, tmp_path):
    pts, _ = scans
    names = ["p0.laz", "p1.laz", "p2_crash.laz", "p3.laz"]
    files = [_points(tmp_path / n, p) for n, p in zip(names, pts, strict=True)]
    pool = WorkerPool(2, init=_die_on_crash_sources)
    chain = NetworkOptions(neighbours=1)  # 0-1, 1-2 (the source kills), 2-3
    result = run_chain(files, config.Config(), tmp_path / "o", executor=pool, network=chain)
    by_pair = {(link.target, link.source): link for link in result.links}
    crashed = by_pair[(1, 2)]  # the link whose source kills
    assert crashed.status is Status.FAILED and "worker process died" in crashed.reason
    assert by_pair[(0, 1)].ok and by_pair[(2, 3)].ok  # the others are registered


class _BreaksAfterOneResult:
    """Local workers, and a driver that breaks after the first result with ``error``."""

    ships_data = True

    def __init__(self, error: BaseException) -> None:
        self.pool, self.ends, self.error = WorkerPool(2, threads=1), [], error

    def start(self) -> None:
        self.pool.start()

    def run(self, tasks, then=None):
        for item in self.pool.run(tasks, then):
            yield item
            raise self.error

    def close(self) -> None:
        self.ends.append("close")
        self.pool.close()


@pytest.mark.slow
def test_an_error_in_the_run_closes_the_workers(scans, tmp_path):
    pts, _ = scans
    files = [_points(tmp_path / f"s{i}.laz", p) for i, p in enumerate(pts)]
    for error, raised in [
        (RuntimeError("a bug in the driver"), RuntimeError),
        (KeyboardInterrupt(), UserInterruptError),
        (during_ctrl_c(ImportError("initialization failed")), UserInterruptError),
    ]:
        executor = _BreaksAfterOneResult(error)
        with pytest.raises(raised) as caught:
            run_chain(files, config.Config(), tmp_path / "o", executor=executor)
        assert executor.ends == ["close"]
        assert not [t for t in threading.enumerate() if isinstance(t, _ExecutorManagerThread)]
        assert raised is RuntimeError or "--resume" in str(caught.value)


CHAIN = [sys.executable, "-c", "from ndt_cli.cli import chain_app; chain_app()"]


def _links(out: Path) -> list[Path]:
    """Finished link files (not the temporary files of a write in progress)."""
    return [p for p in (out / "links").glob("[0-9a-f]*.json")]


def _wait_for_links(out: Path, n: int, proc: subprocess.Popen, limit: float = 120.0) -> None:
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline and proc.poll() is None:
        if len(_links(out)) >= n:
            return
        time.sleep(0.05)


@pytest.mark.slow
def test_sigint_stops_cleanly_and_resume_completes(street6, tmp_path):
    files = street6
    out = tmp_path / "o"
    proc = subprocess.Popen(
        [*CHAIN, *map(str, files), "-o", str(out), "-j", "1", "-q"],
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for_links(out, 1, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "--resume" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    kept = _links(out)
    assert 1 <= len(kept) < 5 and all(json.loads(p.read_text())["key"] for p in kept)
    before = {p.name: p.read_bytes() for p in kept}
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(out), "--resume", "-q"])
    assert res.exit_code == 0, res.output
    assert _reused_every_kept_link(out, before)


@pytest.mark.slow
def test_ctrl_c_reaches_a_chain_started_with_sigint_blocked(street6, tmp_path):
    """A parent that had SIGINT blocked when it started the command (the mask is inherited)
    must not make Ctrl-C a no-op: the chain stops with 130 and one line."""
    out = tmp_path / "o"
    proc = subprocess.Popen(
        [*CHAIN, *map(str, street6), "-o", str(out), "-j", "1", "-q"],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}),
    )
    _wait_for_links(out, 1, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "--resume" in err and len(err.strip().splitlines()) == 1


def _reused_every_kept_link(out: Path, before: dict[str, bytes]) -> bool:
    """Every link file of the interrupted run is still there, unchanged (not registered
    again), and the result says it reused links."""
    after = {p.name: p.read_bytes() for p in _links(out)}
    unchanged = all(after.get(name) == data for name, data in before.items())
    return unchanged and json.loads((out / "summary.json").read_text())["reused"] >= 1


@pytest.fixture(scope="module")
def street6_clean(street6, tmp_path_factory):
    """The outputs of an uninterrupted chain of the six scans (every kill point's reference)."""
    clean = tmp_path_factory.mktemp("clean")
    assert runner.invoke(chain_app, [*map(str, street6), "-o", str(clean), "-q"]).exit_code == 0
    return clean


@pytest.mark.slow
@pytest.mark.parametrize("kill_after", [1, 3])
def test_sigkill_at_several_points_then_resume_equals_clean_run(
    street6, street6_clean, tmp_path, kill_after
):
    files, clean, out = street6, street6_clean, tmp_path / "killed"
    proc = subprocess.Popen(
        [*CHAIN, *map(str, files), "-o", str(out), "-j", "1", "-q"], start_new_session=True
    )
    _wait_for_links(out, kill_after, proc)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    kept = _links(out)
    assert kill_after <= len(kept) < 5 and not (out / "pairs.csv").exists()
    before = {p.name: p.read_bytes() for p in kept}
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(out), "--resume", "-q"])
    assert res.exit_code == 0, res.output
    assert _reused_every_kept_link(out, before)
    for name in ["poses.txt", "poses.csv", *[p.name for p in clean.glob("T_*.txt")]]:
        assert (out / name).read_bytes() == (clean / name).read_bytes(), name
    assert _without_runtime(out / "pairs.csv") == _without_runtime(clean / "pairs.csv")


def _without_runtime(path: Path) -> list[list[str]]:
    rows = list(csv.reader(path.read_text().splitlines()))
    drop = rows[0].index("runtime_s")
    return [row[:drop] + row[drop + 1 :] for row in rows]


@pytest.mark.slow
def test_bit_identical_across_numba_thread_counts(tmp_path):
    code = (
        "import sys, ndt_cli; r = ndt_cli.register(sys.argv[1], sys.argv[2]); "
        "print(r.T_target_source.tobytes().hex())"
    )
    outs = []
    for threads in ["1", "2"]:
        env = {**os.environ, "NUMBA_NUM_THREADS": threads, "OPENBLAS_NUM_THREADS": "1"}
        run = subprocess.run(
            [sys.executable, "-c", code, str(SAMPLE / "scan_00.laz"), str(SAMPLE / "scan_01.laz")],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
        outs.append(run.stdout.strip())
    assert outs[0] == outs[1] and len(outs[0]) == 256


SUFFIXES = [".ply", ".las", ".laz", ".pcd", ".xyz", ".csv"]


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.binary(max_size=2000), suffix=st.sampled_from(SUFFIXES))
def test_readers_never_raise_anything_but_input_error(tmp_path, data, suffix):
    path = tmp_path / f"fuzz{suffix}"
    path.write_bytes(data)
    try:
        cloud = io.read(path)
    except InputError as exc:
        assert "\n" not in str(exc) and path.name in str(exc)
    else:
        assert np.isfinite(cloud.points).all() and len(cloud.points) > 0


_scalar = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 50),
    st.floats(-10, 300),
    st.text(max_size=5),
    st.lists(st.floats(-5, 300), max_size=4),
)
_section = st.dictionaries(
    st.sampled_from(["heights", "thickness", "cell_sizes", "min_points", "method", "z", "bogus"]),
    _scalar,
    max_size=3,
)


@settings(max_examples=200, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(["slices", "grid", "optimizer", "ground", "nope"]),
        st.one_of(_section, _scalar),
        max_size=3,
    )
)
def test_config_is_valid_or_a_config_error(data):
    try:
        cfg = config.from_dict(data)
    except ConfigError as exc:
        assert "\n" not in str(exc)
    else:
        assert all(
            b < a for a, b in zip(cfg.grid.cell_sizes, cfg.grid.cell_sizes[1:], strict=False)
        )
        assert cfg.slices.thickness > 0


def _damage_links(out: Path, how: str) -> int:
    """Damage the transform of every link file of ``out/links``; how many were damaged."""
    damaged = 0
    for link in sorted((out / "links").glob("*.json")):
        data = json.loads(link.read_text())
        if not isinstance(data, dict) or not (data.get("result") or {}).get("T_target_source"):
            continue
        T = np.array(data["result"]["T_target_source"])
        if how == "nan":
            T[0, 3] = np.nan
        else:
            T[:3, :3] *= 3.0
        data["result"]["T_target_source"] = T.tolist()
        link.write_text(json.dumps(data))
        damaged += 1
    return damaged


@pytest.mark.slow
@pytest.mark.parametrize("how", ["nan", "scaled rotation"])
def test_damaged_resume_state_is_recomputed(tmp_path, how):
    sample = Path(__file__).resolve().parents[1] / "sample_data"
    files = [str(sample / "scan_00.laz"), str(sample / "scan_01.laz")]
    out = tmp_path / "out"
    first = CliRunner().invoke(chain_app, [*files, "-o", str(out), "-q", "-j", "1"])
    assert first.exit_code == 0, first.output
    before = read_pose_list(out / "poses.txt")
    assert _damage_links(out, how) >= 1
    res = CliRunner().invoke(chain_app, [*files, "-o", str(out), "-q", "-j", "1", "--resume"])
    assert res.exit_code == 0, res.output
    after = read_pose_list(out / "poses.txt")
    np.testing.assert_allclose(after["scan_01.laz"], before["scan_01.laz"], atol=1e-9)
