"""The sample street's results, pinned: a refactor must not change a number of a result.

The golden files in ``tests/golden`` were written by ``ndt-chain sample_data/*.laz --jobs 2``
and ``ndt-register sample_data/scan_00.laz sample_data/scan_01.laz`` with the default
configuration. Every number is compared within 1e-9 (absolute, or relative for large values):
floating-point sums taken in another order on another CPU move the last digits, and a real
change moves far more. Everything else in the files (names, columns, order, comments, the
format of each number) must be the same character for character. Only ``runtime_s`` (wall
time) is left out. They were last rewritten when each scan's vertical came from its walls and
its slices from heights above a ground model, and the network from the evidence of agreement.
"""

from __future__ import annotations

import csv
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden"
SAMPLE = sorted(p.relative_to(ROOT) for p in (ROOT / "sample_data").glob("scan_*.laz"))
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}

pytestmark = pytest.mark.slow


NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|nan|inf")


def _same(actual: str, golden: str, what: str) -> None:
    """The texts agree character for character outside their numbers, and number for number
    within 1e-9 (absolute, or relative to the golden value)."""
    assert NUMBER.split(actual) == NUMBER.split(golden), f"{what}: the text differs"
    for a, g in zip(NUMBER.findall(actual), NUMBER.findall(golden), strict=True):
        if a != g:
            x, y = float(a), float(g)
            assert abs(x - y) <= 1e-9 * max(1.0, abs(y)), f"{what}: {a} != {g}"


def _without_runtime(path: Path) -> str:
    """A CSV file's text without its ``runtime_s`` column."""
    rows = list(csv.reader(path.read_text(encoding="utf-8").splitlines()))
    if "runtime_s" in rows[0]:
        drop = rows[0].index("runtime_s")
        rows = [row[:drop] + row[drop + 1 :] for row in rows]
    return "\n".join(",".join(row) for row in rows)


def _cli(script: str, *args: str) -> subprocess.CompletedProcess:
    """Run a command from the project folder (scan paths are reported as given)."""
    code = f"from ndt_cli.cli import {script}; {script}()"
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        cwd=ROOT,
        env=ENV,
        capture_output=True,
        text=True,
        check=False,
    )


def test_sample_chain_is_unchanged(tmp_path):
    out = tmp_path / "chain"
    res = _cli("chain_app", *map(str, SAMPLE), "--out", str(out), "--jobs", "2", "-q")
    assert res.returncode == 0, res.stderr
    golden = GOLDEN / "sample_chain"
    for name in ("poses.txt", "poses_chain.txt"):
        _same((out / name).read_text(), (golden / name).read_text(), name)
    for name in ("pairs.csv", "poses.csv"):
        _same(_without_runtime(out / name), _without_runtime(golden / name), name)
    links = sorted(p.name for p in golden.glob("T_*.txt"))
    assert sorted(p.name for p in out.glob("T_*.txt")) == links
    for name in links:
        _same((out / name).read_text(), (golden / name).read_text(), name)


def test_sample_pair_is_unchanged(tmp_path):
    out = tmp_path / "pair"
    res = _cli("register_app", str(SAMPLE[0]), str(SAMPLE[1]), "--out", str(out), "-q")
    assert res.returncode == 0, res.stderr
    golden = GOLDEN / "sample_pair"
    name = "T_target_source.txt"
    _same((out / name).read_text(), (golden / name).read_text(), name)
    _same(_without_runtime(out / "report.csv"), _without_runtime(golden / "report.csv"), "report")


def test_the_comparison_catches_a_change_and_tolerates_the_last_digits():
    _same("a 1.000000000000001 b\n", "a 1.0 b\n", "last digits")
    with pytest.raises(AssertionError):
        _same("a 1.0000001 b\n", "a 1.0 b\n", "a change")
    with pytest.raises(AssertionError):
        _same("a 1.0 c\n", "a 1.0 b\n", "a word")
