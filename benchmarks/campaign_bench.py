"""Benchmark sections of campaigns: how the cost grows with the number of scans (16, 64, 128,
256 sparse simulated scans along a street, in walking order and shuffled, with and without
the scans' times in their files), a street in
shuffled order against the same street in order, and field mode's latency (a 2 M-point scan
renamed into the watched folder until its outputs are published)."""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import data, routes
from benchmarks.common import RUN_BIN, fmt, table, target
from ndt_cli import sim
from ndt_cli.analysis import trust
from ndt_cli.config import Config
from ndt_cli.core.transforms import transform_errors
from ndt_cli.pipeline.campaign import Campaign
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.verify import NodeStatus

CHAIN = str(RUN_BIN / "ndt-chain")
RAYS = (1500, 200)  # a sparse terrestrial scan; far sparser ones defeat the coarse match (2 m
# pixels): at 600 x 80 rays a quarter of the coarse matches of overlapping scans are right
WATCH = str(RUN_BIN / "ndt-watch")


def _campaign(files: list[Path], out: Path, anchor: int = 0) -> tuple[float, Campaign]:
    t0 = time.perf_counter()
    campaign = Campaign(Config(), out, WorkerPool(2), anchor=anchor)
    try:
        campaign.add_scans(files)
        result = campaign.result()
    finally:
        campaign.close()
    return time.perf_counter() - t0, (campaign, result)


def _walk_index(walk: list[np.ndarray], other: list[np.ndarray]) -> list[int]:
    """For each pose of ``other`` (the same scans in another order), its index in ``walk``."""
    return [next(j for j, P in enumerate(walk) if np.array_equal(P, Q)) for Q in other]


def _same_as_walk(walk, result, order: list[int]) -> tuple[int, float]:
    """Scans whose status equals the walk's, and the largest difference of the poses of scans
    ok in both in the anchor's cluster (mm; the frame of the walk's first scan)."""
    same, worst = 0, 0.0
    for k, scan in enumerate(order):
        a, b = walk.solution.scans[scan], result.solution.scans[k]
        same += a.status is b.status
        if a.status is b.status is NodeStatus.OK and a.cluster == b.cluster == 0:
            worst = max(worst, 1000 * transform_errors(a.T_world_scan, b.T_world_scan)[1])
    return same, worst


