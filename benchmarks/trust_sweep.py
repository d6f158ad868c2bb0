"""The trust sweep: ``ndt-chain``'s verdicts on streets unlike the one the defaults were tuned
on, against ground truth, run by hand or by ``make trust``:

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/trust_sweep.py [--quick] [--only NAME]

Clean streets (at least 8 scans each) vary the ground (grades up to 8 %, vertical curves,
camber, cross-fall), the scanners (tilted up to 1 deg, or compensated), the density (0.2 M and
2 M points a scan), the spacing (up to 35 m), the clutter (trees, people, passing cars) and
the shape (bends); hostile cases put a scan of another street or a truncated scan in the
middle of a street, run a corridor of uniform facades, append scans of another street, and
register scans of different streets directly. The real MULLS street sequence (``../shared``)
is compared with its published ICP reference. Printed per case and in total: scans ok, false
alarms (a scan that should be ok and is not; a correct link not ok), wrong ok (an ok scan or
link that is not correct: within 0.1 deg / 5 cm, :mod:`ndt_cli.analysis.trust`), links the
network kept that are wrong, the error of the NDT result before ICP and of each scan's
vertical. Simulated scans are cached in ``benchmarks/.cache/trust``.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from ndt_cli import io, sim  # noqa: E402
from ndt_cli.analysis import trust  # noqa: E402
from ndt_cli.config import Config  # noqa: E402
from ndt_cli.ndt.prepare import prepare  # noqa: E402
from ndt_cli.ndt.register import register_prepared  # noqa: E402
from ndt_cli.ndt.result import Status  # noqa: E402
from ndt_cli.pipeline.chain import run_chain  # noqa: E402
from ndt_cli.pipeline.verify import NodeStatus  # noqa: E402
from ndt_cli.sim.worlds import DENSE, StreetWorld  # noqa: E402

CACHE = ROOT / "benchmarks" / ".cache" / "trust"
SHARED = ROOT.parent / "shared" / "data"


def clean_streets() -> list[StreetWorld]:
    """At least 20 clean streets of at least 8 scans across the parameters."""
    W = StreetWorld
    return [
        W(seed=1, grade=0.02, camber=0.02, tilt_deg=0.5),
        W(seed=2, grade=0.03, camber=0.025, tilt_deg=0.3, rays=DENSE, n_scans=6 + 2),
        W(seed=3, grade=0.05, curve=0.0003, cross_fall=0.015, tilt_deg=0.8),
        W(seed=4, grade=0.08, camber=0.03, tilt_deg=1.0),
        W(seed=5, grade=-0.07, curve=-0.0004, camber=0.02, tilt_deg=1.0, spacing=(15, 30)),
        W(seed=6, grade=0.04, camber=0.035, compensated=True),
        W(seed=7, grade=0.06, cross_fall=0.025, tilt_deg=0.6, trees=True),
        W(seed=8, grade=0.04, camber=0.02, tilt_deg=0.5, people=15, traffic=1, trees=True),
        W(seed=9, grade=0.05, camber=0.03, tilt_deg=0.7, people=25, traffic=2, spacing=(15, 35)),
        W(seed=10, grade=0.02, curve=0.0005, camber=0.025, tilt_deg=0.4, bend_deg=20),
        W(seed=11, grade=0.03, camber=0.02, tilt_deg=0.6, bend_deg=-30, n_scans=16),
        W(seed=12, grade=0.0, camber=0.03, tilt_deg=0.9, spacing=(20, 35)),
        W(seed=13, grade=0.07, curve=-0.0003, tilt_deg=0.3, rays=DENSE),
        W(seed=14, grade=0.01, cross_fall=0.02, compensated=True, trees=True, people=10),
        W(seed=15, grade=0.06, camber=0.035, tilt_deg=1.0, spacing=(20, 35), people=20),
        W(seed=16, grade=-0.04, camber=0.015, tilt_deg=0.5, bend_deg=15, trees=True),
        W(seed=17, grade=0.05, curve=0.0004, cross_fall=0.01, tilt_deg=0.8, n_scans=12),
        W(seed=18, grade=0.08, camber=0.02, compensated=True, spacing=(15, 30)),
        W(seed=19, grade=0.03, camber=0.03, tilt_deg=0.5, rays=(1000, 120)),
        W(seed=20, grade=0.04, camber=0.025, tilt_deg=0.6, rays=DENSE, people=20, traffic=2),
        W(seed=21, grade=-0.02, curve=0.0005, camber=0.01, tilt_deg=1.0, bend_deg=35),
        W(seed=22, grade=0.0, tilt_deg=0.0),
        W(
            seed=23,
            grade=0.06,
            camber=0.02,
            tilt_deg=0.7,
            trees=True,
            people=20,
            traffic=2,
            spacing=(20, 35),
            n_scans=10,
        ),
        W(seed=24, grade=0.03, camber=0.035, tilt_deg=0.4, spacing=(13, 22), n_scans=12),
    ]


def quick_streets() -> list[StreetWorld]:
    """The reduced tier (``--quick``, and the tests): three varied sparse streets."""
    W = StreetWorld
    return [
        W(seed=31, grade=0.05, curve=0.0003, camber=0.025, tilt_deg=0.8),
        W(seed=32, grade=-0.06, camber=0.03, tilt_deg=0.6, people=15, traffic=1, trees=True),
        W(seed=33, grade=0.03, cross_fall=0.02, compensated=True, bend_deg=20),
    ]


@dataclass(frozen=True)
class Case:
    """A campaign to run: its scans (files), true poses, which scans should come out ok."""

    name: str
    files: list[Path]
    truth: list[np.ndarray]
    expected: list[bool]


def simulated(world: StreetWorld) -> tuple[list[Path], list[np.ndarray]]:
    """The world's scans as LAS files and their true poses, cached."""
    sim_dir = ROOT / "ndt_cli" / "sim"  # what a street's scans depend on
    sources = [sim_dir / f"{m}.py" for m in ("ground", "scene", "scanner", "worlds")]
    key = hashlib.sha256(b"".join(f.read_bytes() for f in sources) + repr(world).encode())
    folder = CACHE / f"s{world.seed}_{key.hexdigest()[:12]}"
    files = [folder / f"scan_{k:02d}.las" for k in range(world.n_scans)]
    poses_file = folder / "poses.npy"
    if poses_file.exists() and all(f.exists() for f in files):
        return files, list(np.load(poses_file))
    folder.mkdir(parents=True, exist_ok=True)
    print(f"  simulating {world.describe()} ...", flush=True)
    _, scans, poses = sim.scan_street(world)
    for f, pts in zip(files, scans, strict=True):
        io.write(f, pts)
    np.save(poses_file, np.array(poses))
    return files, poses


