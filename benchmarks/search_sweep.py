"""Sweep of the global search (:mod:`ndt_cli.ndt.bnb`) on simulated links, run by hand:

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/search_sweep.py [--quick] [--field edt]

Links: street sequences (spacing 12-30 m, any heading) give adjacent links; sequences at 17-24 m
give far links (scans i, i+2: 34-48 m apart); corridor sequences give degenerate links. The
prepared scans are cached in ``benchmarks/.cache/search_sweep``. Printed per method: success
rate, median / max time per link and the median of each link's time over today's search (same
link, same run: the machine is shared, ratios are what to compare). Figures are printed only.

(a) the global search alone: its best pose within one pixel (diagonal) and one yaw step;
(b) the global search, then the NDT coarse-to-fine refinement from its best candidates and the
    ranking by evidence: final pose within 0.3 deg / 15 cm;
(c) today's start search (984 starts at 20 m cells), then the refinement from 10 m cells.
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from scipy.ndimage import distance_transform_edt, gaussian_filter  # noqa: E402

from ndt_cli import sim  # noqa: E402
from ndt_cli.config import Config  # noqa: E402
from ndt_cli.core.transforms import wrap_angle  # noqa: E402
from ndt_cli.ndt import bnb  # noqa: E402
from ndt_cli.ndt.backend import NUMBA  # noqa: E402
from ndt_cli.ndt.coarse_to_fine import coarse_to_fine, rank  # noqa: E402
from ndt_cli.ndt.grid import build_map  # noqa: E402
from ndt_cli.ndt.kernels import SourcePoints, point_scores  # noqa: E402
from ndt_cli.ndt.levels import SourceSampler, TargetMaps  # noqa: E402
from ndt_cli.ndt.prepare import PreparedScan, prepare  # noqa: E402
from ndt_cli.ndt.search import start_search  # noqa: E402

CACHE = ROOT / "benchmarks" / ".cache" / "sweep_scans"  # simulated points: this code prepares them
RAYS = {"n_azimuth": 1000}
FINAL_DEG, FINAL_M = 0.3, 0.15  # success of a registration
# (name, BnB candidates refined, cells refined with restarts, then cells refined without)
VARIANTS = [
    ("top1 (2,1)", 1, (), (2.0, 1.0)),
    ("top2 (2,1)", 2, (), (2.0, 1.0)),
    ("top4 (5,2,1)", 4, (), (5.0, 2.0, 1.0)),
    ("top8 (5,2,1)", 8, (), (5.0, 2.0, 1.0)),
    ("top2 (2,1) restarts", 2, (2.0, 1.0), ()),
    ("top4 (5,2,1) restarts", 4, (5.0, 2.0, 1.0), ()),
    ("top8 (5,2,1) restarts", 8, (5.0, 2.0, 1.0), ()),
    ("top4 (5) restarts, (2,1)", 4, (5.0,), (2.0, 1.0)),
    ("top8 (5) restarts, (2,1)", 8, (5.0,), (2.0, 1.0)),
    ("top8 (10,5) restarts, (2,1)", 8, (10.0, 5.0), (2.0, 1.0)),
]
BNB_K = (1, 2, 4, 8)  # candidates asked of the search (the first k picks never depend on K)


@dataclass(frozen=True)
class Link:
    kind: str  # street, far, corridor
    name: str
    target: PreparedScan
    source: PreparedScan
    truth: np.ndarray  # (tx, ty, yaw) in the reduced frames
    distance: float  # m between the scanners


def simulated(
    seed: int, n: int, spacing: tuple[float, float], corridor: bool
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The simulated scans (scanner frames, m) and true poses of one sequence, cached: the
    preparation is not, so that every run measures the code as it is."""
    path = CACHE / f"seq_{seed}_{n}_{spacing[0]:g}_{spacing[1]:g}_{int(corridor)}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    _, scans, poses = sim.make_sequence(
        seed=seed, n_scans=n, spacing=spacing, corridor=corridor, scan_kwargs=RAYS
    )
    CACHE.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps((scans, poses)))
    return scans, poses


def _sequence(seed: int, n: int, spacing: tuple[float, float], corridor: bool) -> tuple:
    """Prepared scans (without ICP points: not thinned for ICP at all) and poses of one
    sequence."""
    scans, poses = simulated(seed, n, spacing, corridor)
    no_icp = Config().replace(refine={"method": "none"})
    return [prepare(s, no_icp) for s in scans], poses


