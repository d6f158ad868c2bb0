"""Throughput of the NDT kernel (score, gradient, Hessian; + the Levenberg-Marquardt terms) in
point evaluations per second, against an estimate of its bound in core cycles."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.common import best_of, table
from ndt_cli.config import Config
from ndt_cli.core import threads as kernel_threads
from ndt_cli.core.transforms import yaw_of
from ndt_cli.ndt.kernels import MATCHED, accumulate
from ndt_cli.ndt.levels import SourceSampler, TargetMaps, source_points
from ndt_cli.ndt.prepare import ScanChunks, load_and_prepare_chunks

CYCLES, CYCLES_LM, CYCLES_MISS = 50, 70, 10  # estimated cycles per point evaluation


def _cases(cfg: Config, files: list[Path], gt: np.ndarray) -> tuple[TargetMaps, list[tuple]]:
    """The target's maps and (label, cell, source points, poses) of the two cases."""
    target = load_and_prepare_chunks(ScanChunks.of(files[0], cfg.input), cfg)
    source = load_and_prepare_chunks(ScanChunks.of(files[1], cfg.input), cfg)
    maps = TargetMaps(target.slices, cfg.grid)
    fine = SourceSampler(source.slices, cfg.source).fine
    coarse = source_points(source.slices, cfg.source.voxel, cfg.search.points_per_slice)
    L = target.to_local() @ gt @ source.from_local()
    truth = np.array([L[0, 3], L[1, 3], yaw_of(L)])
    rng = np.random.default_rng(0)
    near = truth + rng.normal(0, [0.2, 0.2, 0.002], (72, 3))
    offsets = np.column_stack([rng.uniform(-40, 40, (984, 2)), rng.uniform(-np.pi, np.pi, 984)])
    far = offsets + np.array([truth[0], truth[1], 0.0])
    cases = [
        ("fine: 72 poses near the solution, 1 m", 1.0, fine, near),
        ("search: 984 random poses, 20 m", 20.0, coarse, far),
    ]
    return maps, cases


def _rows(maps: TargetMaps, case: tuple, mhz: float) -> list[list[str]]:
    label, cell, src, params = case
    matched = accumulate(maps(cell), src, params, False)[:, MATCHED].sum()
    matched /= len(params) * len(src)
    rows = []
    threads_all = kernel_threads.initial()
    for lm in (False, True):
        accumulate(maps(cell), src, params, lm)  # compiled / warm
        for threads in sorted({1, threads_all}):
            kernel_threads.set_threads(threads)
            t = best_of(lambda m=lm: accumulate(maps(cell), src, params, m))
            evals = len(params) * len(src)
            rate = evals / t
            cycles = mhz * 1e6 * threads / rate  # core cycles per evaluation
            bound = matched * (CYCLES_LM if lm else CYCLES) + (1 - matched) * CYCLES_MISS
            terms = "newton+LM" if lm else "newton"
            rows.append([label, terms, str(threads), f"{evals / 1e6:.1f} M", f"{matched:.2f}"])
            rows[-1] += [
                f"{rate / 1e6:.0f}",
                f"{cycles:.0f}",
                f"{bound:.0f}",
                f"{bound / cycles:.0%}",
            ]
    kernel_threads.set_threads(threads_all)
    return rows


def kernel_throughput(cfg: Config, files: list[Path], gt: np.ndarray, mhz: float) -> None:
    """Point evaluations per second of the NDT kernel, at the solution (every point in a cell,
    as in the fine levels) and for a search batch of random poses."""
    maps, cases = _cases(cfg, files, gt)
    rows = [r for case in cases for r in _rows(maps, case, mhz)]
    print("## NDT kernel (score, gradient, Hessian; + LM terms): point evaluations per second\n")
    head = ["case", "terms", "threads", "evals", "in a cell", "M evals/s", "cycles/eval"]
    table([*head, "bound", "of bound"], rows)
    print(
        "Bound estimate (cycles per evaluation on one core): a point in a cell costs about 60\n"
        "floating-point operations (score, gradient, Hessian; ~95 with the LM terms) plus one\n"
        f"exp (~20 cycles): at 2 scalar operations a cycle ~{CYCLES} (~{CYCLES_LM} with LM);\n"
        f"a point outside any cell only its lookup (~{CYCLES_MISS}). The data of a pose fit in\n"
        "L1/L2 (source points 20 B each, cells 48 B): memory traffic does not bound the loop.\n"
    )