def clean_case(world: StreetWorld) -> Case:
    files, truth = simulated(world)
    return Case(world.describe(), files, truth, [True] * len(files))


def foreign_case(seed: int) -> Case:
    """A sparse street with the middle scan taken from another street."""
    files, truth = simulated(StreetWorld(seed=seed, grade=0.04, camber=0.025, tilt_deg=0.5))
    other, _ = simulated(StreetWorld(seed=seed + 500, n_scans=2, grade=-0.03, tilt_deg=0.5))
    mid = len(files) // 2
    files = [*files[:mid], other[0], *files[mid + 1 :]]
    expected = [k != mid for k in range(len(files))]
    return Case(f"seed {seed}: a scan of another street in the middle", files, truth, expected)


def truncated_case(seed: int) -> Case:
    """A sparse street whose middle scan keeps only a 60 degree sector of its points."""
    files, truth = simulated(StreetWorld(seed=seed, grade=0.05, camber=0.02, tilt_deg=0.6))
    mid = len(files) // 2
    pts = io.read(files[mid]).points
    az = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
    cut = files[mid].with_name("truncated.las")
    if not cut.exists():
        io.write(cut, pts[np.abs(az) < 30.0])
    files = [*files[:mid], cut, *files[mid + 1 :]]
    expected = [k != mid for k in range(len(files))]
    return Case(f"seed {seed}: a truncated scan in the middle", files, truth, expected)


def corridor_case(seed: int) -> Case:
    """Uniform facades: the position along the corridor is unobservable (only the anchor
    should be ok)."""
    files, truth = simulated(StreetWorld(seed=seed, corridor=True, grade=0.03, tilt_deg=0.5))
    expected = [k == 0 for k in range(len(files))]
    return Case(f"seed {seed}: corridor", files, truth, expected)


def two_streets_case(seed: int) -> Case:
    """Eight scans of one street, then four of another (only the first street in the anchor's
    frame)."""
    a, ta = simulated(StreetWorld(seed=seed, grade=0.03, camber=0.02, tilt_deg=0.5))
    b, tb = simulated(StreetWorld(seed=seed + 500, n_scans=4, grade=-0.05, tilt_deg=0.5))
    far = np.eye(4)
    far[:3, 3] = (5000.0, 0.0, 0.0)  # never correct in the anchor's frame
    expected = [True] * len(a) + [False] * len(b)
    return Case(f"seed {seed}: two streets", [*a, *b], [*ta, *[far @ T for T in tb]], expected)


