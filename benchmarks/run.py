"""Benchmarks of ndt-cli, printed as one report: command start-up and import time, a pair end to
end against a bare read of its files, a warm process against that read, the stages of a pair,
peer tools on the same pairs, the network of six scans, a pair at today's density (17 M points
a scan) as LAZ, LAS and E57 against a bare read, the same pair as other writers lay it out
(point formats 1, 3, 6, 7, scan-line order, extra bytes), its network of six scans, the
adjustment of a 1,000-scan network, campaigns of 16, 64 and 256 scans (in a walk and
shuffled) and field mode's latency (2 M and 17 M points a scan), the export, the NDT kernel's
throughput and reading at scale (LAS, and LAZ at 50 M points); then every figure against its
target.

Run with ``make bench``; ``--quick`` skips the slow parts (the 32 M / 50 M point files, the
peers, the export, the chain with one job and everything at today's density of 17 M points a
scan), ``--no-dense`` only the last, ``--export-50m`` adds the 50 M point export
(minutes). The data is made once into ``benchmarks/.cache`` (``benchmarks/data.py``). Figures
are printed, never asserted. Times come from a shared machine: every ratio is of two
measurements taken one right after the other in the same run.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import ndt_cli  # noqa: E402
from benchmarks import campaign_bench, data, dense, fresh, inprocess, writers  # noqa: E402
from benchmarks.common import (  # noqa: E402
    PY,
    RUN_BIN,
    RUN_VENV,
    TARGETS,
    byte_compile_package,
    cpu_mhz,
    table,
)
from benchmarks.kernel import kernel_throughput  # noqa: E402
from ndt_cli.config import Config  # noqa: E402
from ndt_cli.core.threads import threads as kernel_threads  # noqa: E402
from ndt_cli.io.matrices import read_pose_list  # noqa: E402


def pair_of(key: str, files: list[Path], poses_file: Path) -> fresh.Pair:
    """The first two scans of a street and their ground truth ``T_target_source``."""
    poses = read_pose_list(poses_file)
    gt = np.linalg.inv(poses[files[0].name]) @ poses[files[1].name]
    return fresh.Pair(key, files[0], files[1], gt)


def header(files: list[Path], small: list[Path], mhz: float) -> None:
    print(f"# ndt-cli {ndt_cli.__version__} benchmark\n")
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores at {mhz:.0f} MHz,"
        f" kernel threads {kernel_threads()}, Python {platform.python_version()}"
    )
    for label, fs in (("full density", files), ("a tenth of the rays", small)):
        counts = ", ".join(f"{data.las_points(f) / 1e6:.2f}" for f in fs)
        print(f"data, {label}: {len(fs)} simulated street scans, {counts} M points (LAS)")
    where, dev = RUN_BIN.parent.name, Path(PY).parent.parent.name
    plain = " (the runtime dependencies only)" if RUN_BIN.parent == RUN_VENV else ""
    print(f"fresh processes run in {where}{plain}; in-process sections in {dev}")
    print()


def targets() -> None:
    print("## Targets (figures of this run)\n")
    table(["figure", "measured", "target", "met"], TARGETS)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip 32/50 M, peers, export, --jobs 1")
    ap.add_argument("--export-50m", action="store_true", help="export 50 M points too (minutes)")
    ap.add_argument(
        "--no-dense", action="store_true", help="skip the 17 M-point pair and network (minutes)"
    )
    ap.add_argument(
        "--large-campaigns",
        action="store_true",
        help="1,000 scans in every order too (hours)",
    )
    args = ap.parse_args()
    files, poses_file = data.street()
    small_files, small_poses = data.street_small()
    pairs = [pair_of("full", files, poses_file), pair_of("small", small_files, small_poses)]
    mhz = cpu_mhz()
    header(files, small_files, mhz)
    byte_compile_package()
    fresh.startup()
    fresh.import_profile()
    fresh.first_and_second(pairs)
    best = fresh.pair_fresh(pairs, repeat=2 if args.quick else 3)
    dense.warm_process(pairs[0], best["full read"])
    fresh.compile_cold(pairs[0])
    inprocess.stage_times(pairs[0])
    if not args.quick:
        for p in pairs:
            inprocess.peers(p)
    fresh.network(pairs[0], files, poses_file, repeat=1 if args.quick else 2, jobs1=not args.quick)
    if not (args.quick or args.no_dense):
        dense_files, dense_poses = data.street_dense()
        dense.pairs(dense_files, dense_poses, repeat=2)
        writers.section(repeat=2)
        dense.network(dense_files[".laz"], dense_poses, repeat=1)
    inprocess.adjustment()
    campaign_bench.campaigns(
        args.quick, dense=not (args.quick or args.no_dense), large=args.large_campaigns
    )
    if not args.quick or args.export_50m:
        fresh.export(
            ([] if args.quick else [15_000_000]) + ([50_000_000] if args.export_50m else [])
        )
    kernel_throughput(Config(), files, pairs[0].gt, mhz)
    sizes = [500_000, 2_000_000, 8_000_000] + ([] if args.quick else [32_000_000, 50_000_000])
    fresh.scaling(
        files[0], [(n, ".las") for n in sizes] + [(50_000_000, ".laz")] * (not args.quick)
    )
    targets()
    return 0


if __name__ == "__main__":
    sys.exit(main())
