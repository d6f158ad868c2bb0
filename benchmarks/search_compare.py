"""The search methods compared through the whole registration, run by hand:

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/search_compare.py [--far 10]

On the links of ``benchmarks/search_sweep.py`` (120 street links 12-30 m apart at any heading,
far links of scans two apart 34-48 m, corridor links), every variant of ``search`` runs
``register_prepared`` (NDT only: ICP needs the 3D points the sweep's cache leaves out) and
prints its success rate (within 0.3 deg / 15 cm), its false ok rate (status ok but wrong),
and the median time per link and over the ``starts`` method's time of the same link.
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

from benchmarks.search_sweep import errors, link_counts, make_links  # noqa: E402
from ndt_cli.config import Config  # noqa: E402
from ndt_cli.core.transforms import yaw_of  # noqa: E402
from ndt_cli.ndt.register import register_prepared  # noqa: E402

VARIANTS = {
    "starts": {"method": "starts"},
    "bnb": {"method": "bnb", "fallback_ratio": 1.0},
    "bnb, fallback 0.95": {"method": "bnb", "fallback_ratio": 0.95},
    "bnb, fallback 0.9": {"method": "bnb", "fallback_ratio": 0.9},
}


def run(link, search: dict) -> tuple[bool, bool, float]:
    cfg = Config().replace(search=search, refine={"method": "none"})
    t0 = time.perf_counter()
    r = register_prepared(link.target, link.source, cfg)
    dt = time.perf_counter() - t0
    L = link.target.to_local() @ r.T_target_source @ link.source.from_local()
    err_m, err_deg = errors(np.array([L[0, 3], L[1, 3], yaw_of(L)]), link.truth)
    right = err_m < 0.15 and err_deg < 0.3
    return right, r.ok and not right, dt


def main() -> None:
    links = make_links(*link_counts())
    register_prepared(links[0].target, links[0].source, Config())  # compile
    rows = {name: [run(link, v) for link in links] for name, v in VARIANTS.items()}
    base = np.array([t for _, _, t in rows["starts"]])
    for kind in ("street", "far", "corridor"):
        sel = [k for k, link in enumerate(links) if link.kind == kind]
        print(f"\n{kind} links: {len(sel)}")
        for name, res in rows.items():
            right = sum(res[k][0] for k in sel)
            false_ok = sum(res[k][1] for k in sel)
            t = np.array([res[k][2] for k in sel])
            print(
                f"  {name:<20} right {right:3d}/{len(sel)}  false ok {false_ok}  "
                f"median {np.median(t):.2f} s  x starts {np.median(t / base[sel]):.2f}"
            )


if __name__ == "__main__":
    main()
