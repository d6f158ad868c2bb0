"""Street scenes for the simulator: buildings with facade relief, cars, poles and trees.

Units are metres. World frame: right-handed, z up. By default the ground is the plane z = 0 and
the street runs along x, centred on y = 0; a street may also be placed anywhere at any heading
(``origin``, ``axis_deg``) on a sloped, cambered ground (:class:`~ndt_cli.sim.ground.Ground`),
with tree crowns, and scenes can be merged (a junction, a block walked around). Deterministic in
the seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ndt_cli.sim.ground import Ground

# Street cross-section (metres, measured from the street centre line y = 0).
_SIDEWALK = 3.0  # sidewalk width between kerb and facade line
_CORRIDOR_EXTENSION = 150.0  # corridor facades run this far beyond each street end


@dataclass(frozen=True, eq=False)
class Scene:
    """Static street scene in the world frame (metres; z up).

    Attributes:
        boxes_min: (B, 3) float64 lower corners (x, y, z) of boxes (buildings, facade relief,
            cars, signs), in the box's own axes: box k holds the points p with
            ``boxes_min[k] <= Rz(-boxes_yaw[k]) p <= boxes_max[k]``.
        boxes_max: (B, 3) float64 upper corners of the same boxes.
        cylinders: (C, 5) float64 vertical cylinders ``x, y, radius, z_min, z_max``
            (poles, tree trunks), closed by flat caps.
        street_axis_deg: direction of the (first) street axis in the world frame, degrees
            from +x.
        boxes_yaw: (B,) float64 heading of each box's axes (radians about world z; default 0:
            axis-aligned).
        crowns: (K, 7) float64 porous vertical ellipsoids ``x, y, z, rx, ry, rz, density``
            (tree crowns): a ray through one is stopped at an exponentially distributed depth
            of mean ``1 / density`` m, drawn per scan (foliage differs between scans).
        ground: the ground surface (default: the plane z = 0).
    """

    boxes_min: np.ndarray
    boxes_max: np.ndarray
    cylinders: np.ndarray
    street_axis_deg: float = 0.0
    boxes_yaw: np.ndarray | None = None
    crowns: np.ndarray | None = None
    ground: Ground = field(default_factory=Ground)

    def __post_init__(self) -> None:
        bmin = np.array(self.boxes_min, dtype=np.float64).reshape(-1, 3)
        bmax = np.array(self.boxes_max, dtype=np.float64).reshape(-1, 3)
        cyl = np.array(self.cylinders, dtype=np.float64).reshape(-1, 5)
        yaw = np.zeros(len(bmin)) if self.boxes_yaw is None else np.array(self.boxes_yaw, float)
        crowns = np.zeros((0, 7)) if self.crowns is None else np.array(self.crowns, float)
        crowns = crowns.reshape(-1, 7)
        if bmin.shape != bmax.shape or yaw.shape != (len(bmin),):
            raise ValueError("boxes_min, boxes_max (B, 3) and boxes_yaw (B,) must agree")
        if np.any(bmax < bmin):
            raise ValueError("every box needs boxes_max >= boxes_min")
        if np.any(cyl[:, 2] <= 0) or np.any(cyl[:, 4] < cyl[:, 3]):
            raise ValueError("cylinders need radius > 0 and z_max >= z_min")
        if np.any(crowns[:, 3:] <= 0):
            raise ValueError("crowns need positive radii and density")
        arrays = {"boxes_min": bmin, "boxes_max": bmax, "cylinders": cyl}
        arrays.update(boxes_yaw=yaw, crowns=crowns)
        for name, arr in arrays.items():
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "street_axis_deg", float(self.street_axis_deg))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Scene):
            return NotImplemented
        return (
            self.street_axis_deg == other.street_axis_deg
            and self.ground == other.ground
            and all(
                np.array_equal(getattr(self, n), getattr(other, n))
                for n in ("boxes_min", "boxes_max", "cylinders", "boxes_yaw", "crowns")
            )
        )

    __hash__ = None  # type: ignore[assignment]  # mutable-looking arrays: not hashable

    def ground_z(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        """Ground height (m) at world (x, y)."""
        return self.ground.z(x, y)

    def merged(self, *others: Scene) -> Scene:
        """This scene and ``others`` in one (they must share the ground): streets of a
        junction, or a street and the people and cars passing during one scan."""
        scenes = (self, *others)
        if any(o.ground != self.ground for o in others):
            raise ValueError("merged scenes must share one ground")
        return Scene(
            np.vstack([s.boxes_min for s in scenes]),
            np.vstack([s.boxes_max for s in scenes]),
            np.vstack([s.cylinders for s in scenes]),
            self.street_axis_deg,
            np.concatenate([s.boxes_yaw for s in scenes]),
            np.vstack([s.crowns for s in scenes]),
            self.ground,
        )

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Boolean mask of world points strictly inside a box or cylinder shrunk by ``margin`` m
        (crowns are porous and not counted)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        inside = np.zeros(len(pts), dtype=bool)
        step = max(1, 2_000_000 // max(1, len(self.boxes_min) + len(self.cylinders)))
        c, s = np.cos(self.boxes_yaw)[None], np.sin(self.boxes_yaw)[None]
        for k in range(0, len(pts), step):
            p = pts[k : k + step]
            lo = self.boxes_min[None] + margin
            hi = self.boxes_max[None] - margin
            bx = c * p[:, None, 0] + s * p[:, None, 1]  # the points in each box's axes
            by = -s * p[:, None, 0] + c * p[:, None, 1]
            q = np.stack([bx, by, np.broadcast_to(p[:, None, 2], bx.shape)], axis=2)
            in_box = np.all((q > lo) & (q < hi), axis=2).any(axis=1)
            cy = self.cylinders
            d2 = (p[:, None, 0] - cy[None, :, 0]) ** 2 + (p[:, None, 1] - cy[None, :, 1]) ** 2
            r = np.maximum(cy[None, :, 2] - margin, 0.0)
            in_cyl = (
                (d2 < r**2)
                & (p[:, None, 2] > cy[None, :, 3] + margin)
                & (p[:, None, 2] < cy[None, :, 4] - margin)
            ).any(axis=1)
            inside[k : k + step] = in_box | in_cyl
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


@dataclass
class _Side:
    """One side of the street (``sign`` +1: y > 0) and the gaps between its blocks."""

    sign: int
    half_w: float  # m, street centre to facade line
    kerb: float  # m, street centre to kerb
    x_lo: float
    x_hi: float
    gaps: list[tuple[float, float]] = field(default_factory=list)

    def in_gap(self, xc: float, margin: float) -> bool:
        return any(a - margin < xc < b + margin for a, b in self.gaps)


def _blocks(boxes: _BoxList, rng: np.random.Generator, side: _Side) -> None:
    """Buildings along one side, with side streets (gaps) between some of them."""
    x = side.x_lo
    while side.x_hi - x > 4.0:
        u1 = x + rng.uniform(8.0, 30.0)
        if side.x_hi - u1 < 8.0:
            u1 = side.x_hi
        setback = 0.0 if rng.random() < 0.6 else rng.uniform(0.3, 1.5)
        height, depth = rng.uniform(6.0, 25.0), rng.uniform(10.0, 20.0)
        _building(boxes, rng, side.sign, side.half_w + setback, x, u1, height, depth)
        x = u1
        if side.x_hi - x > 12.0 and rng.random() < 0.3:  # side street / gap between blocks
            g1 = x + rng.uniform(5.0, 14.0)
            side.gaps.append((x, g1))
            if rng.random() < 0.6:  # a building across the side street, seen through it
                y0 = side.half_w + rng.uniform(22.0, 40.0)
                top = rng.uniform(8.0, 20.0)
                boxes.facade(side.sign, 0.0, x - 6.0, g1 + 6.0, y0, y0 + 12.0, 0.0, top)
            x = g1


def _parked_cars(boxes: _BoxList, rng: np.random.Generator, side: _Side) -> None:
    """Cars along the kerb (two boxes: body and cabin), none in front of side streets."""
    x = side.x_lo + rng.uniform(0.0, 6.0)
    while x < side.x_hi - 5.0:
        car_len = rng.uniform(4.2, 4.8)
        if rng.random() < 0.65 and not side.in_gap(x + car_len / 2, car_len / 2 + 1.0):
            w = rng.uniform(1.7, 1.9)
            yc = side.kerb - 0.25 - w / 2
            y0, y1 = yc - w / 2, yc + w / 2
            c0, c1 = x + 0.25 * car_len, x + 0.8 * car_len
            boxes.facade(side.sign, 0.0, x, x + car_len, y0, y1, 0.25, 1.05)
            boxes.facade(side.sign, 0.0, c0, c1, y0 + 0.1, y1 - 0.1, 1.05, rng.uniform(1.4, 1.6))
        x += car_len + rng.uniform(0.8, 3.0) + (rng.uniform(5, 15) if rng.random() < 0.15 else 0)


def _furniture(
    boxes: _BoxList, cyl: list[tuple[float, ...]], rng: np.random.Generator, side: _Side
) -> None:
    """Street furniture on the sidewalk: tree trunks, lamp posts, sign posts with plates."""
    kerb, sign = side.kerb, side.sign
    x = side.x_lo + rng.uniform(2.0, 8.0)
    while x < side.x_hi - 2.0:
        if not side.in_gap(x, 1.0) and rng.random() < 0.6:
            cyl.append((x, sign * (kerb + 1.2), rng.uniform(0.12, 0.3), 0.0, rng.uniform(2.5, 4.5)))
        x += rng.uniform(7.0, 14.0)
    x = side.x_lo + rng.uniform(5.0, 20.0)
    while x < side.x_hi - 2.0:
        if not side.in_gap(x, 0.5):
            cyl.append(
                (x, sign * (kerb + 0.5), rng.uniform(0.08, 0.12), 0.0, rng.uniform(6.0, 8.0))
            )
        x += rng.uniform(22.0, 32.0)
    for _ in range(rng.integers(3, 7)):
        xs = rng.uniform(side.x_lo + 2.0, side.x_hi - 2.0)
        if side.in_gap(xs, 0.5):
            continue
        top = rng.uniform(2.2, 2.8)
        ys = sign * (kerb + 0.35)
        cyl.append((xs, ys, 0.04, 0.0, top))
        boxes.add(xs - 0.02, xs + 0.02, ys - 0.3, ys + 0.3, top - 0.2, top + 0.4)  # plate


def make_street(
    seed: int = 0,
    length: float = 260.0,
    width: float = 18.0,
    *,
    corridor: bool = False,
    origin: tuple[float, float] = (0.0, 0.0),
    axis_deg: float = 0.0,
    ground: Ground | None = None,
    trees: bool = False,
    clear: tuple[tuple[float, float, float, float], ...] = (),
) -> Scene:
    """Build a straight street, by default along the world x axis, centred on the origin.

    ``length`` (m) is the street length (x in [-length/2, length/2] along the street) and
    ``width`` (m) the facade-to-facade distance (facade lines at +-width/2, behind 3 m
    sidewalks). The street has blocks 8-30 m wide and 6-25 m high with 10-20 m depth, gaps /
    side streets, facade relief of 0.1-0.6 m, parked cars at both kerbs, lamp posts, sign posts
    and tree trunks. ``corridor=True`` gives the degenerate case: one gap-free facade per side
    that is uniform along x and extends 150 m beyond both street ends, no cars, no poles.

    Placement: the street's centre is at world ``origin`` (x, y) and its axis at ``axis_deg``
    from +x; it stands on ``ground`` (every object keeps its height above the ground in front
    of it, and objects that reach the ground reach down into it). ``trees``: a porous crown on
    every trunk. ``clear``: rectangles ``(x0, x1, y0, y1)`` in the street's own frame (x along
    it, y across, m) left empty of objects, e.g. where a side street joins. Deterministic in
    ``seed``; with the defaults the scene is the one earlier versions built.
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
    else:
        for sign in (1, -1):
            side = _Side(sign, half_w, kerb, x_lo, x_hi)
            _blocks(boxes, rng, side)
            _parked_cars(boxes, rng, side)
            _furniture(boxes, cyl, rng, side)
    bmin, bmax = boxes.arrays()
    cylinders = np.array(cyl, dtype=np.float64).reshape(-1, 5)
    crowns = _crowns(cylinders, kerb, seed) if trees else np.zeros((0, 7))
    local = _cleared(Scene(bmin, bmax, cylinders, 0.0, crowns=crowns), clear)
    return placed(local, np.asarray(origin, dtype=float), axis_deg, ground or Ground())


