"""A terrestrial laser scanner in a :class:`~ndt_cli.sim.scene.Scene`: ray casting with exact
occlusion, range noise, and sequences of standpoints along a street.

Units are metres and radians unless a name ends in ``_deg``. Frames: the **world frame** of the
scene, and the **scanner frame** (origin at the scanner centre, x = azimuth 0, z = the scanner's
up axis, tilted with the scanner). A pose ``T_world_scan`` (4x4) maps scanner-frame points to
the world frame; the ground-truth relative transform of a pair is
``T_target_source = inv(T_world_target) @ T_world_source``. Everything is numpy only and
vectorised; the same seed always gives bit-identical output.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from ndt_cli.sim.scene import Scene, make_street

_PAIR_CHUNK = 1_000_000  # ray/primitive pairs tested per vectorised batch (bounds memory)


def scanner_pose(
    x: float,
    y: float,
    yaw_deg: float,
    height: float = 1.6,
    roll_deg: float = 0.0,
    pitch_deg: float = 0.0,
) -> np.ndarray:
    """4x4 ``T_world_scan`` of a scanner centred at world (x, y, height) m above the ground z = 0.

    Rotation ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (angles in degrees): yaw turns the scanner
    about the world z axis, roll/pitch tilt it about its own x / y axes.
    """
    cy, sy = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    cp, sp = np.cos(np.radians(pitch_deg)), np.sin(np.radians(pitch_deg))
    cr, sr = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    T = np.eye(4)
    T[:3, :3] = rz @ ry @ rx
    T[:3, 3] = (x, y, height)
    return T


def _angle_ranges(lo: np.ndarray, hi: np.ndarray, sorted_az: np.ndarray) -> tuple[np.ndarray, ...]:
    """Index ranges [start, end) into ``sorted_az`` (in [-pi, pi]) of azimuth intervals [lo, hi]
    that may wrap around +-pi (lo >= -2 pi, hi <= 2 pi). Returns (item, start, end) per piece."""
    two_pi = 2 * np.pi
    full = (hi - lo) >= two_pi
    lo = np.where(full, -np.pi, lo)
    hi = np.where(full, np.pi, hi)
    shift = np.where(lo < -np.pi, two_pi, np.where(lo > np.pi, -two_pi, 0.0))
    lo, hi = lo + shift, hi + shift  # now lo in [-pi, pi]
    wraps = hi > np.pi
    items = np.arange(len(lo))
    main_s = np.searchsorted(sorted_az, lo, side="left")
    main_e = np.searchsorted(sorted_az, np.minimum(hi, np.pi), side="right")
    extra_e = np.searchsorted(sorted_az, hi[wraps] - two_pi, side="right")
    item = np.concatenate([items, items[wraps]])
    start = np.concatenate([main_s, np.zeros(int(wraps.sum()), dtype=main_s.dtype)])
    end = np.concatenate([main_e, extra_e])
    keep = end > start
    return item[keep], start[keep], end[keep]


def _pairs(item: np.ndarray, start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand index ranges into flat (item, position) pairs."""
    counts = end - start
    total = int(counts.sum())
    rep_item = np.repeat(item, counts)
    offsets = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    return rep_item, np.repeat(start, counts) + offsets


def _chunks(counts: np.ndarray, limit: int) -> list[slice]:
    """Split consecutive ranges into slices whose summed counts stay near ``limit``."""
    cum = np.cumsum(counts)
    cuts = np.searchsorted(cum, np.arange(limit, int(cum[-1]) if len(cum) else 0, limit))
    bounds = np.unique(np.concatenate([[0], cuts + 1, [len(counts)]]).clip(0, len(counts)))
    return [slice(int(a), int(b)) for a, b in itertools.pairwise(bounds)]


def _cast(
    scene: Scene,
    origin: np.ndarray,
    dirs: np.ndarray,
    max_range: float,
    foliage: np.random.Generator | None = None,
) -> np.ndarray:
    """Distance (m) along unit world rays ``dirs`` from ``origin`` to the first surface hit;
    ``max_range`` where nothing is hit closer. ``foliage`` draws where rays stop in crowns."""
    t_best = np.full(len(dirs), float(max_range))
    if scene.ground.flat:
        down = dirs[:, 2] < -1e-12
        t_best[down] = np.minimum(t_best[down], -origin[2] / dirs[down, 2])  # the plane z = 0
        t_best[t_best < 0] = max_range  # origin below ground: no ground hit
    else:
        if origin[2] <= scene.ground.z(origin[0], origin[1]):
            raise ValueError("the scanner centre lies below the ground")
        np.minimum(t_best, scene.ground.hit(origin, dirs), out=t_best)
    rays = _rays(origin, dirs)
    for yaw in np.unique(scene.boxes_yaw):
        pick = scene.boxes_yaw == yaw
        turned = rays if yaw == 0.0 else _rays(_turn(origin[None], -yaw)[0], _turn(dirs, -yaw))
        _hit_boxes(scene.boxes_min[pick], scene.boxes_max[pick], turned, t_best, max_range)
    _hit_cylinders(scene, rays, t_best, max_range)
    if len(scene.crowns):
        _hit_crowns(scene.crowns, rays, t_best, foliage or np.random.default_rng(0))
    return t_best


