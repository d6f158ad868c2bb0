"""Street scenes for the simulator: buildings with facade relief, cars, poles and trees.

Units are metres. World frame: right-handed, z up, the ground is the plane z = 0, the street runs
along x and is centred on y = 0. Deterministic in the seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Street cross-section (metres, measured from the street centre line y = 0).
_SIDEWALK = 3.0  # sidewalk width between kerb and facade line
_CORRIDOR_EXTENSION = 150.0  # corridor facades run this far beyond each street end


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

    for sign in (1, -1):
        side = _Side(sign, half_w, kerb, x_lo, x_hi)
        _blocks(boxes, rng, side)
        _parked_cars(boxes, rng, side)
        _furniture(boxes, cyl, rng, side)

    bmin, bmax = boxes.arrays()
    return Scene(bmin, bmax, np.array(cyl, dtype=np.float64).reshape(-1, 5), 0.0)