def _link(kind: str, seed: int, seq: tuple, i: int, j: int) -> Link:
    prepared, poses = seq
    t, s = prepared[i], prepared[j]
    L = t.to_local() @ (np.linalg.inv(poses[i]) @ poses[j]) @ s.from_local()
    truth = np.array([L[0, 3], L[1, 3], np.arctan2(L[1, 0], L[0, 0])])
    dist = float(np.hypot(*(poses[j][:2, 3] - poses[i][:2, 3])))
    return Link(kind, f"{kind} s{seed} {i}-{j}", t, s, truth, dist)


def link_counts() -> tuple[int, int, int]:
    """Street, far and corridor sequences asked on the command line (--street, --far,
    --corridor)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--street", type=int, default=24, help="sequences of 6 scans (5 links each)")
    ap.add_argument("--far", type=int, default=10, help="sequences of 4 scans (2 far links each)")
    ap.add_argument("--corridor", type=int, default=5)
    args = ap.parse_args()
    return args.street, args.far, args.corridor


def make_links(n_street: int, n_far: int, n_corr: int) -> list[Link]:
    out = []
    for seed in range(n_street):
        seq = _sequence(seed, 6, (12.0, 30.0), False)
        out += [_link("street", seed, seq, k, k + 1) for k in range(5)]
    for seed in range(100, 100 + n_far):
        seq = _sequence(seed, 4, (17.0, 24.0), False)
        out += [_link("far", seed, seq, k, k + 2) for k in range(2)]
    for seed in range(n_corr):
        seq = _sequence(seed, 3, (12.0, 30.0), True)
        out += [_link("corridor", seed, seq, k, k + 1) for k in range(2)]
    return out


def errors(pose: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Translation error (m) and absolute yaw error (deg) of a pose (tx, ty, yaw)."""
    dt = float(np.hypot(*(pose[:2] - truth[:2])))
    return dt, float(abs(np.degrees(wrap_angle(pose[2] - truth[2]))))


# ----------------------------------------------------------------------------- field variants


def blur_field(slices, resolution: float, sigma_px: float = 1.0) -> bnb.ScoreField:
    """Occupancy (binary per pixel) convolved with a Gaussian, scaled so that a straight line of
    occupied pixels peaks at 255, clipped."""
    edt = bnb.likelihood_field(slices, resolution=resolution, sigma_px=sigma_px)
    occupied = (edt.values == bnb.FIELD_MAX).astype(float)
    blurred = np.stack([gaussian_filter(o, sigma_px) for o in occupied])
    scaled = np.clip(np.sqrt(2 * np.pi) * sigma_px * blurred, 0.0, 1.0)
    return replace(edt, values=np.rint(bnb.FIELD_MAX * scaled).astype(np.uint8))


def ndt_field(slices, resolution: float, cell: float = 2.0) -> bnb.ScoreField:
    """The target's NDT score at every pixel centre (cells of ``cell`` m, variances floored at
    half a pixel squared so that a facade's ridge is wider than the pixels that sample it)."""
    edt = bnb.likelihood_field(slices, resolution=resolution)
    ndt = build_map(slices, cell, min_variance=(0.5 * resolution) ** 2)
    nx, ny = edt.values.shape[1:]
    a, b = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    centres = edt.origin + resolution * (np.column_stack([a.ravel(), b.ravel()]) + 0.5)
    src = SourcePoints.from_slices([centres] * len(slices))
    s, _ = point_scores(ndt, src, np.zeros(3))
    values = np.rint(bnb.FIELD_MAX * np.clip(s, 0, 1)).reshape(len(slices), nx, ny)
    return replace(edt, values=values.astype(np.uint8))


def distinct_field(slices, resolution: float, floor: float = 0.2) -> bnb.ScoreField:
    """The likelihood field, each occupied pixel weighted by how little its neighbourhood
    (Gaussian, 2.5 px) looks like a line: ``floor`` on a straight facade, 1 at corners and
    poles; a pixel off the structure takes the weight of its nearest occupied pixel."""
    edt = bnb.likelihood_field(slices, resolution=resolution)
    out = np.zeros_like(edt.values)
    for k, v in enumerate(edt.values):
        occ = (v == bnb.FIELD_MAX).astype(float)
        if not occ.any():
            continue
        a, b = np.meshgrid(*(np.arange(n, dtype=float) for n in occ.shape), indexing="ij")
        m = [gaussian_filter(occ * f, 2.5) for f in (1, a, b, a * a, a * b, b * b)]
        n = np.maximum(m[0], 1e-12)
        cxx = m[3] / n - (m[1] / n) ** 2
        cxy = m[4] / n - m[1] * m[2] / n**2
        cyy = m[5] / n - (m[2] / n) ** 2
        half, det = 0.5 * (cxx + cyy), cxx * cyy - cxy**2
        disc = np.sqrt(np.maximum(half**2 - det, 0))
        small = np.maximum(half - disc, 0) / np.maximum(half + disc, 1e-12)
        w = floor + (1 - floor) * np.clip(small / 0.25, 0, 1)
        d, (ia, ib) = distance_transform_edt(occ == 0, return_indices=True)
        out[k] = np.rint(bnb.FIELD_MAX * w[ia, ib] * np.exp(-0.5 * d**2)).astype(np.uint8)
    return replace(edt, values=out)