def _turn(v: np.ndarray, angle: float) -> np.ndarray:
    """(N,3) vectors turned by ``angle`` radians about z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1], v[:, 2]])


def _rays(origin: np.ndarray, dirs: np.ndarray) -> _Rays:
    az = np.arctan2(dirs[:, 1], dirs[:, 0])
    order = np.argsort(az, kind="stable")
    with np.errstate(divide="ignore"):
        inv = 1.0 / np.where(dirs == 0.0, 1e-300, dirs)  # huge but finite-safe slab inverses
    return _Rays(origin, dirs, inv, order, az[order])


@dataclass(frozen=True)
class _Rays:
    """Rays from ``origin`` (world, m): unit directions, their safe inverses, and the ray order
    by azimuth (``order``, ``sorted_az``) used to find the rays that can reach an object."""

    origin: np.ndarray
    dirs: np.ndarray
    inv: np.ndarray
    order: np.ndarray
    sorted_az: np.ndarray


def _hit_boxes(
    bmin: np.ndarray, bmax: np.ndarray, rays: _Rays, t_best: np.ndarray, max_range: float
) -> None:
    """Lower ``t_best`` (m along each ray) to the nearest hit of the axis-aligned boxes
    ``bmin``-``bmax`` (in the rays' frame)."""
    origin, inv, order, sorted_az = rays.origin, rays.inv, rays.order, rays.sorted_az
    ox, oy = origin[0], origin[1]
    if not len(bmin):
        return
    near = np.clip(origin, bmin, bmax)
    min_dist = np.linalg.norm(near - origin, axis=1)
    if np.any(min_dist <= 0.0):
        raise ValueError("the scanner centre lies inside or on a box of the scene")
    use = np.flatnonzero(min_dist < max_range)
    use = use[np.argsort(min_dist[use], kind="stable")]  # near first: better culling
    lo3, hi3, md = bmin[use], bmax[use], min_dist[use]
    cx = np.stack([lo3[:, 0], hi3[:, 0], hi3[:, 0], lo3[:, 0]], axis=1) - ox
    cy = np.stack([lo3[:, 1], lo3[:, 1], hi3[:, 1], hi3[:, 1]], axis=1) - oy
    centre = np.arctan2(cy.mean(axis=1), cx.mean(axis=1))
    rel = np.angle(np.exp(1j * (np.arctan2(cy, cx) - centre[:, None])))
    inside_xy = (lo3[:, 0] <= ox) & (ox <= hi3[:, 0]) & (lo3[:, 1] <= oy) & (oy <= hi3[:, 1])
    lo_az = np.where(inside_xy, -np.pi, centre + rel.min(axis=1) - 1e-9)
    hi_az = np.where(inside_xy, np.pi, centre + rel.max(axis=1) + 1e-9)
    item, start, end = _angle_ranges(lo_az, hi_az, sorted_az)
    srt = np.argsort(item, kind="stable")  # keep near-first processing order
    item, start, end = item[srt], start[srt], end[srt]
    for sl in _chunks(end - start, _PAIR_CHUNK):
        b, pos = _pairs(item[sl], start[sl], end[sl])
        ray = order[pos]
        keep = t_best[ray] > md[b]
        b, ray = b[keep], ray[keep]
        iv = inv[ray]
        t1 = (lo3[b] - origin) * iv
        t2 = (hi3[b] - origin) * iv
        t_near = np.minimum(t1, t2).max(axis=1)
        t_far = np.maximum(t1, t2).min(axis=1)
        hit = (t_near <= t_far) & (t_near > 0.0)
        np.minimum.at(t_best, ray[hit], t_near[hit])


def _hit_crowns(
    crowns: np.ndarray, rays: _Rays, t_best: np.ndarray, rng: np.random.Generator
) -> None:
    """Lower ``t_best`` where a ray is stopped inside a porous crown: at an exponentially
    distributed depth (mean ``1 / density`` m) past where it enters, if that is before it
    leaves. Each crown is tested against the rays whose azimuth can reach it (its horizontal
    circle of the larger radius, as seen from the scanner), in the order of the rays."""
    origin, dirs = rays.origin, rays.dirs
    for x, y, z, rx, ry, rz, density in crowns:
        idx = _rays_towards(rays, x - origin[0], y - origin[1], max(rx, ry))
        if not len(idx):
            continue
        scale = np.array([rx, ry, rz])
        o = (origin - (x, y, z)) / scale
        d = dirs[idx] / scale
        a = np.einsum("ij,ij->i", d, d)
        b = d @ o
        c = float(o @ o) - 1.0
        disc = b * b - a * c
        inside = np.flatnonzero(disc > 0.0)
        if not len(inside):
            continue
        cand = idx[inside]
        root = np.sqrt(disc[inside])
        t0 = np.maximum((-b[inside] - root) / a[inside], 0.0)
        t1 = (-b[inside] + root) / a[inside]
        t = t0 + rng.exponential(1.0 / density, len(cand))
        hit = (t < t1) & (t1 > 0.0) & (t < t_best[cand])
        t_best[cand[hit]] = t[hit]


def _rays_towards(rays: _Rays, dx: float, dy: float, radius: float) -> np.ndarray:
    """Indices (ascending) of the rays whose line meets, in azimuth, the horizontal circle of
    ``radius`` m centred ``(dx, dy)`` m from the origin: those pointing into it and those
    pointing away from it (whose backward extension meets it; every ray when the origin is in
    it). The lines, not only the rays: a crown behind the scanner draws its depths too, so
    that the foliage's draws do not depend on this cull."""
    dist = float(np.hypot(dx, dy))
    if dist <= radius:
        return np.arange(len(rays.dirs))
    centre = np.arctan2(dy, dx)
    half = np.arcsin(radius / dist) + 1e-9
    lo = np.array([centre - half, centre + np.pi - half])
    item, start, end = _angle_ranges(lo, lo + 2.0 * half, rays.sorted_az)
    _, pos = _pairs(item, start, end)
    return np.sort(rays.order[pos])


def _hit_cylinders(scene: Scene, rays: _Rays, t_best: np.ndarray, max_range: float) -> None:
    """Lower ``t_best`` (m along each ray) to the nearest vertical cylinder hit (caps included)."""
    origin, dirs, inv = rays.origin, rays.dirs, rays.inv
    order, sorted_az = rays.order, rays.sorted_az
    ox, oy = origin[0], origin[1]
    cyl = scene.cylinders
    if not len(cyl):
        return
    dx, dy = cyl[:, 0] - ox, cyl[:, 1] - oy
    dist = np.hypot(dx, dy)
    use = np.flatnonzero(dist - cyl[:, 2] < max_range)
    cyl, dist = cyl[use], dist[use]
    if np.any((dist <= cyl[:, 2]) & (cyl[:, 3] <= origin[2]) & (origin[2] <= cyl[:, 4])):
        raise ValueError("the scanner centre lies inside a cylinder of the scene")
    centre = np.arctan2(cyl[:, 1] - oy, cyl[:, 0] - ox)
    half = np.arcsin(np.clip(cyl[:, 2] / np.maximum(dist, 1e-12), 0.0, 1.0)) + 1e-9
    full = dist <= cyl[:, 2]
    item, start, end = _angle_ranges(
        np.where(full, -np.pi, centre - half), np.where(full, np.pi, centre + half), sorted_az
    )
    for sl in _chunks(end - start, _PAIR_CHUNK):
        c, pos = _pairs(item[sl], start[sl], end[sl])
        ray = order[pos]
        d = dirs[ray]
        px, py = ox - cyl[c, 0], oy - cyl[c, 1]
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        bq = px * d[:, 0] + py * d[:, 1]
        cq = px**2 + py**2 - cyl[c, 2] ** 2
        disc = bq**2 - a * cq
        ok = (disc >= 0.0) & (a > 1e-18)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        a_safe = np.where(ok, a, 1.0)
        r0, r1 = (-bq - sq) / a_safe, (-bq + sq) / a_safe
        z0 = (cyl[c, 3] - origin[2]) * inv[ray, 2]
        z1 = (cyl[c, 4] - origin[2]) * inv[ray, 2]
        t_near = np.maximum(r0, np.minimum(z0, z1))
        t_far = np.minimum(r1, np.maximum(z0, z1))
        hit = ok & (t_near <= t_far) & (t_near > 0.0)
        np.minimum.at(t_best, ray[hit], t_near[hit])


def simulate_scan(
    scene: Scene,
    T_world_scan: np.ndarray,
    *,
    n_azimuth: int = 1440,
    n_elevation: int = 160,
    elevation_range_deg: tuple[float, float] = (-60.0, 80.0),
    max_range: float = 120.0,
    range_noise: float = 0.008,
    seed: int = 0,
) -> np.ndarray:
    """Simulate one static TLS scan; returns (N, 3) float64 points in the SCANNER frame (m).

    Rays form a regular grid in the scanner frame: ``n_azimuth`` azimuths over the full circle
    (starting at the scanner x axis) times ``n_elevation`` elevations spanning
    ``elevation_range_deg`` (degrees, inclusive). Each ray returns its first hit among the ground
    plane, the boxes and the cylinders (nearest hit, so occlusion is exact); rays with no hit
    closer than ``max_range`` (m) return nothing. Gaussian noise with standard deviation
    ``range_noise`` (m) is added along each ray. Points are ordered azimuth-major, then by
    elevation; the noise is drawn from ``np.random.default_rng(seed)``, where rays stop in tree
    crowns from ``np.random.default_rng([seed, 1])``.
    """
    T = np.asarray(T_world_scan, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError("T_world_scan must be a 4x4 matrix")
    if n_azimuth < 1 or n_elevation < 1 or max_range <= 0 or range_noise < 0:
        raise ValueError("need n_azimuth, n_elevation >= 1, max_range > 0, range_noise >= 0")
    az = np.arange(n_azimuth) * (2 * np.pi / n_azimuth)
    el = np.radians(np.linspace(elevation_range_deg[0], elevation_range_deg[1], n_elevation))
    ca, sa = np.cos(az)[:, None], np.sin(az)[:, None]
    ce, se = np.cos(el)[None, :], np.sin(el)[None, :]
    se = np.broadcast_to(se, (n_azimuth, n_elevation))
    dirs_scan = np.stack([(ca * ce).ravel(), (sa * ce).ravel(), se.ravel()], axis=1)
    dirs_world = dirs_scan @ T[:3, :3].T
    foliage = np.random.default_rng([seed, 1]) if len(scene.crowns) else None
    t = _cast(scene, T[:3, 3].copy(), dirs_world, max_range, foliage)
    hit = t < max_range
    rng = np.random.default_rng(seed)
    r = t[hit] + rng.normal(0.0, range_noise, int(hit.sum())) if range_noise > 0 else t[hit]
    return r[:, None] * dirs_scan[hit]


def make_sequence(
    seed: int = 0,
    n_scans: int = 5,
    spacing: tuple[float, float] = (13.0, 30.0),
    *,
    corridor: bool = False,
    tilt_deg: float = 0.0,
    scan_kwargs: dict[str, Any] | None = None,
    positions: np.ndarray | None = None,
) -> tuple[Scene, list[np.ndarray], list[np.ndarray]]:
    """Scan a street (``make_street(seed, corridor=corridor)``) from ``n_scans`` standpoints.

    Standpoints run along the street (x), centred on x = 0, consecutive ones ``spacing`` m apart
    (uniform draw), with lateral offsets uniform in +-3 m around the centre line, scanner
    height 1.6 m, yaw uniform in [-180, 180) deg and roll/pitch uniform in +-``tilt_deg`` deg.
    All draws come from ``np.random.default_rng(seed)``. ``scan_kwargs`` is passed on to
    :func:`simulate_scan` (its ``seed`` defaults to a per-scan seed from the same generator).
    ``positions`` ((n_scans, 2), world x, y in m) places the standpoints instead (a walk that
    comes back to its start, say); headings and tilts are drawn as before.

    Returns ``(scene, scans, poses)``: each scan is (N, 3) in its own scanner frame, each pose
    its 4x4 ``T_world_scan``.
    """
    if n_scans < 1:
        raise ValueError("n_scans must be >= 1")
    lo, hi = spacing
    if not 0 < lo <= hi:
        raise ValueError("spacing must be (low, high) with 0 < low <= high")
    scene = make_street(seed, corridor=corridor)
    rng = np.random.default_rng(seed)
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(lo, hi, n_scans - 1))])
    xs -= 0.5 * (xs[0] + xs[-1])
    ys = rng.uniform(-3.0, 3.0, n_scans)
    if positions is not None:
        xs, ys = np.asarray(positions, dtype=float).reshape(n_scans, 2).T
    yaws = rng.uniform(-180.0, 180.0, n_scans)
    rolls = rng.uniform(-tilt_deg, tilt_deg, n_scans) if tilt_deg > 0 else np.zeros(n_scans)
    pitches = rng.uniform(-tilt_deg, tilt_deg, n_scans) if tilt_deg > 0 else np.zeros(n_scans)
    noise_seeds = rng.integers(0, 2**31 - 1, n_scans)
    poses, scans = [], []
    for i in range(n_scans):
        T = scanner_pose(xs[i], ys[i], yaws[i], 1.6, rolls[i], pitches[i])
        kwargs = {"seed": int(noise_seeds[i]), **(scan_kwargs or {})}
        poses.append(T)
        scans.append(simulate_scan(scene, T, **kwargs))
    return scene, scans, poses
