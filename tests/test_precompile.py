"""A first run compiles the search's kernels in a second process: the kernels it leaves in the
cache are the ones a registration loads, the result is the same, no process is left behind."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from ndt_cli.ndt import precompile

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
REGISTER = [sys.executable, "-c", "from ndt_cli.cli import register_app; register_app()"]

STATS = """
import json, sys
from ndt_cli.ndt import precompile as p
kernels = p.search_dispatchers() + p.level_dispatchers()
before = [p.cached(d) for d in kernels]
if sys.argv[1:]:
    import ndt_cli
    ndt_cli.register(sys.argv[1], sys.argv[2])
hits = [sum(d.stats.cache_hits.values()) for d in kernels]
misses = [sum(d.stats.cache_misses.values()) for d in kernels]
print(json.dumps({"cached": before, "hits": hits, "misses": misses}))
"""


def _cold_env(tmp_path: Path) -> dict[str, str]:
    return {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "OPENBLAS_NUM_THREADS": "1"}


def _stats(env: dict[str, str], *scans: Path) -> dict:
    run = subprocess.run(
        [sys.executable, "-c", STATS, *map(str, scans)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(run.stdout)


def test_cached_follows_the_cache_numba_writes(tmp_path, monkeypatch):
    """A kernel's index is found exactly once Numba has compiled and cached it."""
    (tmp_path / "fresh_kernel.py").write_text(
        "import numba\n\n\n@numba.njit(cache=True)\ndef twice(x):\n    return 2 * x\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    import fresh_kernel

    assert not precompile.cached(fresh_kernel.twice)
    assert fresh_kernel.twice(3) == 6
    assert precompile.cached(fresh_kernel.twice)


def test_an_error_in_the_block_stops_the_child(tmp_path):
    code = textwrap.dedent(
        """
        import os
        from ndt_cli.ndt.precompile import search_kernels_ahead

        def children():
            me, found = str(os.getpid()), []
            for pid in filter(str.isdigit, os.listdir("/proc")):
                try:
                    stat = open(f"/proc/{pid}/stat").read()
                except OSError:
                    continue
                if stat.rsplit(")", 1)[1].split()[1] == me:
                    found.append(pid)
            return found

        try:
            with search_kernels_ahead():
                print(len(children()))
                raise RuntimeError("stop")
        except RuntimeError:
            print(len(children()))
        """
    )
    env = _cold_env(tmp_path)
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.split() == ["1", "0"]


@pytest.mark.slow
def test_the_kernels_compiled_ahead_are_the_ones_a_registration_loads(tmp_path):
    env = _cold_env(tmp_path)
    empty = _stats(env)
    assert not any(empty["cached"])
    subprocess.run([sys.executable, "-m", "ndt_cli.ndt.precompile"], env=env, check=True)
    level = "from ndt_cli.ndt.precompile import compile_level_kernels; compile_level_kernels()"
    subprocess.run([sys.executable, "-c", level], env=env, check=True)
    after = _stats(env, SAMPLE / "scan_00.laz", SAMPLE / "scan_01.laz")
    assert all(after["cached"])
    assert after["misses"] == [0, 0, 0, 0]
    assert all(h >= 1 for h in after["hits"])


@pytest.mark.slow
def test_a_first_run_gives_the_result_of_a_warm_one(tmp_path):
    pair = [str(SAMPLE / "scan_00.laz"), str(SAMPLE / "scan_01.laz")]
    warm = subprocess.run([*REGISTER, *pair, "--out", str(tmp_path / "warm"), "--quiet"])
    cold = subprocess.run(
        [*REGISTER, *pair, "--out", str(tmp_path / "cold"), "--quiet"], env=_cold_env(tmp_path)
    )
    assert warm.returncode == cold.returncode == 0
    assert any((tmp_path / "cache").rglob("bnb_kernels._search_round-*.nbi"))
    T = "T_target_source.txt"
    assert (tmp_path / "cold" / T).read_bytes() == (tmp_path / "warm" / T).read_bytes()