FIELDS = {
    "distinct": distinct_field,
    "edt": lambda sl, res: bnb.likelihood_field(sl, resolution=res),
    "edt2": lambda sl, res: bnb.likelihood_field(sl, resolution=res, sigma_px=2.0),
    "blur": blur_field,
    "ndt": ndt_field,
}


def run_bnb(link: Link, args, k: int) -> bnb.GlobalSearch:
    """The global search for ``k`` candidates on the chosen field; the time includes the field."""
    t0 = time.perf_counter()
    f = FIELDS[args.field](link.target.slices, args.resolution)
    found = bnb.search_field(f, link.source.slices, window=args.window, candidates=k)
    return replace(found, time_s=time.perf_counter() - t0)


def refine(
    link: Link, candidates: np.ndarray, with_restarts: tuple, plain: tuple
) -> tuple[np.ndarray, float]:
    """Coarse to fine from ``candidates``, first through the cells ``with_restarts`` (each
    restarted from +-1/2 and +-1 cell offsets), then through ``plain`` (no restarts), and the
    ranking by the evidence of the last call: the winner and the time (s)."""
    cfg = Config()
    t0 = time.perf_counter()
    maps = TargetMaps(link.target.slices, cfg.grid)
    sampler = SourceSampler(link.source.slices, cfg.source)
    refined = None
    for cells, restarts in ((with_restarts, True), (plain, False)):
        if cells:
            refined = coarse_to_fine(
                candidates, cells, maps, sampler, cfg.optimizer, restarts, NUMBA
            )
            candidates = refined.candidates
    ranked = rank(refined, (plain or with_restarts)[-1])
    return ranked.poses[0], time.perf_counter() - t0


def today(link: Link) -> tuple[np.ndarray, float, float]:
    """Today's start search and refinement: the winner, its ambiguity and the time (s)."""
    cfg = Config()
    t0 = time.perf_counter()
    maps = TargetMaps(link.target.slices, cfg.grid)
    sampler = SourceSampler(link.source.slices, cfg.source)
    cells = cfg.grid.cell_sizes
    found = start_search(
        link.target, link.source, maps, sampler, cells[0], cfg.search, cfg.optimizer, NUMBA
    )
    refined = coarse_to_fine(
        found.candidates, cells[1:], maps, sampler, cfg.optimizer, cfg.search.refine_offsets, NUMBA
    )
    ranked = rank(refined, cells[-1])
    return ranked.poses[0], ranked.ambiguity, time.perf_counter() - t0


def bnb_ok(link: Link, pose: np.ndarray, found: bnb.GlobalSearch) -> bool:
    """Within one pixel (diagonal) and one yaw step of the truth."""
    dt, dyaw = errors(pose, link.truth)
    return dt <= np.sqrt(2) * found.resolution and dyaw <= np.degrees(found.yaw_step)


def basin_ok(link: Link, pose: np.ndarray) -> bool:
    """Within 2 m and 2 degrees of the truth: where the refinement at 2 m cells converges."""
    dt, dyaw = errors(pose, link.truth)
    return dt <= 2.0 and dyaw <= 2.0


def final_ok(link: Link, pose: np.ndarray) -> bool:
    dt, dyaw = errors(pose, link.truth)
    return dt <= FINAL_M and dyaw <= FINAL_DEG


def measure(link: Link, args) -> dict:
    """Every method on one link: successes, times (s) and ratios."""
    runs = {k: run_bnb(link, args, k) for k in BNB_K}
    found = runs[BNB_K[-1]]
    row = {"ratio": found.ratio, "nodes": runs[4].nodes}
    row |= {f"bnb{k} s": runs[k].time_s for k in BNB_K}
    row["bnb"] = bool(len(found.poses)) and bnb_ok(link, found.poses[0], found)
    row["basin"] = bool(len(found.poses)) and basin_ok(link, found.poses[0])
    hits = [basin_ok(link, p) for p in found.poses]
    row["bnb_rank"] = hits.index(True) + 1 if any(hits) else 0
    if link.kind == "corridor" or args.bnb_only:
        return row
    pose, row["today_amb"], row["today_s"] = today(link)
    row["today"] = final_ok(link, pose)
    for name, k, with_restarts, plain in VARIANTS:
        pose, t = refine(link, runs[k].poses, with_restarts, plain)
        row[name] = final_ok(link, pose)
        row[name + " s"] = runs[k].time_s + t
    return row