def scaling(
    sizes: tuple[int, ...] = (16, 64, 128, 256), shuffled: tuple[int, ...] = (16, 64, 128, 256)
) -> None:
    """Wall time, registrations and coarse matches per scan, in a walk and, for the sizes in
    ``shuffled``, shuffled, its files without times and with them (as scanners write them):
    their time per scan against the walk's at each of those sizes."""
    print("## Campaigns: cost against the number of scans\n")
    print(f"Sparse simulated scans ({RAYS[0]} x {RAYS[1]} rays) 16 m apart along one street, one")
    print("process with two workers; `ok`: scans ok; per scan: wall time, registrations and")
    print("coarse matches divided by the scans; `ok wrong`: scans ok but not right in their")
    print("cluster's frame (as the trust sweep judges); `clusters`: pieces it ended in; a")
    print("shuffled campaign is anchored at the walk's first scan, and compared with the walk")
    print("scan by scan: statuses equal, largest difference of the poses ok in both (mm). The")
    print("walk's files and the `shuffled, timed` files hold their points' GPS times, the")
    print("`shuffled` files none.\n")
    rows, per_scan, agree = [], {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            route = routes.walk(n, seed=5, rays=RAYS)
            orders = [("walk", None)]
            if n in shuffled:
                orders += [("shuffled", False), ("shuffled, timed", True)]
            for label, times in orders:
                folder = f"{label.replace(', ', '_')}{n}"
                s = route if times is None else routes.shuffled(route, Path(tmp) / folder, 1, times)
                order = _walk_index(route.poses, s.poses)  # anchored at the walk's anchor
                out = Path(tmp) / f"out_{folder}"
                wall, (campaign, result) = _campaign(s.files, out, order.index(0))
                if label == "walk":
                    walk = result
                same, worst = _same_as_walk(walk, result, order)
                agree[(label, n)] = (n - same, worst)
                scans = result.solution.scans
                ok = sum(x.status is NodeStatus.OK for x in scans)
                clusters = len({x.cluster for x in scans if x.cluster is not None})
                judged = trust.scan_truths(result, list(s.poses))
                wrong = sum(t.status is NodeStatus.OK and not t.correct for t in judged)
                per_scan[(label, n)] = wall / n
                rows.append(
                    [
                        str(n),
                        label,
                        f"{ok}/{n}",
                        str(wrong),
                        str(clusters),
                        fmt(wall, ".1f"),
                        fmt(wall / n, ".2f"),
                        fmt(len(campaign.finished) / n, ".2f"),
                        fmt(len(campaign.coarse) / n, ".1f"),
                        f"{same}/{n}",
                        fmt(worst, ".1f"),
                    ]
                )
                shutil.rmtree(Path(tmp) / folder, ignore_errors=True)
    head = ["scans", "order", "ok", "ok wrong", "clusters", "wall (s)", "s/scan", "regs/scan"]
    table([*head, "coarse/scan", "status as walk", "pose vs walk (mm)"], rows)
    lo, hi = min(sizes), max(sizes)
    growth = per_scan[("walk", hi)] / per_scan[("walk", lo)]
    target(
        f"campaign in a walk: time per scan at {hi} / at {lo} scans",
        growth,
        2.0,
        "<= 2 (roughly linear)",
        "x",
    )
    for n in shuffled:
        for label in ("shuffled", "shuffled, timed"):
            ratio = per_scan[(label, n)] / per_scan[("walk", n)]
            target(f"{n} scans {label}: time per scan / in a walk", ratio, 2.0, "<= 2", "x")
            differ, worst = agree[(label, n)]
            target(f"{n} scans {label}: scans whose status is not the walk's", differ, 0, "0")
            target(
                f"{n} scans {label}: poses ok in both, largest difference",
                worst,
                5.0,
                "<= 5",
                " mm",
            )


def order_ratio() -> None:
    """A street of 8 sparse scans given in shuffled order against the same street in order
    (ndt-chain as fresh processes, --jobs 2)."""
    print("## A street in any order\n")
    with tempfile.TemporaryDirectory() as tmp:
        survey = sim.route(seed=21, n_scans=8, rays=(1000, 160))
        times = {}
        for label, s in (("in order", survey), ("shuffled", sim.shuffled(survey, seed=2))):
            files = sim.write_survey(s, Path(tmp) / label)
            t0 = time.perf_counter()
            cmd = [CHAIN, *map(str, files), "-o", str(Path(tmp) / f"o{label}"), "-q", "-j", "2"]
            subprocess.run(cmd, check=False)
            times[label] = time.perf_counter() - t0
    ratio = times["shuffled"] / times["in order"]
    table(
        ["street of 8 scans", "wall (s)"],
        [[k, fmt(v, ".1f")] for k, v in times.items()],
    )
    target("ndt-chain of a shuffled street / in order", ratio, 2.0, "<= 2", "x")


def _placed(events: Path) -> list[dict]:
    """The placed (or fits_nowhere) events ndt-watch --json has printed so far."""
    lines = events.read_text().splitlines()
    found = [json.loads(line) for line in lines if line.endswith("}")]
    return [e for e in found if e["event"] in ("placed", "fits_nowhere")]


def watch_latency(dense: bool = False) -> None:
    """Field mode: the scans renamed into the watched folder one by one (full density, 2 M
    points, or today's, 17 M points as LAZ); the time from the rename to the published
    outputs, once the process is warm (the third scan on)."""
    if dense:
        files, limit, what = data.street_dense()[0][".laz"], 6.0, "a 17 M-point LAZ scan"
    else:
        files, limit, what = data.street()[0], 3.0, "a 2 M-point scan"
    print(f"## Field mode: from landing to published outputs ({what})\n")
    rows, warm = [], []
    with tempfile.TemporaryDirectory() as tmp:
        folder, out, events = Path(tmp) / "card", Path(tmp) / "field", Path(tmp) / "events"
        folder.mkdir()
        proc = subprocess.Popen(
            [WATCH, str(folder), "--out", str(out), "-j", "2", "--exit-when-idle", "5", "--json"],
            stdout=events.open("w"),
        )
        for k, f in enumerate(files):
            shutil.copy(f, folder / f".{f.name}.part")
            landed = time.time()
            (folder / f".{f.name}.part").rename(folder / f.name)
            while proc.poll() is None and len(_placed(events)) < k + 1:
                time.sleep(0.05)
            since = time.time() - landed
            event = _placed(events)[k]
            took = event["took_s"]
            status = event.get("status", event["event"])
            rows.append([f.name, f"{data.las_points(f) / 1e6:.2f}", status, fmt(took), fmt(since)])
            if k >= 2:
                warm.append(since if status == "ok" else float("inf"))  # placed and ok
        proc.wait(timeout=600)
    table(["scan", "M points", "status", "update (s)", "landing to line (s)"], rows)
    worst = max(warm) if warm else float("nan")
    target(
        f"ndt-watch, warm: {what} landed to outputs published",
        worst,
        limit,
        f"<= {limit:g} s",
        " s",
    )


def campaigns(quick: bool, dense: bool = False, large: bool = False) -> None:
    """Every campaign section (``quick``: 16 and 64 scans only; ``dense``: field mode at
    today's density too; ``large``: 1,000 scans in every order too, hours while the placement
    of shuffled files without times is quadratic)."""
    if quick:
        scaling((16, 64), (16, 64))
    else:
        scaling((16, 64, 128, 256, 1000), (16, 64, 128, 256, 1000)) if large else scaling()
    order_ratio()
    watch_latency()
    if dense:
        watch_latency(dense=True)
