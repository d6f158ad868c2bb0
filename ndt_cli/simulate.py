"""Deterministic terrestrial-laser-scanner (TLS) simulator of street scenes.

Units are metres and radians unless a name ends in ``_deg``. Frames:

* **world frame**: right-handed, z up, the ground is the plane z = 0, the street runs along x
  (``Scene.street_axis_deg`` = 0) and is centred on y = 0;
* **scanner frame**: origin at the scanner centre, x = azimuth 0, z = the scanner's up axis
  (tilted with the scanner when roll/pitch are non-zero).

A pose ``T_world_scan`` (4x4) maps scanner-frame points to the world frame:
``p_world = R @ p_scan + t``. The ground-truth relative transform of a scan pair is
``T_target_source = inv(T_world_target) @ T_world_source``.

Everything is numpy only and vectorised; the same seed always gives bit-identical output.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Scene", "make_sequence", "make_street", "scanner_pose", "simulate_scan"]

# Street cross-section (metres, measured from the street centre line y = 0).
_SIDEWALK = 3.0  # sidewalk width between kerb and facade line
_CORRIDOR_EXTENSION = 150.0  # corridor facades run this far beyond each street end
_PAIR_CHUNK = 1_000_000  # ray/primitive pairs tested per vectorised batch (bounds memory)


@dataclass(frozen=True, eq=False)
class Scene:
    """Static street scene in the world frame (metres; z up; ground is the plane z = 0).

    Attributes:
        boxes_min: (B, 3) float64 lower corners (x, y, z) of axis-aligned boxes (buildings,
            facade relief, cars, signs).
        boxes_max: (B, 3) float64 upper corners of the same boxes.
        cylinders: (C, 5) float64 vertical cylinders ``x, y, radius, z_min, z_max``
            (poles, tree trunks), closed by flat caps.
        street_axis_deg: direction of the street axis in the world frame, degrees from +x.
    """

    boxes_min: np.ndarray
    boxes_max: np.ndarray
    cylinders: np.ndarray
    street_axis_deg: float = 0.0

    def __post_init__(self) -> None:
        bmin = np.array(self.boxes_min, dtype=np.float64).reshape(-1, 3)
        bmax = np.array(self.boxes_max, dtype=np.float64).reshape(-1, 3)
        cyl = np.array(self.cylinders, dtype=np.float64).reshape(-1, 5)
        if bmin.shape != bmax.shape:
            raise ValueError("boxes_min and boxes_max must have the same shape (B, 3)")
        if np.any(bmax < bmin):
            raise ValueError("every box needs boxes_max >= boxes_min")
        if np.any(cyl[:, 2] <= 0) or np.any(cyl[:, 4] < cyl[:, 3]):
            raise ValueError("cylinders need radius > 0 and z_max >= z_min")
        for name, arr in (("boxes_min", bmin), ("boxes_max", bmax), ("cylinders", cyl)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "street_axis_deg", float(self.street_axis_deg))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Scene):
            return NotImplemented
        return (
            self.street_axis_deg == other.street_axis_deg
            and np.array_equal(self.boxes_min, other.boxes_min)
            and np.array_equal(self.boxes_max, other.boxes_max)
            and np.array_equal(self.cylinders, other.cylinders)
        )

    __hash__ = None  # type: ignore[assignment]  # mutable-looking arrays: not hashable

    def ground_z(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Ground height (m) at world (x, y); the ground is the flat plane z = 0."""
        return np.zeros(np.broadcast(np.asarray(x), np.asarray(y)).shape)

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Boolean mask of world points strictly inside a box or cylinder shrunk by ``margin`` m."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        inside = np.zeros(len(pts), dtype=bool)
        step = max(1, 2_000_000 // max(1, len(self.boxes_min) + len(self.cylinders)))
        for s in range(0, len(pts), step):
            p = pts[s : s + step]
            lo = self.boxes_min[None] + margin
            hi = self.boxes_max[None] - margin
            in_box = np.all((p[:, None] > lo) & (p[:, None] < hi), axis=2).any(axis=1)
            c = self.cylinders
            d2 = (p[:, None, 0] - c[None, :, 0]) ** 2 + (p[:, None, 1] - c[None, :, 1]) ** 2
            r = np.maximum(c[None, :, 2] - margin, 0.0)
            in_cyl = (
                (d2 < r**2)
                & (p[:, None, 2] > c[None, :, 3] + margin)
                & (p[:, None, 2] < c[None, :, 4] - margin)
            ).any(axis=1)
            inside[s : s + step] = in_box | in_cyl
        return inside


class _BoxList:
    """Accumulates world boxes; facade boxes are given in street-side local coordinates."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, float, float, float, float]] = []

    def add(self, x0: float, x1: float, y0: float, y1: float, z0: float, z1: float) -> None:
        if x1 > x0 and y1 > y0 and z1 > z0:
            self.rows.append((x0, y0, z0, x1, y1, z1))

    def facade(
        self,
        side: int,
        y_front: float,
        u0: float,
        u1: float,
        v0: float,
        v1: float,
        z0: float,
        z1: float,
    ) -> None:
        """Add a box on one street side; ``v`` is depth behind the facade line (v < 0: protrudes
        towards the street), ``u`` runs along x, ``y_front`` is the facade line's |y|."""
        a, b = y_front + v0, y_front + v1
        if side > 0:
            self.add(u0, u1, a, b, z0, z1)
        else:
            self.add(u0, u1, -b, -a, z0, z1)

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        arr = np.array(self.rows, dtype=np.float64).reshape(-1, 6)
        return arr[:, :3].copy(), arr[:, 3:].copy()


def _window_columns(u0: float, u1: float, n: int, frac: float) -> tuple[np.ndarray, np.ndarray]:
    """Left/right edges of ``n`` openings centred in equal bays, each ``frac`` of a bay wide."""
    bay = (u1 - u0) / n
    centres = u0 + bay * (np.arange(n) + 0.5)
    half = 0.5 * bay * frac
    return centres - half, centres + half


def _building(
    boxes: _BoxList,
    rng: np.random.Generator,
    side: int,
    y_front: float,
    u0: float,
    u1: float,
    height: float,
    depth: float,
) -> None:
    """One building block: body, ground-floor openings, window grid and facade relief."""
    niche = rng.uniform(0.15, 0.4)  # depth of window / door niches behind the facade line
    boxes.facade(side, y_front, u0, u1, niche, depth, 0.0, height)  # body (back side included)
    width = u1 - u0

    # Ground floor: shop windows or a residential pattern, with at least one door.
    gf = min(rng.uniform(3.6, 4.6), height - 1.5)
    n_g = max(1, round(width / rng.uniform(3.0, 5.5)))
    shop = rng.random() < 0.5
    frac = rng.uniform(0.6, 0.85) if shop else rng.uniform(0.35, 0.55)
    gl, gr = _window_columns(u0, u1, n_g, frac)
    sills = rng.uniform(0.3, 0.9, n_g) if shop else rng.uniform(0.85, 1.25, n_g)
    sills[rng.choice(n_g, size=1 + (n_g > 4), replace=False)] = 0.0  # doors reach the ground
    g_top = gf - rng.uniform(0.5, 0.9)
    edges = np.concatenate([[u0], np.column_stack([gl, gr]).ravel(), [u1]])
    for a, b in edges.reshape(-1, 2):  # piers between the openings
        boxes.facade(side, y_front, a, b, 0.0, niche, 0.0, gf)
    for a, b, s in zip(gl, gr, sills, strict=True):  # parapets below the shop windows
        boxes.facade(side, y_front, a, b, 0.0, niche, 0.0, s)
    boxes.facade(side, y_front, u0, u1, 0.0, niche, g_top, gf)  # lintel band
    if rng.random() < 0.5:  # plinth protruding a little, low enough to leave doors usable
        boxes.facade(
            side, y_front, u0, u1, -rng.uniform(0.08, 0.15), 0.0, 0.0, rng.uniform(0.3, 0.6)
        )
    if rng.random() < 0.5:  # string course between ground floor and upper floors
        boxes.facade(side, y_front, u0, u1, -rng.uniform(0.1, 0.25), 0.0, gf - 0.3, gf)

    # Upper floors: a regular window grid (piers + spandrels) and optional relief.
    fh, sill_h, win_h = rng.uniform(2.8, 3.4), rng.uniform(0.8, 1.0), rng.uniform(1.3, 1.7)
    floors = np.arange(gf, height - (sill_h + win_h + 0.4), fh)  # bottoms of the upper floors
    n_b = max(2, round(width / rng.uniform(2.6, 4.2)))
    wl, wr = _window_columns(u0, u1, n_b, rng.uniform(0.35, 0.6))
    if len(floors) == 0:
        boxes.facade(side, y_front, u0, u1, 0.0, niche, gf, height)
        return
    edges = np.concatenate([[u0], np.column_stack([wl, wr]).ravel(), [u1]])
    for a, b in edges.reshape(-1, 2):
        boxes.facade(side, y_front, a, b, 0.0, niche, gf, height)
    prev_top = gf
    for zb in floors:
        boxes.facade(side, y_front, u0, u1, 0.0, niche, prev_top, zb + sill_h)
        prev_top = zb + sill_h + win_h
    boxes.facade(side, y_front, u0, u1, 0.0, niche, prev_top, height)  # attic / parapet
    if rng.random() < 0.4:  # balconies on some bays of the upper floors
        bd = rng.uniform(0.4, 0.6)
        bays = np.flatnonzero(rng.random(n_b) < 0.5)[:4]
        for zb in floors:
            for k in bays:
                a, b = wl[k] - 0.4, wr[k] + 0.4
                boxes.facade(side, y_front, a, b, -bd, 0.0, zb, zb + 0.18)  # slab
                boxes.facade(side, y_front, a, b, -bd, -bd + 0.06, zb, zb + 1.0)  # parapet
    if rng.random() < 0.35:  # pilasters on every other pier
        p = rng.uniform(0.1, 0.25)
        for k in range(0, n_b + 1, 2):
            a = u0 if k == 0 else wr[k - 1]
            b = u1 if k == n_b else wl[k]
            inset = 0.2 * (b - a)
            boxes.facade(side, y_front, a + inset, b - inset, -p, 0.0, gf, height - 0.4)
    if rng.random() < 0.7:  # cornice
        boxes.facade(side, y_front, u0, u1, -rng.uniform(0.2, 0.5), 0.0, height - 0.45, height)


def _corridor_side(
    boxes: _BoxList, rng: np.random.Generator, side: int, y_front: float, u0: float, u1: float
) -> None:
    """A facade that is uniform along x: ribbon windows, bands and a cornice, no gaps."""
    height = rng.uniform(12.0, 20.0)
    niche = rng.uniform(0.15, 0.4)
    boxes.facade(side, y_front, u0, u1, niche, 15.0, 0.0, height)
    gf, fh = rng.uniform(3.6, 4.6), rng.uniform(2.8, 3.4)
    boxes.facade(side, y_front, u0, u1, 0.0, niche, 0.0, 0.9)
    prev_top = gf - 0.6
    for zb in np.arange(gf, height - 2.8, fh):
        boxes.facade(side, y_front, u0, u1, 0.0, niche, prev_top, zb + 0.9)
        prev_top = zb + 0.9 + 1.5
    boxes.facade(side, y_front, u0, u1, 0.0, niche, prev_top, height)
    boxes.facade(side, y_front, u0, u1, -0.3, 0.0, height - 0.45, height)


def make_street(
    seed: int = 0, length: float = 260.0, width: float = 18.0, *, corridor: bool = False
) -> Scene:
    """Build a straight street along the world x axis, centred on the origin.

    ``length`` (m) is the street length (x in [-length/2, length/2]) and ``width`` (m) the
    facade-to-facade distance (facade lines at y = +-width/2, behind 3 m sidewalks). The street
    has blocks 8-30 m wide and 6-25 m high with 10-20 m depth, gaps / side streets, facade relief
    of 0.1-0.6 m, parked cars at both kerbs, lamp posts, sign posts and tree trunks.
    ``corridor=True`` gives the degenerate case: one gap-free facade per side that is uniform
    along x and extends 150 m beyond both street ends, no cars, no poles. Deterministic in ``seed``.
    """
    if length <= 0 or width <= 2 * _SIDEWALK + 2:
        raise ValueError("need length > 0 and width > 8 m")
    rng = np.random.default_rng(seed)
    boxes = _BoxList()
    cyl: list[tuple[float, float, float, float, float]] = []
    half_w, x_lo, x_hi = width / 2, -length / 2, length / 2
    kerb = half_w - _SIDEWALK
    if corridor:
        for side in (1, -1):
            _corridor_side(
                boxes, rng, side, half_w, x_lo - _CORRIDOR_EXTENSION, x_hi + _CORRIDOR_EXTENSION
            )
        bmin, bmax = boxes.arrays()
        return Scene(bmin, bmax, np.zeros((0, 5)), 0.0)

    for side in (1, -1):
        gaps: list[tuple[float, float]] = []
        x = x_lo
        while x_hi - x > 4.0:
            u1 = x + rng.uniform(8.0, 30.0)
            if x_hi - u1 < 8.0:
                u1 = x_hi
            setback = 0.0 if rng.random() < 0.6 else rng.uniform(0.3, 1.5)
            _building(
                boxes,
                rng,
                side,
                half_w + setback,
                x,
                u1,
                rng.uniform(6.0, 25.0),
                rng.uniform(10.0, 20.0),
            )
            x = u1
            if x_hi - x > 12.0 and rng.random() < 0.3:  # side street / gap between blocks
                g1 = x + rng.uniform(5.0, 14.0)
                gaps.append((x, g1))
                if rng.random() < 0.6:  # a building across the side street, seen through it
                    y0 = half_w + rng.uniform(22.0, 40.0)
                    boxes.facade(
                        side, 0.0, x - 6.0, g1 + 6.0, y0, y0 + 12.0, 0.0, rng.uniform(8.0, 20.0)
                    )
                x = g1

        def in_gap(xc: float, margin: float, gaps: list[tuple[float, float]] = gaps) -> bool:
            return any(a - margin < xc < b + margin for a, b in gaps)

        # Parked cars along the kerb (two boxes: body and cabin), none in front of side streets.
        x = x_lo + rng.uniform(0.0, 6.0)
        while x < x_hi - 5.0:
            car_len = rng.uniform(4.2, 4.8)
            if rng.random() < 0.65 and not in_gap(x + car_len / 2, car_len / 2 + 1.0):
                w = rng.uniform(1.7, 1.9)
                yc = kerb - 0.25 - w / 2
                c0, c1 = x + 0.25 * car_len, x + 0.8 * car_len
                boxes.facade(side, 0.0, x, x + car_len, yc - w / 2, yc + w / 2, 0.25, 1.05)
                boxes.facade(
                    side,
                    0.0,
                    c0,
                    c1,
                    yc - w / 2 + 0.1,
                    yc + w / 2 - 0.1,
                    1.05,
                    rng.uniform(1.4, 1.6),
                )
            x += (
                car_len
                + rng.uniform(0.8, 3.0)
                + (rng.uniform(5.0, 15.0) if rng.random() < 0.15 else 0.0)
            )

        # Street furniture on the sidewalk: tree trunks, lamp posts, sign posts.
        x = x_lo + rng.uniform(2.0, 8.0)
        while x < x_hi - 2.0:
            if not in_gap(x, 1.0) and rng.random() < 0.6:
                cyl.append(
                    (x, side * (kerb + 1.2), rng.uniform(0.12, 0.3), 0.0, rng.uniform(2.5, 4.5))
                )
            x += rng.uniform(7.0, 14.0)
        x = x_lo + rng.uniform(5.0, 20.0)
        while x < x_hi - 2.0:
            if not in_gap(x, 0.5):
                cyl.append(
                    (x, side * (kerb + 0.5), rng.uniform(0.08, 0.12), 0.0, rng.uniform(6.0, 8.0))
                )
            x += rng.uniform(22.0, 32.0)
        for _ in range(rng.integers(3, 7)):
            xs = rng.uniform(x_lo + 2.0, x_hi - 2.0)
            if in_gap(xs, 0.5):
                continue
            top = rng.uniform(2.2, 2.8)
            ys = side * (kerb + 0.35)
            cyl.append((xs, ys, 0.04, 0.0, top))
            boxes.add(xs - 0.02, xs + 0.02, ys - 0.3, ys + 0.3, top - 0.2, top + 0.4)  # plate

    bmin, bmax = boxes.arrays()
    return Scene(bmin, bmax, np.array(cyl, dtype=np.float64).reshape(-1, 5), 0.0)


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


def _cast(scene: Scene, origin: np.ndarray, dirs: np.ndarray, max_range: float) -> np.ndarray:
    """Distance (m) along unit world rays ``dirs`` from ``origin`` to the first surface hit;
    ``max_range`` where nothing is hit closer."""
    t_best = np.full(len(dirs), float(max_range))
    down = dirs[:, 2] < -1e-12
    t_best[down] = np.minimum(t_best[down], -origin[2] / dirs[down, 2])  # ground plane z = 0
    t_best[t_best < 0] = max_range  # origin below ground: no ground hit

    az = np.arctan2(dirs[:, 1], dirs[:, 0])
    order = np.argsort(az, kind="stable")
    sorted_az = az[order]
    with np.errstate(divide="ignore"):
        inv = 1.0 / np.where(dirs == 0.0, 1e-300, dirs)  # huge but finite-safe slab inverses
    ox, oy = origin[0], origin[1]

    # --- boxes -----------------------------------------------------------------------------
    bmin, bmax = scene.boxes_min, scene.boxes_max
    if len(bmin):
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

    # --- vertical cylinders with caps --------------------------------------------------------
    cyl = scene.cylinders
    if len(cyl):
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
    return t_best


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
    elevation; the noise is drawn from ``np.random.default_rng(seed)``.
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
    t = _cast(scene, T[:3, 3].copy(), dirs_world, max_range)
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
) -> tuple[Scene, list[np.ndarray], list[np.ndarray]]:
    """Scan a street (``make_street(seed, corridor=corridor)``) from ``n_scans`` standpoints.

    Standpoints run along the street (x), centred on x = 0, consecutive ones ``spacing`` m apart
    (uniform draw), with lateral offsets uniform in +-3 m around the centre line, scanner
    height 1.6 m, yaw uniform in [-180, 180) deg and roll/pitch uniform in +-``tilt_deg`` deg.
    All draws come from ``np.random.default_rng(seed)``. ``scan_kwargs`` is passed on to
    :func:`simulate_scan` (its ``seed`` defaults to a per-scan seed from the same generator).

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
