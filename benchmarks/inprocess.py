"""Benchmark sections that run in this process, warm: the stages of a pair with either search,
the peers on the same pairs (ndt-cli timed right after each peer, so that every ratio is of two
neighbouring measurements) and the global adjustment of a large simulated network."""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

import ndt_cli
from benchmarks.common import fmt, ratio, table, target, timed
from benchmarks.fresh import OUT, Pair
from benchmarks.peers import FAMILIES, NO_GUESS, errors, guess_label, perturbed_guess
from ndt_cli.config import Config
from ndt_cli.ndt.coarse_to_fine import with_verification
from ndt_cli.ndt.prepare import ScanChunks, load_and_prepare_chunks
from ndt_cli.ndt.register import register_prepared
from ndt_cli.report.register_outputs import write_register_outputs

GUESS = guess_label(1.0, 2.0)

# ----------------------------------------------------------------------------- stages


def _search_levels(result, cfg: Config) -> int:
    """How many of ``result.levels`` are the search's (the rest refine): bnb alone, bnb and
    the start grid (its fallback), or the start grid."""
    if cfg.search.method != "bnb":
        return 1
    s = cfg.search
    schedule = tuple(c for c in cfg.grid.cell_sizes if c <= s.bnb_start_cell)
    alone = 1 + len(with_verification(schedule or (min(cfg.grid.cell_sizes),)))
    return 1 if len(result.levels) == alone else 2


def _stages(cfg: Config, p: Pair) -> tuple[dict[str, float], object]:
    """Seconds per stage of one warm registration of ``p`` with ``cfg``, and its result."""
    t_read, chunks = timed(lambda: [ScanChunks.of(f, cfg.input) for f in (p.a, p.b)])
    t_prep, scans = timed(lambda: [load_and_prepare_chunks(c, cfg) for c in chunks])
    t_reg, result = timed(lambda: register_prepared(scans[0], scans[1], cfg))
    t_write, _ = timed(lambda: write_register_outputs(OUT / "stages", result, cfg))
    tm, n = result.timings, _search_levels(result, cfg)
    search = sum(level.time_s for level in result.levels[:n])
    finer = sum(level.time_s for level in result.levels[n:])
    stages = {
        "read (2 files)": t_read,
        "prepare: ground, levelling, slices, ICP thinning": t_prep,
        "search": search,
        "finer levels and evidence": finer,
        "other NDT: samplers, the gate's 1 m fit": tm["ndt_s"] + tm["grid_s"] - search - finer,
        "ICP (and the gate after it)": tm["refine_s"],
        "write outputs": t_write,
    }
    stages["total"] = t_read + t_prep + t_reg + t_write
    stages["(NDT grids, built on first use within the above)"] = tm["grid_s"]
    return stages, result


def stage_times(p: Pair) -> None:
    """The stages of a pair with ``search.method: bnb`` (the default) and ``starts``."""
    cfgs = {"bnb": Config()}
    cfgs["starts"] = replace(cfgs["bnb"], search=replace(cfgs["bnb"].search, method="starts"))
    found = {}
    for name, cfg in cfgs.items():
        ndt_cli.register(p.a, p.b, cfg)  # warm: kernels loaded, caches filled
        found[name] = _stages(cfg, p)
    (bnb, r_bnb), (starts, r_starts) = found["bnb"], found["starts"]
    rows = [[k, f"{bnb[k]:.3f}", f"{starts[k]:.3f}"] for k in bnb]
    n = _search_levels(r_bnb, cfgs["bnb"])
    how = "branch and bound" + (" + start grid (fallback ran)" if n == 2 else "")
    print(f"## Stages of one pair in process, warm ({p.label}; {p.a.name} + {p.b.name})\n")
    table(["stage", "bnb (s)", "starts (s)"], rows)
    r = ratio(bnb["search"], starts["search"])
    print(f"search with bnb: {how}; search time bnb / starts: {fmt(r)}")
    for name, r in (("bnb", r_bnb), ("starts", r_starts)):
        rot, trans = errors(r.T_target_source, p.gt)
        levels = ", ".join(level.describe() for level in r.levels)
        print(f"{name}: {r.status}, error {rot:.4f} deg / {trans * 100:.2f} cm; levels {levels}")
    print()


# ----------------------------------------------------------------------------- peers


def _ours(target: np.ndarray, source: np.ndarray, start: str, init, gt: np.ndarray) -> dict:
    """One in-process ndt-cli registration of the arrays: wall time, errors, status."""
    wall, r = timed(lambda: ndt_cli.register(target, source, init=init))
    rot, trans = errors(r.T_target_source, gt)
    return {
        "start": start,
        "wall_s": wall,
        "rot_err_deg": rot,
        "trans_err_m": trans,
        "note": str(r.status),
    }


def _family(fn, target: np.ndarray, source: np.ndarray, p: Pair, T_guess) -> list[tuple]:
    """One peer's rows, each with ndt-cli's registration from the same start run right after
    the peer (None for a peer that did not run)."""
    rows = fn(target, source, p.gt, T_guess, GUESS)
    if all(not np.isfinite(r["wall_s"]) for r in rows):
        return [(r, None) for r in rows]
    inits = {NO_GUESS: None, GUESS: T_guess}
    starts = sorted({r["start"] for r in rows if r["start"] in inits})
    mine = {s: _ours(target, source, s, inits[s], p.gt) for s in starts}
    return [(r, mine.get(r["start"])) for r in rows]