def _times(rows: list[dict], key: str) -> str:
    t = np.array([r[key] for r in rows])
    rel = np.array([r[key] / r["today_s"] for r in rows]) if "today_s" in rows[0] else None
    text = f"median {np.median(t):6.3f} s  max {t.max():6.3f} s"
    return text + (f"  x today (median) {np.median(rel):5.2f}" if rel is not None else "")


def _rate(rows: list[dict], key: str) -> str:
    ok = sum(bool(r[key]) for r in rows)
    return f"{ok:3d}/{len(rows):3d} = {100 * ok / len(rows):5.1f} %"


def summary(kind: str, rows: list[dict], bnb_only: bool) -> None:
    print(f"\n== {kind}: {len(rows)} links")
    ranks = np.array([r["bnb_rank"] for r in rows])
    among = [int(((ranks > 0) & (ranks <= k)).sum()) for k in BNB_K]
    print(f"(a) BnB alone, best within 1 px / 1 yaw step: {_rate(rows, 'bnb')}")
    print(f"    BnB alone, best within 2 m / 2 deg      : {_rate(rows, 'basin')}")
    for k in BNB_K:
        print(f"    time, {k} candidate(s): {_times(rows, f'bnb{k} s')}")
    print(f"    a candidate within 2 m / 2 deg among the top 1 / 2 / 4 / 8: {among}")
    nodes = np.array([r["nodes"] for r in rows])
    print(f"    nodes (4 candidates): median {np.median(nodes):,.0f}, max {nodes.max():,}")
    if kind == "corridor" or bnb_only:
        return
    for v, (name, *_) in enumerate(VARIANTS):
        print(f"(b{v}) BnB + {name:27s}: {_rate(rows, name)}   {_times(rows, name + ' s')}")
    print(
        f"(c) today's search + c2f             : {_rate(rows, 'today')}   {_times(rows, 'today_s')}"
    )


def ratios(kind: str, rows: list[dict], key: str = "ratio") -> None:
    r = np.array([row[key] for row in rows])
    q = np.quantile(r, [0.0, 0.1, 0.5, 0.9, 1.0])
    names = ("min", "p10", "median", "p90", "max")
    text = "  ".join(f"{n} {v:.3f}" for n, v in zip(names, q, strict=True))
    print(f"{kind:9s} {key:10s} {text}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 street seeds, 2 far, 2 corridors")
    ap.add_argument("--field", default="edt", choices=sorted(FIELDS))
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--window", type=float, default=50.0)
    ap.add_argument(
        "--bnb-only", action="store_true", help="skip the refinement and today's search"
    )
    args = ap.parse_args()
    counts = (4, 2, 2) if args.quick else (24, 5, 5)
    links = make_links(*counts)
    bnb.search_field(
        bnb.likelihood_field(links[0].target.slices), links[0].source.slices
    )  # compile
    rows: dict[str, list[dict]] = {}
    t0 = time.perf_counter()
    for link in links:
        row = measure(link, args)
        rows.setdefault(link.kind, []).append(row)
        flag = "ok " if row["bnb"] else "MISS"
        failed = [str(v) for v, (name, *_) in enumerate(VARIANTS) if name in row and not row[name]]
        failed += ["today"] if "today" in row and not row["today"] else []
        print(
            f"{link.name:22s} {link.distance:5.1f} m  {flag} rank {row['bnb_rank']}"
            f"  ratio {row['ratio']:.3f}  {row['bnb4 s']:.3f} s  failed: {' '.join(failed)}",
            flush=True,
        )
    print(
        f"\nfield {args.field}, pixel {args.resolution} m, window +-{args.window} m,"
        f" {time.perf_counter() - t0:.0f} s in all"
    )
    for kind, group in rows.items():
        summary(kind, group, args.bnb_only)
    print("\nsecond-best distinct score over the best (BnB):")
    for kind, group in rows.items():
        ratios(kind, group)
    if "street" in rows and not args.bnb_only:
        ratios("street", rows["street"], "today_amb")


if __name__ == "__main__":
    main()