def mulls_case() -> Case | None:
    folder = SHARED / "mulls_demo_hdl64_sequence"
    if not folder.is_dir():
        return None
    rel = np.loadtxt(folder / "reference_icp_relative_4x4.txt").reshape(-1, 4, 4)
    poses = [np.eye(4)]
    for T in rel:
        poses.append(poses[-1] @ T)
    files = sorted(folder.glob("*.pcd"))
    return Case("real: MULLS HDL-64 street (ICP reference)", files, poses, [True] * len(files))


def run_case(case: Case, cfg: Config, jobs: int) -> tuple[trust.TrustCounts, dict]:
    """Chain the case's scans and judge the verdicts against the truth."""
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        result = run_chain(case.files, cfg, out, jobs=jobs)
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


def cross_scene_pairs(cfg: Config, n: int = 12) -> list[dict]:
    """Scans of different streets registered directly (every one wrong): a row per pair."""
    worlds = quick_streets() + clean_streets()[: max(3, n // 4)]
    files = [simulated(w)[0] for w in worlds]
    m = len(files)
    rows = []
    for k in range(n):
        a, b = files[k % m][k // m % 3], files[(k + 1 + k // m) % m][(k + 1) % 3]
        pa, pb = (prepare(io.read(f).points, cfg, f) for f in (a, b))
        r = register_prepared(pa, pb, cfg)
        rows.append(
            {
                "case": "cross-scene",
                "target": 0,
                "source": 1,
                "kind": "cross",
                "correct": False,
                "status": r.status,  # written as its value
                "state": "",
                **trust.metrics(r),
                "warnings": "; ".join(r.warnings),
            }
        )
    return rows


def _row(name: str, c: trust.TrustCounts, d: dict) -> str:
    return (
        f"{name[:62]:62s} scans {c.scans_ok:2d}/{c.scans:2d} ok, "
        f"FA {c.scan_false_alarms:2d}, "
        f"wrong ok {c.scan_wrong_ok}, split {c.scans_split} | "
        f"links {c.links_ok:2d}/{c.links:2d} ok, "
        f"FA {c.link_false_alarms:2d}, wrong ok {c.link_wrong_ok}, wrong kept "
        f"{c.link_wrong_kept} | NDT {d['ndt_deg']:.3f} deg {d['ndt_cm']:.1f} cm | vertical "
        f"{d['vertical_deg']:.3f} deg | {d['time_s']:.0f} s"
    )


def cases(quick: bool) -> list[Case]:
    streets = quick_streets() if quick else clean_streets()
    out = [clean_case(w) for w in streets]
    out += [foreign_case(41), truncated_case(42), corridor_case(43)]
    if not quick:
        out += [foreign_case(44), truncated_case(45), two_streets_case(46)]
        mulls = mulls_case()
        if mulls is not None:
            out.append(mulls)
    return out


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the reduced tier")
    ap.add_argument("--only", default="", help="run the cases whose name contains this")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("-v", "--verbose", action="store_true", help="list every wrong verdict")
    ap.add_argument("--cross", type=int, default=12, help="cross-scene pairs")
    ap.add_argument(
        "--links",
        type=Path,
        default=CACHE / "links.csv",
        help="where every link's metrics and truth are written (CSV)",
    )
    args = ap.parse_args()
    rows: list[dict] = []
    cfg = Config()
    total = {"clean": trust.TrustCounts(), "hostile": trust.TrustCounts()}
    for case in cases(args.quick):
        if args.only and args.only not in case.name:
            continue
        counts, detail = run_case(case, cfg, args.jobs)
        rows += detail["rows"]
        kind = "clean" if all(case.expected) and "real" not in case.name else "hostile"
        total[kind] = total[kind] + counts
        print(_row(case.name, counts, detail), flush=True)
        if args.verbose:
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
    cross = cross_scene_pairs(cfg, args.cross)
    rows += cross
    ok = sum(r["status"] is Status.OK for r in cross)
    print(f"cross-scene pairs: {ok}/{len(cross)} ok (must be 0)")
    _write(args.links, rows)
    for kind, c in total.items():
        print(
            f"TOTAL {kind}: scans {c.scans_ok}/{c.scans} ok, false alarms {c.scan_false_alarms}, "
            f"wrong ok {c.scan_wrong_ok}, split off the anchor's cluster {c.scans_split}; "
            f"links {c.links_correct} correct, "
            f"{c.link_false_alarms} false alarms "
            f"({c.link_false_alarms / max(c.links_correct, 1):.1%} of correct), "
            f"{c.link_wrong_ok} wrong ok, {c.link_wrong_kept} wrong kept"
        )


if __name__ == "__main__":
    main()
