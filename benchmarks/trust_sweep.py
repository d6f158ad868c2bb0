"""The trust sweep: ``ndt-chain``'s verdicts in worlds unlike the street the defaults were
tuned on, against ground truth, run by hand or by ``make trust``:

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/trust_sweep.py [--quick]
        [--world streets|interiors|forests|districts|shuffled|guessed] [--only TEXT]

Six worlds: streets (varied clean streets, hostile cases and the real MULLS sequence:
``benchmarks/trust_cases.py``), building interiors, forests, city districts and long routes
given in shuffled order (``benchmarks/trust_worlds.py``), and scans of them with approximate
poses (``--init-poses``: ``benchmarks/trust_guessed.py``). Printed per case, and totalled per
world (clean and hostile cases apart): scans ok, false alarms (a scan that should be ok and is
not; a correct link not ok), wrong ok (an ok scan or link that is not correct: within 0.1 deg
/ 5 cm,
:mod:`ndt_cli.analysis.trust`), scans split off the anchor's cluster, links the network kept
that are wrong, the error of the NDT result before ICP and of each scan's vertical. Simulated
scans are cached in ``benchmarks/.cache/trust``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.trust_cases import CACHE, Case, cross_scene_pairs, street_cases  # noqa: E402
from benchmarks.trust_guessed import guessed_cases  # noqa: E402
from benchmarks.trust_worlds import (  # noqa: E402
    district_cases,
    forest_cases,
    interior_cases,
    route_cases,
)
from ndt_cli.analysis import trust  # noqa: E402
from ndt_cli.config import Config  # noqa: E402
from ndt_cli.ndt.result import Status  # noqa: E402
from ndt_cli.pipeline.chain import run_chain  # noqa: E402
from ndt_cli.pipeline.options import NetworkOptions  # noqa: E402
from ndt_cli.pipeline.verify import NodeStatus  # noqa: E402

WORLDS: dict[str, Callable[[bool], list[Case]]] = {
    "streets": street_cases,
    "interiors": interior_cases,
    "forests": forest_cases,
    "districts": district_cases,
    "shuffled": route_cases,
    "guessed": guessed_cases,
}


def run_case(case: Case, cfg: Config, jobs: int) -> tuple[trust.TrustCounts, dict]:
    """Chain the case's scans and judge the verdicts against the truth."""
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        network = NetworkOptions(init_poses=case.guesses) if case.guesses else None
        result = run_chain(case.files, cfg, out, jobs=jobs, network=network)
        elapsed = time.perf_counter() - t0
    links = trust.link_truths(result, case.truth)
    scans = trust.scan_truths(result, case.truth)
    counts = trust.count(links, scans, case.expected)
    good = [x for x in links if x.correct]
    ndt_rot = [x.ndt_rot_deg for x in good if np.isfinite(x.ndt_rot_deg)]
    ndt_trans = [x.ndt_trans_m for x in good if np.isfinite(x.ndt_trans_m)]
    vertical = [s.vertical_deg for s in scans if np.isfinite(s.vertical_deg)]
    rows = [
        {
            "case": case.name,
            "target": x.target,
            "source": x.source,
            "kind": x.kind,
            "correct": x.correct,
            "rot_deg": x.rot_deg,
            "trans_m": x.trans_m,
            "status": x.status.value,
            "state": x.state.value,
            "distance_m": float(
                np.linalg.norm(case.truth[x.target][:3, 3] - case.truth[x.source][:3, 3])
            ),
            **(trust.metrics(link.result) if link.result is not None else {}),
            "warnings": link.reason,
            "candidates": json.dumps(
                []
                if link.result is None
                else trust.candidates(
                    link.result, np.linalg.inv(case.truth[x.target]) @ case.truth[x.source]
                )
            ),
        }
        for x, link in zip(links, result.links, strict=True)
    ]
    detail = {
        "rows": rows,
        "time_s": elapsed,
        "ndt_deg": max(ndt_rot, default=float("nan")),
        "ndt_cm": 100 * max(ndt_trans, default=float("nan")),
        "vertical_deg": max(vertical, default=float("nan")),
        "bad_links": [
            x
            for x in links
            if (x.correct and x.status is not Status.OK)
            or (not x.correct and x.status is Status.OK)
        ],
        "scans": scans,
        "bad_scans": [
            x
            for x, e in zip(scans, case.expected, strict=True)
            if (e and x.status is not NodeStatus.OK)
            or (x.status is NodeStatus.OK and not x.correct)
            or (e and x.cluster != 0)
        ],
    }
    return counts, detail


