"""Guards before and around the work: every scan checked before any is prepared, a scan known
by the content that was registered, an output folder that is another campaign's or another
run's refused, and resume state that was edited never trusted."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest
from conftest import street_files
from typer.testing import CliRunner

from ndt_cli.cli import chain_app, export_app, register_app
from ndt_cli.config import Config
from ndt_cli.errors import InputError, OutputError
from ndt_cli.io.export import ExportScan, export
from ndt_cli.io.outlock import lock_path, output_lock
from ndt_cli.io.points import check_readable
from ndt_cli.pipeline.campaign import Campaign
from ndt_cli.pipeline.chain import refuse_changed, run_chain
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.scans import file_hash
from ndt_cli.pipeline.verify import NodeStatus
from ndt_cli.report.chain_outputs import write_chain_outputs

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
CHAIN = [sys.executable, "-c", "from ndt_cli.cli import chain_app; chain_app()"]
REGISTER = [sys.executable, "-c", "from ndt_cli.cli import register_app; register_app()"]
runner = CliRunner()


@pytest.fixture(scope="module")
def street(tmp_path_factory) -> list[Path]:
    """Four scans of one simulated street (LAZ); every link of their chain is ok."""
    return street_files(tmp_path_factory.mktemp("street"), n_scans=4)[0]


@pytest.fixture(scope="module")
def other_street(tmp_path_factory) -> list[Path]:
    """Two scans of another street."""
    return street_files(tmp_path_factory.mktemp("other"), n_scans=2, seed=77)[0]


def _error_line(output: str) -> str:
    lines = output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in output, output
    return lines[0]


def _las_with_header_value(path: Path, offset: int, value: float) -> Path:
    """The sample's scan_01 as LAS at a 0.1 m scale, one header double at byte ``offset``
    (131: x scale, 155: x offset) replaced by ``value``."""
    las = laspy.read(SAMPLE / "scan_01.laz")
    header = laspy.LasHeader(point_format=las.header.point_format.id, version=las.header.version)
    header.scales, header.offsets = np.array([0.1] * 3), np.zeros(3)
    out = laspy.LasData(header)
    out.x, out.y, out.z = las.x, las.y, las.z
    out.write(path)
    data = bytearray(path.read_bytes())
    data[offset : offset + 8] = struct.pack("<d", value)
    path.write_bytes(bytes(data))
    return path


def _truncated_laz(path: Path) -> Path:
    path.write_bytes((SAMPLE / "scan_00.laz").read_bytes()[:100_000])  # an aborted copy
    return path


BAD_SCANS = {
    "missing": (lambda d: d / "scan_9.laz", "file not found"),
    "not a scan format": (lambda d: _text(d / "scene.json", "{}"), "unknown extension"),
    "text without points": (lambda d: _text(d / "notes.txt", "a b c\n"), "no row of x y z"),
    "aborted LAZ copy": (lambda d: _truncated_laz(d / "aborted.laz"), "truncated LAZ file"),
    "damaged LAS scale": (
        lambda d: _las_with_header_value(d / "dm.las", 131, 1e300),
        "damaged header",
    ),
    "a LAZ named as scan K": (lambda d: Path(f"{SAMPLE / 'scan_00.laz'}#0"), "holds one scan"),
}


def _text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", sorted(BAD_SCANS))
@pytest.mark.slow
def test_a_bad_scan_among_good_ones_is_exit_2_before_any_work(case, street, tmp_path):
    make, needle = BAD_SCANS[case]
    bad = make(tmp_path)
    out = tmp_path / "out"
    res = runner.invoke(chain_app, [*map(str, street), str(bad), "-o", str(out), "-q"])
    assert res.exit_code == 2, res.output
    line = _error_line(res.output)
    assert needle in line and bad.name in line, line
    assert not out.exists()  # nothing prepared, no link kept


def _register_refuses(source: Path, tmp_path: Path) -> str:
    """``ndt-register`` of the sample's first scan and ``source``, in a process of its own:
    exit 2 and one line, which is returned."""
    run = subprocess.run(
        [*REGISTER, str(SAMPLE / "scan_00.laz"), str(source), "-o", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        env=ENV,
        check=False,
        timeout=300,
    )
    assert run.returncode == 2, run.stderr
    return _error_line(run.stderr)


@pytest.mark.parametrize("case", ["not a scan format", "aborted LAZ copy", "damaged LAS scale"])
def test_ndt_register_refuses_them_too(case, tmp_path):
    """In a process of its own: before the header check, a damaged scale crashed it."""
    make, needle = BAD_SCANS[case]
    bad = make(tmp_path)
    assert needle in _register_refuses(bad, tmp_path)


def test_a_damaged_las_offset_and_an_e57_scan_number_are_named(tmp_path):
    bad = _las_with_header_value(tmp_path / "off.las", 155, 1e300)
    with pytest.raises(InputError, match="beyond any real scan"):
        check_readable(bad)
    e57 = tmp_path / "two.e57"
    scans = [ExportScan(SAMPLE / f"scan_0{k}.laz", f"s{k}", k, np.eye(4)) for k in (0, 1)]
    export(scans, e57)
    check_readable(f"{e57}#1")
    for tail in ("#abc", "#-1", "#", "#1#0"):
        with pytest.raises(InputError, match=r"names no scan: two\.e57#K takes a scan number"):
            check_readable(f"{e57}{tail}")


def test_an_anchor_in_other_digits_is_one_line(street, tmp_path):
    for anchor in ("²", "①", "٣"):
        args = [*map(str, street), "-o", str(tmp_path / "o"), "--anchor", anchor]
        res = runner.invoke(chain_app, args)
        assert res.exit_code == 2 and "neither a scan index" in _error_line(res.output)


@pytest.mark.parametrize("how", ["centimetres", "an id column first"])
@pytest.mark.slow
def test_a_scan_in_other_units_is_refused_at_once(how, tmp_path):
    """A scan's points crowd around it; in centimetres, or with an id as x, they spread over
    kilometres, and registering them took minutes and gigabytes (or a 31 GB allocation)."""
    las = laspy.read(SAMPLE / "scan_01.laz")
    xyz = np.column_stack([las.x, las.y, las.z])
    bad = tmp_path / "bad.csv"
    if how == "centimetres":
        np.savetxt(bad, xyz * 100, fmt="%.1f", delimiter=",")
    else:
        rows = np.column_stack([np.arange(len(xyz)), xyz])
        np.savetxt(bad, rows, fmt="%.4f", delimiter=",", header="id,x,y,z", comments="")
    assert "input.scale" in _register_refuses(bad, tmp_path)
    if how == "centimetres":  # with their units given, a pair in centimetres registers
        target = laspy.read(SAMPLE / "scan_00.laz")
        cm = tmp_path / "target.csv"
        np.savetxt(cm, np.column_stack([target.x, target.y, target.z]) * 100, delimiter=",")
        cfg = tmp_path / "cm.yaml"
        cfg.write_text("input:\n  scale: 0.01\n")
        args = [str(cm), str(bad), "-o", str(tmp_path / "m"), "-c", str(cfg), "-q"]
        res = runner.invoke(register_app, args)
        assert res.exit_code == 0, res.output


def test_the_same_scan_under_two_names_is_exit_2(street, tmp_path):
    copy = tmp_path / "scan_1_copy.laz"
    shutil.copy(street[1], copy)
    out = tmp_path / "out"
    res = runner.invoke(chain_app, [*map(str, street), str(copy), "-o", str(out), "-q"])
    assert res.exit_code == 2
    line = _error_line(res.output)
    assert "the same content as" in line and {"scan_1.laz", "scan_1_copy.laz"} <= set(
        Path(w.strip(":(),")).name for w in line.split()
    )
    assert not out.exists()


def test_a_second_run_into_a_folder_being_written_is_exit_2(street, tmp_path):
    out = tmp_path / "out"
    with output_lock(out, "a test holding it"):
        assert lock_path(out).exists()
        run = subprocess.run(
            [*CHAIN, *map(str, street), "-o", str(out), "-q"],
            capture_output=True,
            text=True,
            env=ENV,
            check=False,
        )
        assert run.returncode == 2, run.stderr
        line = _error_line(run.stderr)
        assert "another run is writing this folder" in line and f"process {os.getpid()}" in line
        with (
            pytest.raises(OutputError, match="another run"),
            output_lock(out, "a second holder in this process"),
        ):
            pass
    assert not lock_path(out).exists()  # released and removed
    assert not out.exists()


def test_a_lock_left_by_a_killed_run_is_no_obstacle(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from pathlib import Path; from ndt_cli.io.outlock import "
            "output_lock\nwith output_lock(Path(sys.argv[1]), 'killed'):\n"
            "    print('held', flush=True); time.sleep(600)",
            str(out),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(OutputError, match="process"), output_lock(out, "too early"):
        pass
    holder.kill()
    holder.wait()
    assert lock_path(out).exists()  # left behind by the killed run
    with output_lock(out, "after the kill"):
        pass


@pytest.mark.slow
def test_a_lock_whose_run_is_gone_is_waited_for_while_its_last_process_exits(tmp_path):
    """A run killed with its workers: the lock names a process that is gone, while another of
    its processes still holds it for a moment. The next run waits and takes it."""
    out = tmp_path / "out"
    done = tmp_path / "holder-done"
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()  # a process that existed and is gone
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import fcntl, os, sys, time\n"
            "fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT)\n"
            "fcntl.flock(fd, fcntl.LOCK_EX)\n"
            "os.write(fd, (sys.argv[2] + ' ndt-chain').encode())\n"
            "print('held', flush=True); time.sleep(1.5)\n"
            "open(sys.argv[3], 'w').close()",  # the lock is released only at exit, after this
            str(lock_path(out)),
            str(gone.pid),
            str(done),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline().strip() == "held"
    with output_lock(out, "the next run"):
        # Taken only once the holder finished. Not `poll()`: the kernel releases the lock when
        # the holder's files close, a moment before the process can be waited for.
        assert done.exists()
    assert holder.wait(timeout=30) == 0


@pytest.mark.slow
def test_another_campaign_s_result_is_kept_unless_overwrite(street, other_street, tmp_path):
    out = tmp_path / "out"
    first = runner.invoke(chain_app, [*map(str, street[:3]), "-o", str(out), "-q"])
    assert first.exit_code == 0, first.output
    before = (out / "summary.json").read_bytes()
    res = runner.invoke(chain_app, [*map(str, other_street), "-o", str(out), "-q"])
    assert res.exit_code == 2
    line = _error_line(res.output)
    assert "another campaign" in line and "--overwrite" in line and str(out) in line
    assert (out / "summary.json").read_bytes() == before
    grown = runner.invoke(chain_app, [*map(str, street), "-o", str(out), "-q"])
    assert grown.exit_code == 0, grown.output  # the same campaign, grown: updated
    assert len(json.loads((out / "summary.json").read_text())["scans"]) == 4
    res = runner.invoke(chain_app, [*map(str, other_street), "-o", str(out), "--overwrite", "-q"])
    assert res.exit_code == 0, res.output
    scans = json.loads((out / "summary.json").read_text())["scans"]
    assert [Path(s).name for s in scans] == [p.name for p in other_street]


@pytest.mark.slow
def test_the_hashes_recorded_are_those_of_what_was_registered(street, tmp_path):
    """A scan file replaced after registration (a card copied again, a file still syncing):
    the result records the content registered, so that the export refuses the new file."""
    scans = tmp_path / "scans"
    scans.mkdir()
    files = [Path(shutil.copy(f, scans)) for f in street[:3]]
    registered = [file_hash(f) for f in files]
    out = tmp_path / "out"
    campaign = Campaign(Config(), out, WorkerPool(2))
    try:
        campaign.add_scans(files)
        shutil.copy(street[3], files[2])  # replaced in place, after registration
        result = campaign.result()
    finally:
        campaign.close()
    assert list(result.hashes) == registered
    write_chain_outputs(out, result, Config(), 1.0)
    assert json.loads((out / "summary.json").read_text())["scan_sha256"] == registered
    res = runner.invoke(export_app, [str(out), "--out", str(tmp_path / "c.laz"), "-q"])
    assert res.exit_code == 2 and "scan_2.laz" in _error_line(res.output)
    with pytest.raises(InputError, match="changed while the campaign was registered"):
        refuse_changed(result)  # what ndt-chain says before publishing


class _ChangesAFile:
    """Local worker processes; once the first task is done, a scan file is replaced (a file
    still being synced while the chain runs)."""

    ships_data = True

    def __init__(self, jobs: int, change: tuple[Path, Path]) -> None:
        self.pool, self.change = WorkerPool(jobs), change

    def start(self) -> None:
        self.pool.start()

    def run(self, tasks, then=None):
        for n, item in enumerate(self.pool.run(tasks, then)):
            if n == 0:
                shutil.copy(*self.change)
            yield item

    def close(self) -> None:
        self.pool.close()


@pytest.mark.slow
def test_a_file_changed_during_the_chain_is_exit_2(street, tmp_path):
    scans = tmp_path / "scans"
    scans.mkdir()
    files = [Path(shutil.copy(f, scans)) for f in street[:3]]
    executor = _ChangesAFile(1, (street[3], files[1]))
    with pytest.raises(InputError, match="changed while the campaign was registered") as caught:
        run_chain(files, Config(), tmp_path / "out", executor=executor)
    assert caught.value.path == files[1]


@pytest.mark.slow
def test_an_edited_link_or_scan_summary_is_registered_again(street, tmp_path):
    out = tmp_path / "out"
    assert runner.invoke(chain_app, [*map(str, street[:3]), "-o", str(out), "-q"]).exit_code == 0
    clean = (out / "poses.txt").read_text()
    links = sorted((out / "links").glob("[0-9a-f]*.json"))
    edited = links[0]
    record = json.loads(edited.read_text())
    record["result"]["T_target_source"][0][3] += 0.5  # still rigid: only the digest tells
    edited.write_text(json.dumps(record))
    summary = next((out / "links").glob("scan_*.npz"))
    with np.load(summary) as z:
        arrays = {name: z[name] for name in z.files}
    arrays["preview"] = arrays["preview"] + 1.0
    np.savez(summary, **arrays)
    res = runner.invoke(chain_app, [*map(str, street[:3]), "-o", str(out), "--resume"])
    assert res.exit_code == 0, res.output
    assert "changed since it was written" in res.output
    assert (out / "poses.txt").read_text() == clean
    assert json.loads((out / "summary.json").read_text())["reused"] == len(links) - 1


@pytest.mark.slow
def test_an_unreadable_first_scan_is_not_the_anchor(street, tmp_path):
    """An aborted copy landing first in the field: the first scan that can be read defines
    the world, and the good scans are ok in its cluster."""
    aborted = _truncated_laz(tmp_path / "aborted.laz")
    campaign = Campaign(Config(), tmp_path / "out", WorkerPool(2))
    try:
        campaign.add_scans([aborted, *street[:3]])
        result = campaign.result()
    finally:
        campaign.close()
    assert result.anchor == 1
    statuses = [s.status for s in result.solution.scans]
    assert statuses == [NodeStatus.UNPOSED] + [NodeStatus.OK] * 3, statuses
    assert all(s.cluster == 0 for s in result.solution.scans[1:])
    assert np.allclose(result.poses[1], np.eye(4), atol=1e-3)


@pytest.mark.slow
def test_a_scan_name_that_is_not_utf8_exports(street, tmp_path):
    scans = tmp_path / "scans"
    scans.mkdir()
    odd = scans / os.fsdecode(b"a_\xff\xfe.laz")
    shutil.copy(street[0], odd)
    files = [odd, Path(shutil.copy(street[1], scans))]
    out = tmp_path / "out"
    assert runner.invoke(chain_app, [*map(str, files), "-o", str(out), "-q"]).exit_code == 0
    res = runner.invoke(export_app, [str(out), "--out", str(tmp_path / "c.laz"), "-q"])
    assert res.exit_code == 0, res.output
    assert laspy.read(tmp_path / "c.laz").header.point_count > 0


def test_a_link_in_place_of_the_lock_is_refused_and_its_target_kept(tmp_path):
    out = tmp_path / "out"
    victim = tmp_path / "victim.txt"
    victim.write_text("kept")
    lock_path(out).symlink_to(victim)
    with pytest.raises(OutputError, match="a link or a folder"), output_lock(out, "a run"):
        pass
    assert victim.read_text() == "kept"
