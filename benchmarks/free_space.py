"""The free-space check (:mod:`ndt_cli.ndt.visibility`) on and off, through the whole
registration with ICP, run by hand:

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/free_space.py [--street 24 --far 10]

The links of ``benchmarks/search_sweep.py`` (street links 12-30 m apart at any heading, far
links of scans two apart 34-48 m, corridor links), prepared by this code with their 3D points
(the check and ICP need them; the simulated scans are those the sweep caches). Printed per
kind and setting: links right against the simulator's true 6-DOF pose (within 0.3 deg /
15 cm), links ok, links ok but wrong, links where the check kept the second pose, and the
median time per link; then every link whose outcome differs.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.search_sweep import link_counts, simulated  # noqa: E402
from ndt_cli.config import Config  # noqa: E402
from ndt_cli.core.transforms import transform_errors  # noqa: E402
from ndt_cli.ndt.prepare import PreparedScan, prepare  # noqa: E402
from ndt_cli.ndt.register import register_prepared  # noqa: E402
from ndt_cli.ndt.result import Status  # noqa: E402

RIGHT_DEG, RIGHT_M = 0.3, 0.15
SETTINGS = {"on": Config(), "off": Config().replace(search={"free_space_ratio": 0.0})}


def _sequence(
    seed: int, n: int, spacing: tuple[float, float], corridor: bool
) -> tuple[list[PreparedScan], list[np.ndarray]]:
    """Scans prepared (with their 3D points) and true poses of one sequence."""
    scans, poses = simulated(seed, n, spacing, corridor)
    return [prepare(s, Config()) for s in scans], poses


Link = tuple[PreparedScan, PreparedScan, np.ndarray]  # target, source, true T_target_source


def links(n_street: int, n_far: int, n_corridor: int) -> list[tuple[str, str, Link]]:
    """(kind, name, (target, source, T_true)) of every link."""
    plan = [("street", s, 6, (12.0, 30.0), False, 1) for s in range(n_street)]
    plan += [("far", s, 4, (17.0, 24.0), False, 2) for s in range(100, 100 + n_far)]
    plan += [("corridor", s, 3, (12.0, 30.0), True, 1) for s in range(n_corridor)]
    out = []
    for kind, seed, n, spacing, corridor, step in plan:
        scans, poses = _sequence(seed, n, spacing, corridor)
        for i in range(n - step):
            truth = np.linalg.inv(poses[i]) @ poses[i + step]
            out.append((kind, f"{kind} s{seed} {i}-{i + step}", (scans[i], scans[i + step], truth)))
    return out


def run(
    target: PreparedScan, source: PreparedScan, truth: np.ndarray, cfg: Config
) -> tuple[bool, Status, bool, float]:
    """(right, status, second pose kept, seconds) of one registration."""
    t0 = time.perf_counter()
    r = register_prepared(target, source, cfg)
    dt = time.perf_counter() - t0
    rot, trans = transform_errors(r.T_target_source, truth)
    kept = any(w.startswith("free space") for w in r.warnings)
    return rot < RIGHT_DEG and trans < RIGHT_M, r.status, kept, dt


def main() -> None:
    todo = links(*link_counts())
    register_prepared(todo[0][2][0], todo[0][2][1], Config())  # compile
    rows = {name: [run(*lk, cfg) for _, _, lk in todo] for name, cfg in SETTINGS.items()}
    for kind in ("street", "far", "corridor"):
        sel = [k for k, (kd, _, _) in enumerate(todo) if kd == kind]
        print(f"\n{kind} links: {len(sel)}")
        for name, res in rows.items():
            sub = [res[k] for k in sel]
            right = sum(r[0] for r in sub)
            ok = sum(r[1] is Status.OK for r in sub)
            false_ok = sum(r[1] is Status.OK and not r[0] for r in sub)
            kept = sum(r[2] for r in sub)
            t = np.median([r[3] for r in sub])
            print(
                f"  check {name:<4} right {right:3d}/{len(sel)}  ok {ok:3d}  false ok {false_ok}  "
                f"second kept {kept:2d}  median {t:.2f} s"
            )
    print("\nlinks whose outcome differs (right, status):")
    for k, (_, name, _) in enumerate(todo):
        on, off = rows["on"][k], rows["off"][k]
        if on[:2] != off[:2]:
            print(f"  {name}: on {on[:2]}  off {off[:2]}")


if __name__ == "__main__":
    main()