def _label(name: str, width: int = 88) -> str:
    """The case's name cut after its last whole item that fits in ``width`` characters."""
    cut = name.rfind(", ", 0, width)
    return name if len(name) <= width else name[: cut if cut > 0 else width]


def _row(name: str, c: trust.TrustCounts, d: dict) -> str:
    return (
        f"{_label(name):88s} scans {c.scans_ok:2d}/{c.scans:2d} ok, "
        f"FA {c.scan_false_alarms:2d}, "
        f"wrong ok {c.scan_wrong_ok}, split {c.scans_split} | "
        f"links {c.links_ok:2d}/{c.links:2d} ok, "
        f"FA {c.link_false_alarms:2d}, wrong ok {c.link_wrong_ok}, wrong kept "
        f"{c.link_wrong_kept} | NDT {d['ndt_deg']:.3f} deg {d['ndt_cm']:.1f} cm | vertical "
        f"{d['vertical_deg']:.3f} deg | {d['time_s']:.0f} s"
    )


def _write(path: Path, rows: list[dict]) -> None:
    """Every link's row as CSV (columns: the union of the rows' keys, in first-seen order)."""
    import csv

    names = list(dict.fromkeys(k for r in rows for k in r))
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, names)
        w.writeheader()
        w.writerows(rows)
    print(f"links: {path}")


def _details(detail: dict) -> None:
    """Every wrong verdict of a case (``--verbose``)."""
    for x in detail["bad_links"]:
        print(
            f"    link {x.target}-{x.source} {x.kind} {x.status.value} "
            f"{x.state.value}: {x.rot_deg:.3f} deg {100 * x.trans_m:.1f} cm"
        )
    for x in detail["bad_scans"]:
        print(
            f"    scan {x.index} {x.status.value} cluster {x.cluster}: "
            f"{x.rot_deg:.3f} deg {100 * x.trans_m:.1f} cm"
        )


def _total(label: str, c: trust.TrustCounts) -> str:
    return (
        f"TOTAL {label}: scans {c.scans_ok}/{c.scans} ok, false alarms {c.scan_false_alarms}, "
        f"wrong ok {c.scan_wrong_ok}, split off the anchor's cluster {c.scans_split}; "
        f"links {c.links_correct} correct, "
        f"{c.link_false_alarms} false alarms "
        f"({c.link_false_alarms / max(c.links_correct, 1):.1%} of correct), "
        f"{c.link_wrong_ok} wrong ok, {c.link_wrong_kept} wrong kept"
    )


def _run_world(name: str, args: argparse.Namespace, cfg: Config, rows: list[dict]) -> dict:
    """Run one world's cases; returns its totals by kind (clean, hostile)."""
    total: dict[str, trust.TrustCounts] = {}
    print(f"== {name}", flush=True)
    for case in WORLDS[name](args.quick):
        if args.only and args.only not in case.name:
            continue
        counts, detail = run_case(case, cfg, args.jobs)
        rows += detail["rows"]
        clean = all(case.expected) and "real" not in case.name and not case.hostile
        kind = "clean" if clean else "hostile"
        total[kind] = total.get(kind, trust.TrustCounts()) + counts
        print(_row(case.name, counts, detail), flush=True)
        if args.verbose:
            _details(detail)
    return total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the reduced tier")
    ap.add_argument("--world", choices=list(WORLDS), help="run this world only (default: all)")
    ap.add_argument("--only", default="", help="run the cases whose name contains this")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("-v", "--verbose", action="store_true", help="list every wrong verdict")
    ap.add_argument("--cross", type=int, default=12, help="cross-scene pairs (streets)")
    ap.add_argument(
        "--links",
        type=Path,
        default=CACHE / "links.csv",
        help="where every link's metrics and truth are written (CSV)",
    )
    args = ap.parse_args()
    rows: list[dict] = []
    cfg = Config()
    totals = {}
    for name in [args.world] if args.world else list(WORLDS):
        totals[name] = _run_world(name, args, cfg, rows)
        if name == "streets" and args.cross:
            cross = cross_scene_pairs(cfg, args.cross)
            rows += cross
            ok = sum(r["status"] is Status.OK for r in cross)
            print(f"cross-scene pairs: {ok}/{len(cross)} ok (must be 0)", flush=True)
    _write(args.links, rows)
    for name, by_kind in totals.items():
        for kind, c in by_kind.items():
            print(_total(f"{name} {kind}", c))


if __name__ == "__main__":
    main()