def _peer_row(r: dict, mine: dict | None) -> list[str]:
    ours = float("nan") if mine is None else mine["wall_s"]
    return [
        str(r["peer"]),
        str(r["start"]),
        fmt(r["wall_s"]),
        fmt(r["rot_err_deg"], ".3f"),
        fmt(r["trans_err_m"], ".3f"),
        fmt(ours),
        fmt(ratio(ours, r["wall_s"])),
        str(r["note"]),
    ]


def _ours_rows(results: list[tuple]) -> list[list[str]]:
    """ndt-cli's own rows: its fastest run from each start, with that run's errors."""
    best: dict[str, dict] = {}
    for _, mine in results:
        if mine is not None and mine["wall_s"] < best.get(mine["start"], mine)["wall_s"] + 1e-12:
            best[mine["start"]] = mine
    name = f"ndt-cli {ndt_cli.__version__} (fastest of its runs)"
    return [[*_peer_row({"peer": name, **m}, None)[:5], "", "", m["note"]] for m in best.values()]


def _accurate(mine: dict | None, r: dict) -> bool:
    """ndt-cli at least as accurate as the peer (or within 0.02 deg / 1 cm)."""
    if mine is None:
        return False
    rot_ok = mine["rot_err_deg"] <= max(r["rot_err_deg"], 0.02)  # NaN peer errors: False
    return rot_ok and mine["trans_err_m"] <= max(r["trans_err_m"], 0.01)


def _peer_targets(p: Pair, results: list[tuple]) -> None:
    for r, mine in results:
        ours = float("nan") if mine is None else mine["wall_s"]
        name = str(r["peer"])
        if "FPFH" in name and p.key == "full":
            what = "ndt-cli / open3d FPFH+RANSAC+ICP (full pair, in process)"
            target(what, ratio(ours, r["wall_s"]), 0.5, "<= 0.5", " x")
        if "KISS" in name:
            what = "KISS-Matcher + GICP" if "GICP" in name else "KISS-Matcher alone (< its + GICP)"
            what = f"ndt-cli / {what} ({p.key} pair, in process)"
            ok = _accurate(mine, r)
            target(what, ratio(ours, r["wall_s"]), 0.999, "< 1, error <= the peer's", " x", ok)


def peers(p: Pair) -> None:
    """Every installed peer on the arrays of ``p``; ndt-cli from the same start right after."""
    from ndt_cli import io

    target_pts, source_pts = io.read(p.a).points, io.read(p.b).points
    T_guess = perturbed_guess(p.gt, 1.0, 2.0)
    ndt_cli.register(target_pts, source_pts)  # warm
    results = [x for fn in FAMILIES for x in _family(fn, target_pts, source_pts, p, T_guess)]
    rows = _ours_rows(results) + [_peer_row(r, mine) for r, mine in results]
    n = f"{len(target_pts):,} + {len(source_pts):,}"
    print(f"## Peers on the same pair ({p.label}: {n} points, arrays in memory, in process)\n")
    head = ["tool", "start", "wall (s)", "rot err (deg)", "trans err (m)", "ndt-cli (s)"]
    table([*head, "ndt-cli/peer", "note"], rows)
    print("'ndt-cli (s)': ndt-cli from the same start, run right after that peer; errors against")
    print("the simulator's ground truth; parameters and what each time includes: peers.py\n")
    _peer_targets(p, results)


# ----------------------------------------------------------------------------- adjustment


def adjustment(nodes: int = 1000) -> None:
    """benchmarks/adjust_bench.py's network: the adjustment and the verification of links."""
    from benchmarks import adjust_bench as ab
    from ndt_cli.pipeline.adjust import adjust
    from ndt_cli.pipeline.verify import EdgeState, NodeStatus, verify

    args = argparse.Namespace(nodes=nodes, outliers=5, untrusted=0.03, seed=0)
    truth = ab.truth_poses(nodes, np.random.default_rng(args.seed))
    edges, clean, wrong = ab.make_edges(truth, ab.network_pairs(nodes), args)
    t_adjust, plain = timed(lambda: adjust(nodes, 0, clean))
    mean, worst = ab.error_m(plain.poses, truth)
    rows = [["adjust (links without gross errors)", f"{t_adjust:.2f}", f"{plain.iterations} it"]]
    rows[-1] += ["", "", f"{mean * 100:.2f} / {worst * 100:.2f}"]
    t, res = timed(lambda: verify(nodes, 0, edges))
    rejected = {k for k, s in enumerate(res.states()) if s is EdgeState.REJECTED}
    ok = sum(s is NodeStatus.OK for s in res.statuses())
    mean, worst = ab.error_m(res.poses, truth)
    rows.append(["verify", f"{t:.2f}", f"{res.solves} solves", f"{len(wrong & rejected)}/"])
    rows[-1][-1] += f"{len(wrong)}, {len(rejected - wrong)} good"
    rows[-1] += [f"{ok}/{nodes}", f"{mean * 100:.2f} / {worst * 100:.2f}"]
    target(f"verify a {nodes}-scan network", t, 10.0, "a few seconds", " s")
    n_untrusted = sum(not e.trusted for e in edges)
    print(f"## Adjustment at scale: {nodes} simulated scans, {len(edges)} links")
    print(f"({len(wrong)} wrong, {n_untrusted} untrusted; benchmarks/adjust_bench.py)\n")
    head = ["step", "time (s)", "work", "wrong rejected", "scans ok", "error mean / max (cm)"]
    table(head, rows)
    target(f"adjust a {nodes}-scan network", t_adjust, 10.0, "a few seconds", " s")