def _crowns(cylinders: np.ndarray, kerb: float, seed: int) -> np.ndarray:
    """A porous crown above every tree trunk (the trunks stand 1.2 m behind the kerb), drawn
    from a generator of their own so that the rest of the street does not change."""
    rng = np.random.default_rng([seed, 2])
    trunks = cylinders[np.isclose(np.abs(cylinders[:, 1]), kerb + 1.2)]
    n = len(trunks)
    r = rng.uniform(1.5, 3.0, n)
    rz = rng.uniform(1.5, 2.8, n)
    z = trunks[:, 4] + 0.7 * rz
    density = rng.uniform(0.6, 2.0, n)
    return np.column_stack([trunks[:, 0], trunks[:, 1], z, r, r, rz, density])


def _cleared(scene: Scene, rects: tuple[tuple[float, float, float, float], ...]) -> Scene:
    """The scene without the objects whose footprint meets one of the rectangles
    ``(x0, x1, y0, y1)`` (axis-aligned scene, m)."""
    if not rects:
        return scene
    keep_b = np.ones(len(scene.boxes_min), dtype=bool)
    keep_c = np.ones(len(scene.cylinders), dtype=bool)
    keep_k = np.ones(len(scene.crowns), dtype=bool)
    for x0, x1, y0, y1 in rects:
        lo, hi = scene.boxes_min, scene.boxes_max
        keep_b &= ~((lo[:, 0] < x1) & (hi[:, 0] > x0) & (lo[:, 1] < y1) & (hi[:, 1] > y0))
        for keep, arr, r in ((keep_c, scene.cylinders, 2), (keep_k, scene.crowns, 3)):
            x, y, rad = arr[:, 0], arr[:, 1], arr[:, r]
            keep &= ~((x + rad > x0) & (x - rad < x1) & (y + rad > y0) & (y - rad < y1))
    return Scene(
        scene.boxes_min[keep_b],
        scene.boxes_max[keep_b],
        scene.cylinders[keep_c],
        scene.street_axis_deg,
        crowns=scene.crowns[keep_k],
    )


