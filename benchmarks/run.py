"""Benchmarks: kernel throughput, per-stage and end-to-end times, peak memory, the reading
scaling curve and peer tools side by side, on full-density simulated street scans.

Run with ``make bench`` (``--quick`` skips the 32 M / 50 M point files and the peers). The data
is made once into ``benchmarks/.cache`` (see ``benchmarks/data.py``). Figures are printed, never
asserted. Times come from shared machines: compare ratios within one run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numba  # noqa: E402
import numpy as np  # noqa: E402

import ndt_cli  # noqa: E402
from benchmarks import data  # noqa: E402
from ndt_cli.config import Config  # noqa: E402
from ndt_cli.core.transforms import transform_errors, yaw_of  # noqa: E402
from ndt_cli.io.matrices import read_pose_list  # noqa: E402
from ndt_cli.ndt.kernels import MATCHED, accumulate  # noqa: E402
from ndt_cli.ndt.levels import SourceSampler, TargetMaps, source_points  # noqa: E402
from ndt_cli.ndt.prepare import ScanChunks, load_and_prepare_chunks  # noqa: E402
from ndt_cli.ndt.register import register_prepared  # noqa: E402
from ndt_cli.report.register_outputs import write_register_outputs  # noqa: E402

BIN = Path(sys.executable).parent
_CYCLES, _CYCLES_LM, _CYCLES_MISS = 50, 70, 10  # estimated cycles per point evaluation
OUT = data.CACHE / "results"


def best_of(fn, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def measured(cmd: list[str], env: dict[str, str] | None = None) -> dict:
    """Wall time, exit code and peak memory of ``cmd`` run as a fresh child process."""
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "measure.py"), *cmd],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def table(header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows, strict=True)]
    for r in [header, ["-" * w for w in widths], *rows]:
        print("  ".join(str(x).ljust(w) for x, w in zip(r, widths, strict=True)).rstrip())
    print()


def cpu_mhz() -> float:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("cpu MHz"):
                return float(line.split(":")[1])
    except OSError:
        pass
    return float("nan")


# --------------------------------------------------------------------------------- sections


def kernel_throughput(cfg: Config, files: list[Path], gt: np.ndarray, mhz: float) -> None:
    """Point evaluations per second of the NDT kernel, at the solution (every point in a cell,
    as in the fine levels) and for a search batch of random poses."""
    target = load_and_prepare_chunks(ScanChunks.of(files[0], cfg.input), cfg)
    source = load_and_prepare_chunks(ScanChunks.of(files[1], cfg.input), cfg)
    maps = TargetMaps(target.slices, cfg.grid)
    fine = SourceSampler(source.slices, cfg.source).fine
    coarse = source_points(source.slices, cfg.source.voxel, cfg.search.points_per_slice)
    L = target.to_local() @ gt @ source.from_local()
    truth = np.array([L[0, 3], L[1, 3], yaw_of(L)])
    rng = np.random.default_rng(0)
    offsets = np.column_stack([rng.uniform(-40, 40, (984, 2)), rng.uniform(-np.pi, np.pi, 984)])
    cases = [
        (
            "fine: 72 poses near the solution, 1 m",
            1.0,
            fine,
            truth + rng.normal(0, [0.2, 0.2, 0.002], (72, 3)),
        ),
        (
            "search: 984 random poses, 20 m",
            20.0,
            coarse,
            offsets + np.array([truth[0], truth[1], 0.0]),
        ),
    ]
    rows = []
    threads_all = numba.config.NUMBA_NUM_THREADS
    for label, cell, src, params in cases:
        matched = accumulate(maps(cell), src, params)[:, MATCHED].sum() / (len(params) * len(src))
        for lm in (False, True):
            accumulate(maps(cell), src, params, lm)  # compiled / warm
            for threads in sorted({1, threads_all}):
                numba.set_num_threads(threads)
                t = best_of(lambda c=cell, s=src, p=params, m=lm: accumulate(maps(c), s, p, m))
                evals = len(params) * len(src)
                rate = evals / t
                cycles = mhz * 1e6 * threads / rate  # core cycles per evaluation
                bound = matched * (_CYCLES_LM if lm else _CYCLES) + (1 - matched) * _CYCLES_MISS
                rows.append(
                    [
                        label,
                        "newton" if not lm else "newton+LM",
                        str(threads),
                        f"{evals / 1e6:.1f} M",
                        f"{matched:.2f}",
                        f"{rate / 1e6:.0f}",
                        f"{cycles:.0f}",
                        f"{bound:.0f}",
                        f"{bound / cycles:.0%}",
                    ]
                )
    numba.set_num_threads(threads_all)
    print("## NDT kernel (score, gradient, Hessian; + LM terms): point evaluations per second\n")
    table(
        [
            "case",
            "terms",
            "threads",
            "evals",
            "in a cell",
            "M evals/s",
            "cycles/eval",
            "bound",
            "of bound",
        ],
        rows,
    )
    print(
        "Bound estimate (cycles per evaluation on one core): a point in a cell costs about 60\n"
        "floating-point operations (score, gradient, Hessian; ~95 with the LM terms) plus one\n"
        f"exp (~20 cycles): at 2 scalar operations a cycle ~{_CYCLES} (~{_CYCLES_LM} with LM);\n"
        f"a point outside any cell only its lookup (~{_CYCLES_MISS}). The data of a pose fit in\n"
        "L1/L2 (source points 20 B each, cells 48 B): memory traffic does not bound the loop.\n"
    )


def stage_times(cfg: Config, files: list[Path], gt: np.ndarray) -> None:
    a, b = files[0], files[1]
    ndt_cli.register(a, b, cfg)  # warm
    t0 = time.perf_counter()
    chunks = [ScanChunks.of(f, cfg.input) for f in (a, b)]
    t_read = time.perf_counter() - t0
    t0 = time.perf_counter()
    scans = [load_and_prepare_chunks(c, cfg) for c in chunks]
    t_prepare = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = register_prepared(scans[0], scans[1], cfg)
    t_register = time.perf_counter() - t0
    t0 = time.perf_counter()
    write_register_outputs(OUT / "stages", result, cfg)
    t_write = time.perf_counter() - t0
    tm = result.timings
    search = result.levels[0].time_s
    rows = [
        ["read (2 files)", f"{t_read:.3f}"],
        ["ground, levelling, slices, ICP thinning (2 scans)", f"{t_prepare:.3f}"],
        ["grid build (all cell sizes)", f"{tm['grid_s']:.3f}"],
        [f"optimise: search at {result.levels[0].cell_size:g} m", f"{search:.3f}"],
        ["optimise: finer levels and evidence", f"{tm['ndt_s'] - search:.3f}"],
        ["refine (ICP)", f"{tm['refine_s']:.3f}"],
        ["write outputs", f"{t_write:.3f}"],
        ["total", f"{t_read + t_prepare + t_register + t_write:.3f}"],
    ]
    rot, trans = transform_errors(result.T_target_source, gt)
    print(f"## Stages of one pair in-process, warm ({a.name} + {b.name})\n")
    table(["stage", "time (s)"], rows)
    print(f"result: {result.status}, error {rot:.4f} deg / {trans * 100:.2f} cm\n")


def end_to_end(files: list[Path]) -> None:
    a, b = map(str, files[:2])
    out = str(OUT / "e2e")
    reg = [str(BIN / "ndt-register"), a, b, "--quiet", "--out", out]
    rows = []
    help_s = min(measured([str(BIN / "ndt-register"), "--help"])["wall_s"] for _ in range(3))
    rows.append(["ndt-register --help", f"{help_s:.2f}", ""])
    with tempfile.TemporaryDirectory() as cache:  # an empty Numba cache: everything compiles
        cold = measured(reg, {"NUMBA_CACHE_DIR": cache})
        before = {p: p.stat().st_mtime_ns for p in Path(cache).rglob("*")}
        warm = [measured(reg, {"NUMBA_CACHE_DIR": cache}) for _ in range(3)]
        after = {p: p.stat().st_mtime_ns for p in Path(cache).rglob("*")}
    rows.append(
        [
            "ndt-register, first run ever (compiles)",
            f"{cold['wall_s']:.2f}",
            f"{cold['peak_mb']:.0f}",
        ]
    )
    best = min(warm, key=lambda r: r["wall_s"])
    rows.append(
        [
            "ndt-register, fresh process, cached kernels",
            f"{best['wall_s']:.2f}",
            f"{best['peak_mb']:.0f}",
        ]
    )
    scans = [str(f) for f in files]
    for jobs in (1, 2):
        r = measured(
            [
                str(BIN / "ndt-chain"),
                *scans,
                "--jobs",
                str(jobs),
                "--quiet",
                "--out",
                str(OUT / f"chain{jobs}"),
            ]
        )
        rows.append(
            [
                f"ndt-chain of {len(files)} scans, --jobs {jobs}",
                f"{r['wall_s']:.2f}",
                f"{r['peak_mb']:.0f}",
            ]
        )
    print("## End to end (fresh processes; peak memory of the largest process)\n")
    table(["run", "wall (s)", "peak (MB)"], rows)
    hit = "yes" if before == after else "no (the cache changed)"
    print(f"second process reused the compiled kernels without compiling: {hit}\n")


def scaling(base: Path, sizes: list[int]) -> None:
    rows = []
    for n in sizes:
        f = data.tiled(base, n)
        code = (
            "import time; from ndt_cli.config import Config; "
            "from ndt_cli.ndt.prepare import load_and_prepare; t = time.perf_counter(); "
            f"load_and_prepare({str(f)!r}, Config()); print(time.perf_counter() - t)"
        )
        r = measured([sys.executable, "-c", code])
        inner = float(r["last"])
        rows.append(
            [
                f"{n / 1e6:g} M",
                f"{f.stat().st_size / 2**20:.0f}",
                f"{inner:.2f}",
                f"{n / inner / 1e6:.1f}",
                f"{r['wall_s']:.2f}",
                f"{r['peak_mb']:.0f}",
            ]
        )
    print("## Reading and preparing one LAS file: read, ground, levelling, slices, ICP thinning")
    print("(each in a fresh process; 'prepare' is the call itself, 'process' adds start-up)\n")
    table(["points", "file (MB)", "prepare (s)", "M points/s", "process (s)", "peak (MB)"], rows)


def peers(files: list[Path], gt: np.ndarray) -> None:
    from benchmarks.peers import errors, guess_label, peer_rows, perturbed_guess
    from ndt_cli import io

    target, source = io.read(files[0]).points, io.read(files[1]).points
    ndt_cli.register(target, source)  # warm
    ours = []
    for label, init in [("no guess", None), (guess_label(1.0, 2.0), perturbed_guess(gt, 1, 2))]:
        t0 = time.perf_counter()
        r = ndt_cli.register(target, source, init=init)
        wall = time.perf_counter() - t0
        rot, trans = errors(r.T_target_source, gt)
        ours.append(
            {
                "peer": f"ndt-cli {ndt_cli.__version__}",
                "start": label,
                "wall_s": wall,
                "rot_err_deg": rot,
                "trans_err_m": trans,
                "note": r.status,
            }
        )
    rows = []
    mine = {row["start"]: row["wall_s"] for row in ours}
    for row in ours + peer_rows(target, source, gt):
        ratio = mine[row["start"]] / row["wall_s"] if np.isfinite(row["wall_s"]) else float("nan")
        rows.append(
            [
                row["peer"],
                row["start"],
                f"{row['wall_s']:.2f}",
                f"{row['rot_err_deg']:.3f}",
                f"{row['trans_err_m']:.3f}",
                f"{ratio:.2f}",
                row["note"],
            ]
        )
    n = f"{len(target):,} + {len(source):,}"
    print(f"## Peers on the same pair ({n} points, arrays in memory)\n")
    table(
        ["tool", "start", "wall (s)", "rot err (deg)", "trans err (m)", "ndt-cli/peer", "note"],
        rows,
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip 32/50 M points and the peers")
    args = ap.parse_args()
    files, poses_file = data.street()
    poses = read_pose_list(poses_file)
    gt = np.linalg.inv(poses[files[0].name]) @ poses[files[1].name]
    mhz = cpu_mhz()
    print(f"# ndt-cli {ndt_cli.__version__} benchmark\n")
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores at {mhz:.0f} MHz,"
        f" Numba threads {numba.config.NUMBA_NUM_THREADS}, Python {platform.python_version()}"
    )
    print(
        f"data: {len(files)} simulated street scans, "
        f"{', '.join(f'{data.las_points(f) / 1e6:.2f}' for f in files)} M points (LAS)\n"
    )
    cfg = Config()
    kernel_throughput(cfg, files, gt, mhz)
    stage_times(cfg, files, gt)
    end_to_end(files)
    sizes = [500_000, 2_000_000, 8_000_000] + ([] if args.quick else [32_000_000, 50_000_000])
    scaling(files[0], sizes)
    if not args.quick:
        peers(files, gt)
    return 0


if __name__ == "__main__":
    sys.exit(main())
