"""The campaign section's routes, simulated once into ``benchmarks/.cache/route_<n>_<key>``:
sparse scans along one street (:func:`ndt_cli.sim.write_route`), each simulated and written
on its own (memory for two scans, not a thousand), their GPS times in the files; the shuffled
orders are copies of those files (with their times, or without: the points written again).
The key holds the simulator's sources, so a changed simulator makes the scans again."""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks.data import CACHE, sim_key
from ndt_cli import io, sim


@dataclass(frozen=True)
class Order:
    """A route's scans in one order: the files and each scan's true ``T_world_scan``."""

    files: list[Path]
    poses: list[np.ndarray]


def walk(n: int, seed: int, rays: tuple[int, int]) -> Order:
    """The route of ``n`` scans in walking order, their files with their times (made once)."""
    folder = CACHE / f"route_{n}_{sim_key((n, seed, rays))}"
    done = folder / "poses.npy"  # written last: the folder is complete
    if not done.exists():
        print(f"simulating {n} scans into {folder} (once) ...", flush=True)
        shutil.rmtree(folder, ignore_errors=True)
        jobs = min(2, os.cpu_count() or 1)
        _, poses = sim.write_route(folder / "walk", seed, n, rays=rays, times=True, jobs=jobs)
        np.save(done, np.array(poses))
    files = [folder / "walk" / f"scan_{k:02d}.laz" for k in range(n)]
    return Order(files, list(np.load(done)))


def shuffled(route: Order, folder: Path, seed: int, times: bool) -> Order:
    """The route's scans in the order :func:`ndt_cli.sim.shuffled` gives them, named in that
    order, as files in ``folder``: copies of the walk's (``times``) or the points alone."""
    order = np.random.default_rng([seed, 13]).permutation(len(route.files))
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for k, j in enumerate(order):
        f = folder / f"scan_{k:02d}.laz"
        if times:
            shutil.copyfile(route.files[j], f)
        else:
            io.write(f, io.read(route.files[j]).points)
        files.append(f)
    return Order(files, [route.poses[j] for j in order])