def placed(local: Scene, origin: np.ndarray, axis_deg: float, ground: Ground) -> Scene:
    """An axis-aligned street on flat ground, turned to ``axis_deg``, moved to ``origin`` and
    set on ``ground``. The defaults return it unchanged."""
    if axis_deg == 0.0 and not origin.any() and ground.flat:
        return local
    a = np.radians(axis_deg)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    shift = R.T @ origin  # the origin in the turned axes: boxes are stored in those
    lo, hi = local.boxes_min.copy(), local.boxes_max.copy()
    lo[:, :2] += shift
    hi[:, :2] += shift
    y0, y1 = local.boxes_min[:, 1], local.boxes_max[:, 1]
    near_y = np.where(y0 > 0, y0, np.where(y1 < 0, y1, 0.0)) + shift[1]  # the side facing the axis
    front = np.column_stack([0.5 * (lo[:, 0] + hi[:, 0]), near_y])
    base = ground.z(*(front @ R.T).T)  # the ground in front of each box
    corners = [
        (lo[:, 0], lo[:, 1]),
        (lo[:, 0], hi[:, 1]),
        (hi[:, 0], lo[:, 1]),
        (hi[:, 0], hi[:, 1]),
    ]
    low = np.min([ground.z(*(np.column_stack(c) @ R.T).T) for c in corners], axis=0)
    touching = local.boxes_min[:, 2] <= 1e-9
    lo[:, 2] = np.where(touching, low - 0.3, lo[:, 2] + base)
    hi[:, 2] += base
    cyl, crowns = local.cylinders.copy(), local.crowns.copy()
    cyl[:, :2] = cyl[:, :2] @ R.T + origin
    g = ground.z(cyl[:, 0], cyl[:, 1])
    cyl[:, 3] = np.where(cyl[:, 3] <= 1e-9, g - 0.3, cyl[:, 3] + g)
    cyl[:, 4] += g
    crowns[:, :2] = crowns[:, :2] @ R.T + origin
    crowns[:, 2] += ground.z(crowns[:, 0], crowns[:, 1])
    yaw = np.full(len(lo), a)
    return Scene(lo, hi, cyl, axis_deg, yaw, crowns, ground)
