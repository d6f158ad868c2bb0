"""Building interiors for the simulator: one floor of an office building, its rooms, doors,
furniture and columns, and standpoints in its corridors and rooms.

Interiors are where a registration is most easily fooled: right angles everywhere, rooms of
one size repeated along a corridor, a corridor that looks the same turned by 180 degrees. A
:class:`FloorWorld` describes a floor plan and where it is scanned; :func:`scan_floor`
simulates it.

Frames and units as in :mod:`ndt_cli.sim.scanner`: metres, world z up, the floor is the plane
z = 0, ``T_world_scan`` maps scanner points into the world. Layouts (``layout``):

- ``double``: a corridor along x with rooms on both sides (an office floor);
- ``single``: rooms on one side, windows along the other side of the corridor;
- ``open``: an open-plan hall with a grid of columns and rows of desks, and a corridor of
  rooms along one side.

Deterministic in the seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.sim.scanner import scanner_pose, simulate_scan
from ndt_cli.sim.scene import Scene

_PARTITION = 0.12  # m, walls between rooms
_INNER = 0.15  # m, corridor walls
_OUTER = 0.30  # m, exterior walls
_DOOR_H = 2.1  # m, door openings
_LEAF = 0.04  # m, door leaves
_SILL, _HEAD = 0.9, 2.3  # m, windows


@dataclass(frozen=True)
class FloorWorld:
    """One floor and its standpoints.

    ``length`` (m) of the corridor (along x), ``corridor_width`` (m), ``room_depth`` (m, each
    side draws one), ``module`` (m: rooms are one or two modules wide, so their sizes repeat),
    ``ceiling`` (m above the floor), ``closed`` (share of doors closed), ``furniture`` (0: empty
    rooms, 1: an office's, 2: crowded), ``columns`` (pilasters along the corridor walls, free
    columns in open plan), ``windows`` (in the exterior walls), ``spacing`` (m between corridor
    standpoints, uniform draw), ``room_scans`` (standpoints in rooms whose door is open, each
    between two corridor standpoints), ``rays`` (azimuths x elevations), ``tilt_deg`` (each
    scanner's roll and pitch, uniform in +-tilt).
    """

    seed: int = 0
    layout: str = "double"
    length: float = 44.0
    corridor_width: float = 2.4
    room_depth: tuple[float, float] = (4.5, 6.0)
    module: float = 3.6
    ceiling: float = 3.0
    closed: float = 0.3
    furniture: float = 1.0
    columns: bool = True
    windows: bool = True
    spacing: tuple[float, float] = (6.0, 12.0)
    room_scans: int = 2
    rays: tuple[int, int] = (1440, 160)
    tilt_deg: float = 0.0
    range_noise: float = 0.005

    def describe(self) -> str:
        """A short label of the floor."""
        parts = [f"seed {self.seed}", f"{self.layout} floor {self.length:g} m"]
        parts.append(f"corridor {self.corridor_width:g} m, ceiling {self.ceiling:g} m")
        parts.append(f"{self.closed:.0%} doors closed, furniture {self.furniture:g}")
        if self.tilt_deg:
            parts.append(f"tilt {self.tilt_deg:g} deg")
        return ", ".join(parts)


class _Plan:
    """Boxes (optionally turned: ``yaw`` about z, radians) and columns of a floor, in world
    coordinates, and the open doors' rooms where a scanner can stand."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, ...]] = []
        self.cylinders: list[tuple[float, ...]] = []
        self.rooms: list[tuple[float, float, float, float, bool]] = []  # x0 x1 y0 y1 door open
        self.walks: list[tuple[float, float]] = []  # lines along x scanned: centre y, +-spread

    def box(self, x0: float, x1: float, y0: float, y1: float, z0: float, z1: float) -> None:
        if x1 > x0 and y1 > y0 and z1 > z0:
            self.rows.append((x0, y0, z0, x1, y1, z1, 0.0))

    def turned(
        self, cx: float, cy: float, w: float, d: float, z: tuple[float, float], yaw: float
    ) -> None:
        """A box ``w`` x ``d`` m centred at (cx, cy), turned by ``yaw`` rad, from z[0] to z[1]."""
        c, s = np.cos(-yaw), np.sin(-yaw)
        ux, uy = c * cx - s * cy, s * cx + c * cy  # the centre in the box's own axes
        self.rows.append((ux - w / 2, uy - d / 2, z[0], ux + w / 2, uy + d / 2, z[1], yaw))

    def leaf(self, hx: float, hy: float, width: float, angle: float) -> None:
        """A door leaf hinged at (hx, hy), ``angle`` rad from +x, 2.0 m high."""
        c, s = np.cos(angle), np.sin(angle)
        cx, cy = hx + 0.5 * width * c, hy + 0.5 * width * s
        self.turned(cx, cy, width, _LEAF, (0.01, 2.0), angle)

    def scene(self) -> Scene:
        arr = np.array(self.rows, dtype=np.float64).reshape(-1, 7)
        cyl = np.array(self.cylinders, dtype=np.float64).reshape(-1, 5)
        return Scene(arr[:, :3], arr[:, 3:6], cyl, 0.0, arr[:, 6])


def _wall_x(
    plan: _Plan, y0: float, y1: float, x0: float, x1: float, top: float, gaps: list
) -> None:
    """A wall along x from x0 to x1 (thickness y0..y1) with openings ``(a, b, sill, head)``."""
    for a, b, z0, z1 in _wall_pieces(x0, x1, top, gaps):
        plan.box(a, b, y0, y1, z0, z1)


def _wall_y(
    plan: _Plan, x0: float, x1: float, y0: float, y1: float, top: float, gaps: list
) -> None:
    """A wall along y from y0 to y1 (thickness x0..x1) with openings ``(a, b, sill, head)``."""
    for a, b, z0, z1 in _wall_pieces(y0, y1, top, gaps):
        plan.box(x0, x1, a, b, z0, z1)


def _wall_pieces(lo: float, hi: float, top: float, gaps: list) -> list[tuple[float, ...]]:
    """The solid parts ``(from, to, z0, z1)`` of a wall from ``lo`` to ``hi`` along its length,
    ``top`` high, with openings ``(a, b, sill, head)``: the piers between the openings, the
    parapets below windows (none below a door: sill 0) and the lintels above."""
    edges = [lo]
    for a, b, _, _ in sorted(gaps):
        edges += [a, b]
    edges.append(hi)
    out = [(a, b, -0.3, top) for a, b in zip(edges[::2], edges[1::2], strict=True)]
    for a, b, sill, head in gaps:
        out += [(a, b, -0.3, sill), (a, b, head, top)]
    return out


def _widths(rng: np.random.Generator, length: float, module: float) -> list[float]:
    """Room widths along a corridor: mostly one module, some two (sizes repeat)."""
    out: list[float] = []
    left = length
    while left > 1.5 * module:
        w = module * (2 if rng.random() < 0.25 and left > 3 * module else 1)
        out.append(w)
        left -= w
    out.append(left)
    return out


def _rooms_side(
    plan: _Plan, rng: np.random.Generator, world: FloorWorld, side: int, y_wall: float
) -> None:
    """Rooms along one side of the corridor: ``y_wall`` is the corridor face of their wall,
    ``side`` +1 (rooms at y > y_wall) or -1."""
    depth = rng.uniform(*world.room_depth)
    top = world.ceiling + 0.05
    near, far = y_wall, y_wall + side * (_INNER + depth)
    lo, hi = min(near, far), max(near, far)
    x, doors = 0.0, []
    for w in _widths(rng, world.length, world.module):
        x0, x1 = x, x + w
        if x0 > 0.0:
            plan.box(x0 - _PARTITION / 2, x0 + _PARTITION / 2, lo, hi, -0.3, top)
        door_w = rng.uniform(0.9, 1.0)
        at = x0 + 0.4 if rng.random() < 0.5 else x1 - 0.4 - door_w  # near a partition
        doors.append((at, at + door_w, 0.0, _DOOR_H))
        is_open = _door(plan, rng, world, side, y_wall, at, door_w)
        room = (x0 + _PARTITION / 2, x1 - _PARTITION / 2, lo, hi)
        if side > 0:
            room = (room[0], room[1], near + _INNER, far)
        else:
            room = (room[0], room[1], far, near - _INNER)
        plan.rooms.append((*room, is_open))
        _furnish(plan, rng, world.furniture, room, side, (at, at + door_w))
        x = x1
    wall = (y_wall, y_wall + _INNER) if side > 0 else (y_wall - _INNER, y_wall)
    _wall_x(plan, *wall, 0.0, world.length, top, doors)
    outer = (far, far + _OUTER) if side > 0 else (far - _OUTER, far)
    _wall_x(plan, *outer, -_OUTER, world.length + _OUTER, top, _windows(rng, world))


def _door(
    plan: _Plan,
    rng: np.random.Generator,
    world: FloorWorld,
    side: int,
    y_wall: float,
    at: float,
    width: float,
) -> bool:
    """The leaf of a door in the corridor wall: closed, or open into the room at an angle.
    Returns whether it is open wide enough to see into the room."""
    hinge_left = rng.random() < 0.5
    hx = at + 0.02 if hinge_left else at + width - 0.02
    if rng.random() < world.closed:
        plan.box(
            at + 0.02,
            at + width - 0.02,
            *sorted((y_wall + side * 0.05, y_wall + side * 0.09)),
            0.0,
            2.0,
        )
        return False
    swing = np.radians(rng.uniform(25.0, 110.0))
    base = 0.0 if hinge_left else np.pi  # the closed leaf points along +x or -x from its hinge
    angle = base + side * swing * (1.0 if hinge_left else -1.0)
    plan.leaf(hx, y_wall + side * (_INNER + 0.03), width - 0.04, angle)
    return swing > np.radians(45.0)


def _windows(rng: np.random.Generator, world: FloorWorld) -> list[tuple[float, ...]]:
    """Window openings along an exterior wall: one per module, 1.2-2.0 m wide."""
    if not world.windows:
        return []
    head = min(_HEAD, world.ceiling - 0.3)
    out = []
    n = int(world.length // world.module)
    for k in range(n):
        w = rng.uniform(1.2, 2.0)
        c = (k + 0.5) * world.module
        out.append((c - w / 2, c + w / 2, _SILL, head))
    return out


def _furnish(
    plan: _Plan,
    rng: np.random.Generator,
    amount: float,
    room: tuple[float, float, float, float],
    side: int,
    door: tuple[float, float],
) -> None:
    """Desks with monitors, shelves, cabinets and chairs along a room's walls; the room's
    middle and the swing of its door stay free."""
    _, _, y0, y1 = room
    n = rng.poisson(3.0 * amount) if amount > 0 else 0
    back = y1 - 0.05 if side > 0 else y0 + 0.05  # the exterior wall's face
    for _ in range(n):
        kind = rng.choice(["desk", "shelf", "cabinet", "chair"], p=[0.35, 0.25, 0.2, 0.2])
        _piece(plan, rng, kind, room, back, side, door)


def _piece(
    plan: _Plan,
    rng: np.random.Generator,
    kind: str,
    room: tuple[float, float, float, float],
    back: float,
    side: int,
    door: tuple[float, float],
) -> None:
    """One piece of furniture against a wall (the back wall or a partition)."""
    x0, x1, y0, y1 = room
    w, d, h = {
        "desk": (rng.uniform(1.2, 1.8), rng.uniform(0.7, 0.8), 0.74),
        "shelf": (rng.uniform(0.8, 2.0), rng.uniform(0.35, 0.45), rng.uniform(1.1, 2.2)),
        "cabinet": (rng.uniform(0.8, 1.2), rng.uniform(0.45, 0.6), rng.uniform(0.75, 1.3)),
        "chair": (0.5, 0.5, rng.uniform(0.9, 1.1)),
    }[kind]
    if rng.random() < 0.6:  # against the back wall
        cx = rng.uniform(x0 + w / 2 + 0.05, max(x0 + w / 2 + 0.06, x1 - w / 2 - 0.05))
        cy = back - side * (d / 2 + (0.6 if kind == "chair" else 0.0))
        yaw = 0.0
    else:  # against a partition
        left = rng.random() < 0.5
        cx = x0 + d / 2 + 0.03 if left else x1 - d / 2 - 0.03
        cy = (
            rng.uniform(min(y0, y1) + 1.6, max(y0, y1) - 0.3)
            if abs(y1 - y0) > 2.2
            else 0.5 * (y0 + y1)
        )
        yaw = np.pi / 2
    if door[0] - 1.1 < cx < door[1] + 1.1 and abs(cy - (y0 if side > 0 else y1)) < 1.3:
        return  # in the door's swing
    plan.turned(cx, cy, w, d, (0.0, h), yaw)
    if kind == "desk":  # a monitor on it
        plan.turned(cx, cy, 0.55, 0.08, (h, 1.2), yaw)


def _shell(plan: _Plan, world: FloorWorld, y_lo: float, y_hi: float) -> None:
    """End walls (a window at each corridor end), the ceiling slab and the corridor's own
    fittings: pilasters along its walls."""
    top = world.ceiling + 0.05
    half = world.corridor_width / 2
    end = (
        [(-half + 0.3, half - 0.3, _SILL, min(_HEAD, world.ceiling - 0.3))] if world.windows else []
    )
    for x0, x1 in ((-_OUTER, 0.0), (world.length, world.length + _OUTER)):
        _wall_y(plan, x0, x1, y_lo - _OUTER, y_hi + _OUTER, top, end)
    plan.box(
        -_OUTER, world.length + _OUTER, y_lo - _OUTER, y_hi + _OUTER, world.ceiling, top + 0.25
    )


def _pilasters(plan: _Plan, world: FloorWorld, faces: tuple[float, ...]) -> None:
    """Columns engaged in the corridor walls every two modules (0.4 m wide, 0.15 m proud)."""
    if not world.columns:
        return
    for y in faces:
        inward = -np.sign(y)
        for x in np.arange(2 * world.module, world.length - 1.0, 2 * world.module):
            a, b = sorted((y, y + inward * 0.15))
            plan.box(x - 0.2, x + 0.2, a, b, 0.0, world.ceiling)


def _hall(plan: _Plan, rng: np.random.Generator, world: FloorWorld, y_wall: float) -> float:
    """An open-plan hall beside the corridor (y < ``y_wall``): a grid of columns, desk
    islands with screens. Returns the y of its exterior wall's face."""
    depth = rng.uniform(12.0, 16.0)
    far = y_wall - depth
    top = world.ceiling + 0.05
    _wall_x(plan, far - _OUTER, far, -_OUTER, world.length + _OUTER, top, _windows(rng, world))
    for x in np.arange(world.module * 2, world.length - 1.0, world.module * 2):
        for y in np.arange(y_wall - 4.0, far + 2.0, -6.0):
            if world.columns:
                plan.box(x - 0.25, x + 0.25, y - 0.25, y + 0.25, 0.0, world.ceiling)
            if world.furniture > 0 and rng.random() < 0.6 * world.furniture:
                cx = x + world.module + rng.uniform(-0.4, 0.4)
                plan.turned(cx, y, 3.2, 1.6, (0.0, 0.74), 0.0)  # two desks face to face
                plan.turned(cx, y, 3.2, 0.04, (0.74, 1.25), 0.0)  # a screen between them
    plan.walks.append((0.5 * (far + y_wall) - 1.0, 2.0))  # between the rows of columns
    return far


def floor_scene(world: FloorWorld) -> tuple[Scene, _Plan]:
    """The floor's static scene and its plan (rooms where a scanner can stand)."""
    rng = np.random.default_rng([world.seed, 21])
    plan = _Plan()
    half = world.corridor_width / 2
    top = world.ceiling + 0.05
    plan.walks.append((0.0, half - 0.45))
    _rooms_side(plan, rng, world, 1, half)
    y_hi = max(r[3] for r in plan.rooms)
    if world.layout == "double":
        _rooms_side(plan, rng, world, -1, -half)
        y_lo = min(r[2] for r in plan.rooms)
        _pilasters(plan, world, (half, -half))
    elif world.layout == "single":
        _wall_x(
            plan, -half - _OUTER, -half, -_OUTER, world.length + _OUTER, top, _windows(rng, world)
        )
        y_lo = -half
        _pilasters(plan, world, (half,))
    elif world.layout == "open":
        y_lo = _hall(plan, rng, world, -half)
        _pilasters(plan, world, (half,))
    else:
        raise ValueError(f"unknown layout {world.layout!r} (double, single, open)")
    _shell(plan, world, y_lo, y_hi)
    return plan.scene(), plan


def _free(scene: Scene, xy: np.ndarray, clear: float = 0.4) -> bool:
    """Whether a tripod at ``xy`` stands clear of every object (0.4 m around, up to 2 m)."""
    ring = np.array([[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)])
    pts = [np.array([*xy, z]) for z in (0.3, 1.0, 1.7)]
    pts += [np.array([*(xy + clear * r), z]) for r in ring for z in (0.3, 1.0, 1.7, 1.95)]
    return not scene.contains(np.array(pts)).any()


def _walk(
    world: FloorWorld, scene: Scene, y: float, spread: float, rng: np.random.Generator
) -> list[np.ndarray]:
    """Standpoints along the line ``y``, ``spacing`` apart, jittered by +-``spread`` across."""
    xs = [rng.uniform(1.2, 3.0)]
    while xs[-1] + world.spacing[0] < world.length - 1.2:
        xs.append(min(xs[-1] + rng.uniform(*world.spacing), world.length - 1.2))
    out = []
    for x in xs:
        for _ in range(50):
            p = np.array([x + rng.uniform(-0.5, 0.5), y + rng.uniform(-spread, spread)])
            if _free(scene, p):
                out.append(p)
                break
    return out


def _stations(world: FloorWorld, scene: Scene, plan: _Plan, rng: np.random.Generator) -> list:
    """Standpoints (x, y) in walking order: along each walk (the corridor first), and some in
    rooms whose door is open, each after the standpoint along the corridor before it."""
    walks = [_walk(world, scene, y, spread, rng) for y, spread in plan.walks]
    out = walks[0]
    x_lo, x_hi = out[0][0], out[-1][0]
    rooms = [r for r in plan.rooms if r[4] and x_lo < 0.5 * (r[0] + r[1]) < x_hi]
    pick = rng.choice(len(rooms), size=min(world.room_scans, len(rooms)), replace=False)
    for k in sorted(pick, key=lambda k: rooms[k][0]):
        p = _room_spot(scene, rooms[k], rng)
        if p is not None:
            at = int(np.searchsorted([q[0] for q in out], p[0]))
            out.insert(at, p)
    for more in walks[1:]:  # then back along the hall
        out += more[::-1]
    return out


def _room_spot(scene: Scene, room: tuple, rng: np.random.Generator) -> np.ndarray | None:
    x0, x1, y0, y1, _ = room
    for _ in range(100):
        p = np.array([rng.uniform(x0 + 0.8, x1 - 0.8), rng.uniform(y0 + 1.0, y1 - 1.0)])
        if _free(scene, p):
            return p
    return None


def scan_floor(world: FloorWorld) -> tuple[Scene, list[np.ndarray], list[np.ndarray]]:
    """Simulate the floor's scans: ``(scene, scans, poses)`` as
    :func:`~ndt_cli.sim.worlds.scan_street` (each scan (N, 3) in its scanner frame)."""
    scene, plan = floor_scene(world)
    rng = np.random.default_rng([world.seed, 22])
    scans, poses = [], []
    for k, p in enumerate(_stations(world, scene, plan, rng)):
        tilt = world.tilt_deg
        roll, pitch = rng.uniform(-tilt, tilt, 2) if tilt > 0 else (0.0, 0.0)
        T = scanner_pose(
            p[0], p[1], rng.uniform(-180.0, 180.0), rng.uniform(1.45, 1.75), roll, pitch
        )
        pts = simulate_scan(
            scene,
            T,
            n_azimuth=world.rays[0],
            n_elevation=world.rays[1],
            elevation_range_deg=(-60.0, 90.0),
            range_noise=world.range_noise,
            seed=int(rng.integers(0, 2**31 - 1)) + k,
        )
        scans.append(pts)
        poses.append(T)
    return scene, scans, poses
