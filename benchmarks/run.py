"""Benchmarks: NDT kernel throughput and pair registration time on the sample data.

Run with ``make bench``. Figures are printed, never asserted. Times come from one process on a
shared machine: compare ratios within one run.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numba
import numpy as np

import ndt_cli
from ndt_cli.config import Config
from ndt_cli.engine import TargetMaps, source_points
from ndt_cli.kernels import evaluate
from ndt_cli.prepare import load_and_prepare

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"


def best_of(fn, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def kernel_throughput(cfg: Config) -> None:
    target = load_and_prepare(SAMPLE / "scan_00.laz", cfg)
    source = load_and_prepare(SAMPLE / "scan_01.laz", cfg)
    maps = TargetMaps(target, cfg)
    src = source_points(source, cfg, cfg.source.points_per_slice)
    print(f"source slice points: {len(src)}; cells at 2 m: {maps(2.0).n_cells}")
    print(f"{'case':<34}{'threads':>8}{'evals':>12}{'time (ms)':>12}{'M evals/s':>12}")
    for n_starts, label in [(1, "one pose (a Newton step)"), (64, "64 poses (a search batch)")]:
        rng = np.random.default_rng(0)
        params = np.column_stack([rng.normal(0, 1, (n_starts, 2)), rng.normal(0, 0.05, n_starts)])
        evaluate(maps(2.0), src, params)  # compile / warm
        for threads in sorted({1, numba.config.NUMBA_NUM_THREADS}):
            numba.set_num_threads(threads)
            t = best_of(lambda p=params: evaluate(maps(2.0), src, p))
            evals = n_starts * len(src)
            print(f"{label:<34}{threads:>8}{evals:>12,}{t * 1e3:>12.2f}{evals / t / 1e6:>12.1f}")
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def pair_time(cfg: Config) -> None:
    a, b = SAMPLE / "scan_00.laz", SAMPLE / "scan_01.laz"
    ndt_cli.register(a, b, cfg)  # warm
    t0 = time.perf_counter()
    result = ndt_cli.register(a, b, cfg)
    total = time.perf_counter() - t0
    print(f"\npair registration in-process (warm): {total:.2f} s")
    for level in result.levels:
        print(f"  cell {level.cell_size:>5g} m: {level.starts:>4} starts, {level.time_s:.3f} s")
    t0 = time.perf_counter()
    subprocess.run(
        [
            str(Path(sys.executable).parent / "ndt-register"),
            str(a),
            str(b),
            "--quiet",
            "--out",
            str(ROOT / "ndt_results" / "bench"),
        ],
        check=True,
    )
    print(f"ndt-register as a fresh process (cached kernels): {time.perf_counter() - t0:.2f} s")


def main() -> int:
    if not (SAMPLE / "scan_00.laz").exists():
        print("sample_data/ is missing: run `make sample-data`")
        return 2
    print(f"cores: {os.cpu_count()}, numba threads: {numba.config.NUMBA_NUM_THREADS}\n")
    cfg = Config()
    kernel_throughput(cfg)
    pair_time(cfg)
    return 0


if __name__ == "__main__":
    sys.exit(main())
