"""Campaigns as surveyors walk them: a junction with a side street, a loop around a block, a
long route, scans in random order, two separate sites in one call.

Built from the street primitives (:func:`~ndt_cli.sim.scene.make_street` placed at any origin
and heading, with rectangles cleared where streets meet, and :meth:`Scene.merged`). Frames and
units as in :mod:`ndt_cli.sim.scanner`: metres, world z up, ``T_world_scan`` maps scanner
points into the world. Deterministic in the seed.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from ndt_cli import io
from ndt_cli.sim.scanner import scanner_pose, simulate_scan
from ndt_cli.sim.scene import Scene, make_street

RAYS = (1000, 160)  # azimuths x elevations: sparse scans, about 0.1 M points each
WIDTH = 18.0  # facade to facade (m)
_HALF = WIDTH / 2
_REACH = 130.0  # objects farther than this from a scanner cannot be hit (max range 120 m)
DAY_START = 86_400.0 + 8 * 3_600.0  # s of the GPS week: Monday, 8 o'clock
STANDPOINT_S = 600.0  # s from one standpoint's start to the next's (set up, scan, move on)
SCAN_S = 180.0  # s a scan takes, its points measured evenly over it


@dataclass(frozen=True)
class Survey:
    """A simulated campaign: the static scene, and per scan (in the order given) its name,
    its points (N,3, scanner frame, m) and its true ``T_world_scan``."""

    scene: Scene
    names: tuple[str, ...]
    scans: tuple[np.ndarray, ...]
    poses: tuple[np.ndarray, ...]
    site: tuple[int, ...]  # which site each scan belongs to (0 unless two_sites)
    taken: tuple[float, ...] = ()  # when each scan began (s of the GPS week), walk order

    def __len__(self) -> int:
        return len(self.scans)

    def relative(self, a: int, b: int) -> np.ndarray:
        """True ``T_a_b`` (4x4): scan ``b``'s frame into scan ``a``'s."""
        return np.linalg.inv(self.poses[a]) @ self.poses[b]


def _street(seed: int, a: tuple[float, float], b: tuple[float, float], clear: tuple = ()) -> Scene:
    """A street whose centre line runs from world ``a`` to ``b`` (the street ends there)."""
    a_, b_ = np.asarray(a, float), np.asarray(b, float)
    d = b_ - a_
    axis = float(np.degrees(np.arctan2(d[1], d[0])))
    centre = tuple(0.5 * (a_ + b_))
    return make_street(
        seed, float(np.hypot(*d)), WIDTH, origin=centre, axis_deg=axis, clear=tuple(clear)
    )


def stations_along(path: Sequence[tuple[float, float]], spacing: float) -> np.ndarray:
    """(n,2) world points every ``spacing`` m along a polyline, its first vertex included."""
    pts = [np.asarray(path[0], float)]
    carry = 0.0
    for p, q in itertools.pairwise(path):
        p, q = np.asarray(p, float), np.asarray(q, float)
        length = float(np.hypot(*(q - p)))
        s = spacing - carry
        while s <= length + 1e-9:
            pts.append(p + (q - p) * s / length)
            s += spacing
        carry = length - (s - spacing)
    return np.array(pts)


def within_reach(scene: Scene, xy: np.ndarray, reach: float = _REACH) -> Scene:
    """The objects of ``scene`` within ``reach`` m of world ``xy`` (a faster cast, the same
    hits: nothing farther is within the scanner's range)."""
    c = 0.5 * (scene.boxes_min[:, :2] + scene.boxes_max[:, :2])  # box centres, box axes
    cy, sy = np.cos(scene.boxes_yaw), np.sin(scene.boxes_yaw)
    world = np.column_stack([cy * c[:, 0] - sy * c[:, 1], sy * c[:, 0] + cy * c[:, 1]])
    size = np.hypot(*(scene.boxes_max[:, :2] - scene.boxes_min[:, :2]).T)
    keep_b = np.hypot(*(world - xy).T) < reach + size
    keep_c = np.hypot(*(scene.cylinders[:, :2] - xy).T) < reach
    keep_k = np.hypot(*(scene.crowns[:, :2] - xy).T) < reach
    return Scene(
        scene.boxes_min[keep_b],
        scene.boxes_max[keep_b],
        scene.cylinders[keep_c],
        scene.street_axis_deg,
        scene.boxes_yaw[keep_b],
        scene.crowns[keep_k],
        scene.ground,
    )


def _standpoints(scene: Scene, stations: np.ndarray, seed: int) -> list[tuple[np.ndarray, int]]:
    """Per station its true ``T_world_scan`` (jittered by up to 2 m, any heading, 1.5-1.8 m
    high) and the seed of its scan's noise: drawn in station order, whoever simulates them."""
    rng = np.random.default_rng([seed, 11])
    out = []
    for k, xy in enumerate(stations):
        p = xy + rng.uniform(-2.0, 2.0, 2)
        height = float(scene.ground_z(*p)) + rng.uniform(1.5, 1.8)
        T = scanner_pose(p[0], p[1], rng.uniform(-180.0, 180.0), height)
        out.append((T, int(rng.integers(0, 2**31 - 1)) + k))
    return out


def _scan(scene: Scene, T: np.ndarray, rays: tuple[int, int], noise: int) -> np.ndarray:
    """The points (N,3, scanner frame, m) a scanner at ``T`` (world) sees of ``scene``."""
    near = within_reach(scene, T[:2, 3])
    return simulate_scan(near, T, n_azimuth=rays[0], n_elevation=rays[1], seed=noise)


def _survey(
    scene: Scene, stations: np.ndarray, seed: int, rays: tuple[int, int], prefix: str = "scan"
) -> Survey:
    """Scan ``scene`` from each station (:func:`_standpoints`)."""
    standpoints = _standpoints(scene, stations, seed)
    scans = [_scan(scene, T, rays, noise) for T, noise in standpoints]
    names = tuple(f"{prefix}_{k:02d}" for k in range(len(scans)))
    taken = tuple(DAY_START + STANDPOINT_S * k for k in range(len(scans)))
    poses = tuple(T for T, _ in standpoints)
    return Survey(scene, names, tuple(scans), poses, (0,) * len(scans), taken)


def write_survey(survey: Survey, folder: Path, *, times: bool = False) -> list[Path]:
    """The survey's scans as LAZ files in ``folder`` (``NAME.laz``, in the survey's order); with
    ``times``, as a scanner writes them: every point with its GPS time, the scan's start
    (:attr:`Survey.taken`) plus its place among the points over :data:`SCAN_S`."""
    folder.mkdir(parents=True, exist_ok=True)
    files = [folder / f"{n}.laz" for n in survey.names]
    for f, pts, taken in zip(files, survey.scans, survey.taken, strict=True):
        _write_scan(f, pts, taken if times else None)
    return files


def _write_scan(path: Path, pts: np.ndarray, taken: float | None) -> None:
    """One scan's LAZ file; ``taken``: its start (s of the GPS week) when it holds times."""
    t = None if taken is None else taken + SCAN_S * np.arange(len(pts)) / max(len(pts), 1)
    io.write(path, pts, gps_time=t)


def _simulated_file(path: Path, near: Scene, T: np.ndarray, rays, noise: int, taken) -> Path:
    """Simulate one scan and write it (a worker's task: the scene within reach only)."""
    _write_scan(path, _scan(near, T, rays, noise), taken)
    return path


def write_route(
    folder: Path,
    seed: int = 0,
    n_scans: int = 16,
    spacing: float = 16.0,
    rays: tuple[int, int] = (600, 80),
    *,
    times: bool = False,
    jobs: int = 1,
) -> tuple[list[Path], list[np.ndarray]]:
    """The files :func:`route` and :func:`write_survey` would write (the same points), each
    simulated and written on its own, ``jobs`` at a time: memory for ``jobs`` scans, not for
    the campaign (a thousand scans). Returns the files and their true ``T_world_scan``."""
    scene, stations = _route(seed, n_scans, spacing)
    standpoints = _standpoints(scene, stations, seed)
    folder.mkdir(parents=True, exist_ok=True)
    tasks = []
    for k, (T, noise) in enumerate(standpoints):
        taken = DAY_START + STANDPOINT_S * k if times else None
        near = within_reach(scene, T[:2, 3])
        tasks.append((folder / f"scan_{k:02d}.laz", near, T, rays, noise, taken))
    if jobs <= 1:
        files = [_simulated_file(*t) for t in tasks]
    else:
        with ProcessPoolExecutor(jobs, mp_context=get_context("spawn")) as pool:
            files = list(pool.map(_simulated_file, *zip(*tasks, strict=True)))
    return files, [T for T, _ in standpoints]


def junction(seed: int = 0, spacing: float = 16.0, rays: tuple[int, int] = RAYS) -> Survey:
    """A main street along x (x from -150 to 150 m) and a side street joining it from the north
    at x = 0 (a T junction). The walk goes east along the main street from x = -64 to the
    junction, turns up the side street to y = 80, walks back to the junction without scanning
    and goes on east to x = 64 (the scan after the side street is far from the one before)."""
    side_w = 16.0
    gap = (-0.5 * side_w - 1.0, 0.5 * side_w + 1.0, 0.0, 60.0)  # the side street's mouth
    main = _street(seed, (-150.0, 0.0), (150.0, 0.0), clear=(gap,))
    side = _street(seed + 1, (0.0, _HALF), (0.0, 140.0))
    scene = main.merged(side)
    path = [(-64.0, 0.0), (0.0, 0.0), (0.0, 80.0)]
    out = stations_along(path, spacing)
    back = stations_along([(0.0, 0.0), (64.0, 0.0)], spacing)[1:]
    return _survey(scene, np.vstack([out, back]), seed, rays)


def _block_scene(seed: int, x0: float, x1: float, y1: float, spur: float) -> Scene:
    """Four streets around a block: the main street (y = 0, from ``spur`` past x0 to 70 m past
    x1), the back street (y = y1) and two side streets (x = x0, x1) between their facades; each
    mouth cleared in the street it joins."""
    west, east = x0 - spur, x1 + 70.0

    def mouth(x: float, centre: float, north: bool) -> tuple[float, float, float, float]:
        u = x - centre  # along the street (its own frame: x along, y across)
        ys = (0.0, 60.0) if north else (-60.0, 0.0)
        return (u - _HALF - 1.0, u + _HALF + 1.0, *ys)

    mid = 0.5 * (west + east)
    back_mid = 0.5 * (x0 - 40.0 + x1 + 40.0)
    main = _street(seed, (west, 0.0), (east, 0.0), (mouth(x0, mid, True), mouth(x1, mid, True)))
    back = _street(
        seed + 1,
        (x0 - 40.0, y1),
        (x1 + 40.0, y1),
        (mouth(x0, back_mid, False), mouth(x1, back_mid, False)),
    )
    left = _street(seed + 2, (x0, _HALF), (x0, y1 - _HALF))
    right = _street(seed + 3, (x1, _HALF), (x1, y1 - _HALF))
    return main.merged(back, left, right)


def block_loop(
    seed: int = 0,
    spacing: float = 16.0,
    rays: tuple[int, int] = RAYS,
    size: tuple[float, float] = (100.0, 76.0),
) -> Survey:
    """A loop around a block of ``size`` (m, between street centre lines) with a spur: the walk
    starts 32 m west of the block on the main street, goes east along it, north up the east
    side street, west along the back street and south down the west side street, and ends
    one step past where it entered the loop (junctions at all four corners, a side street on
    each side, the loop closed)."""
    x0, x1, y1 = -0.5 * size[0], 0.5 * size[0], size[1]
    scene = _block_scene(seed, x0, x1, y1, 80.0)
    path = [(x0 - 32.0, 0.0), (x1, 0.0), (x1, y1), (x0, y1), (x0, 0.0), (x0 + spacing, 0.0)]
    return _survey(scene, stations_along(path, spacing), seed, rays)


def route(
    seed: int = 0, n_scans: int = 16, spacing: float = 16.0, rays: tuple[int, int] = (600, 80)
) -> Survey:
    """``n_scans`` along one long street (very sparse scans by default): a campaign whose size
    is the only thing that grows (benchmarks; :func:`write_route` writes it scan by scan)."""
    return _survey(*_route(seed, n_scans, spacing), seed, rays)


def _route(seed: int, n_scans: int, spacing: float) -> tuple[Scene, np.ndarray]:
    """The street of :func:`route` (60 m beyond its first and last station) and its stations."""
    length = spacing * (n_scans - 1)
    scene = _street(seed, (-60.0, 0.0), (length + 60.0, 0.0))
    return scene, stations_along([(0.0, 0.0), (length, 0.0)], spacing)


def shuffled(survey: Survey, seed: int = 0) -> Survey:
    """The same scans in a random order, named in that order (``scan_00`` is now any scan):
    files merged from two scanners, a numbering that restarted, a second day added."""
    order = np.random.default_rng([seed, 13]).permutation(len(survey))
    names = tuple(f"scan_{k:02d}" for k in range(len(survey)))
    return Survey(
        survey.scene,
        names,
        tuple(survey.scans[k] for k in order),
        tuple(survey.poses[k] for k in order),
        tuple(survey.site[k] for k in order),
        tuple(survey.taken[k] for k in order),
    )


def two_sites(
    seed: int = 0, n_scans: tuple[int, int] = (5, 4), spacing: float = 16.0, rays=RAYS
) -> Survey:
    """Two separate campaigns in one call: a street at the origin and another 2 km away
    (nothing of one is in range of the other). Scans of the first site come first
    (``a_00``, ...), then those of the second (``b_00``, ...)."""
    parts = []
    for site, (n, origin) in enumerate(zip(n_scans, ((0.0, 0.0), (2000.0, 500.0)), strict=True)):
        length = spacing * (n - 1)
        a = (origin[0] - 0.5 * length, origin[1])
        b = (origin[0] + 0.5 * length, origin[1])
        scene = _street(seed + 10 * site, (a[0] - 60.0, a[1]), (b[0] + 60.0, b[1]))
        parts.append(_survey(scene, stations_along([a, b], spacing), seed + site, rays, "ab"[site]))
    first, second = parts
    return Survey(
        first.scene.merged(second.scene),
        first.names + second.names,
        first.scans + second.scans,
        first.poses + second.poses,
        (0,) * len(first) + (1,) * len(second),
        first.taken + tuple(t + STANDPOINT_S * len(first) for t in second.taken),
    )
