"""Streets as a surveyor meets them: grades, vertical curves, camber and cross-fall, tilted or
compensated scanners, sparse or dense scans, wide spacings, trees, people and passing cars,
bends. One :class:`StreetWorld` describes a street and its standpoints; :func:`scan_street`
simulates it.

Frames and units as in :mod:`ndt_cli.sim.scanner`: metres, the world z is the true vertical,
``T_world_scan`` maps scanner points into the world. People and passing cars are drawn anew for
every scan (they move between scans); crowns stop rays at random depths per scan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.sim.ground import Ground
from ndt_cli.sim.scanner import scanner_pose, simulate_scan
from ndt_cli.sim.scene import Scene, make_street, placed

SPARSE = (1440, 160)  # azimuths x elevations: about 0.2 M points a scan
DENSE = (4500, 640)  # about 2 M points a scan
_MARGIN = 70.0  # street beyond the first and last standpoints (m)


@dataclass(frozen=True)
class StreetWorld:
    """One street and its standpoints.

    ``grade`` (m/m along the street, at its centre), ``curve`` (change of grade per metre: a
    vertical curve), ``cross_fall`` (m/m across), ``camber`` (the cross slope at the kerbs of a
    crowned carriageway, m/m); ``tilt_deg``: each scanner's roll and pitch, uniform in
    +-tilt; ``compensated``: the scanner's z is the vertical (a dual-axis compensator), so
    the tilt is only its residual of 0.003 deg at most; ``rays``: azimuths x elevations
    (:data:`SPARSE`, :data:`DENSE`); ``spacing``: distance between consecutive standpoints
    (m, uniform draw); ``trees``: porous crowns on the trunks; ``people``, ``traffic``: pedestrians
    and passing cars in every scan; ``bend_deg``: the street turns by this much at its middle
    standpoint; ``corridor``: uniform facades (a degenerate street).
    """

    seed: int = 0
    n_scans: int = 8
    spacing: tuple[float, float] = (13.0, 30.0)
    grade: float = 0.0
    curve: float = 0.0
    cross_fall: float = 0.0
    camber: float = 0.0
    tilt_deg: float = 0.0
    compensated: bool = False
    rays: tuple[int, int] = SPARSE
    trees: bool = False
    people: int = 0
    traffic: int = 0
    bend_deg: float = 0.0
    width: float = 18.0
    corridor: bool = False
    range_noise: float = 0.008

    @property
    def ground(self) -> Ground:
        kerb = 0.5 * self.width - 3.0
        return Ground(self.grade, self.cross_fall, self.curve, -self.camber / kerb)

    def describe(self) -> str:
        """A short label: the parameters that differ from a flat, level, sparse street."""
        parts = [f"seed {self.seed}", f"{self.n_scans} scans"]
        for name, unit, scale in (
            ("grade", "%", 100),
            ("curve", "%/100m", 1e4),
            ("cross_fall", "%", 100),
            ("camber", "%", 100),
            ("tilt_deg", "deg", 1),
            ("people", "", 1),
            ("traffic", "", 1),
            ("bend_deg", "deg", 1),
        ):
            value = getattr(self, name)
            if value:
                parts.append(f"{name} {value * scale:g}{unit}")
        parts += ["compensated"] * self.compensated + ["trees"] * self.trees
        parts += ["corridor"] * self.corridor
        parts.append("dense" if self.rays[0] * self.rays[1] > 1e6 else "sparse")
        return ", ".join(parts)


@dataclass(frozen=True)
class _Segment:
    """A straight piece of the street: its centre, heading (deg) and length (m)."""

    origin: np.ndarray
    axis_deg: float
    length: float

    def to_world(self, along: float, across: float) -> np.ndarray:
        a = np.radians(self.axis_deg)
        u, v = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
        return self.origin + (along - 0.0) * u + across * v


def _stations(world: StreetWorld, rng: np.random.Generator) -> np.ndarray:
    """Distance of each standpoint along the street (m), the middle one at 0."""
    gaps = rng.uniform(*world.spacing, world.n_scans - 1)
    s = np.concatenate([[0.0], np.cumsum(gaps)])
    return s - s[(world.n_scans - 1) // 2]


def _segments(world: StreetWorld, s: np.ndarray) -> list[_Segment]:
    """One segment (no bend) or two meeting at the middle standpoint (s = 0)."""
    if world.bend_deg == 0.0:
        lo, hi = s[0] - _MARGIN, s[-1] + _MARGIN
        return [_Segment(np.array([0.5 * (lo + hi), 0.0]), 0.0, hi - lo)]
    a_len, b_len = _MARGIN - s[0], s[-1] + _MARGIN
    first = _Segment(np.array([-0.5 * a_len, 0.0]), 0.0, a_len)
    b = np.radians(world.bend_deg)
    second = _Segment(0.5 * b_len * np.array([np.cos(b), np.sin(b)]), world.bend_deg, b_len)
    return [first, second]


def _position(segments: list[_Segment], s: float, across: float) -> tuple[np.ndarray, float]:
    """World (x, y) and street heading (deg) of a point ``s`` m along the street."""
    if len(segments) == 1 or s <= 0.0:
        seg = segments[0]
        return seg.to_world(s - seg.origin[0], across), seg.axis_deg
    seg = segments[1]
    return seg.to_world(s - 0.5 * seg.length, across), seg.axis_deg


def street_scene(world: StreetWorld, s: np.ndarray) -> Scene:
    """The static street: one segment, or two meeting at an angle with the inner corner
    cleared (a building of one segment must not stand in the other's carriageway)."""
    segments = _segments(world, s)
    inner = 0.5 * world.width * np.tan(np.radians(abs(world.bend_deg)) / 2) + 2.0
    side = 1.0 if world.bend_deg > 0 else -1.0
    scenes = []
    for k, seg in enumerate(segments):
        clear = ()
        if len(segments) == 2:
            end = 0.5 * seg.length
            x0, x1 = (end - inner, end + 1.0) if k == 0 else (-end - 1.0, -end + inner)
            y0, y1 = (0.0, 60.0) if side > 0 else (-60.0, 0.0)
            clear = ((x0, x1, y0, y1),)
        scenes.append(
            make_street(
                world.seed + 1000 * k,
                seg.length,
                world.width,
                corridor=world.corridor,
                origin=tuple(seg.origin),
                axis_deg=seg.axis_deg,
                ground=world.ground,
                trees=world.trees,
                clear=clear,
            )
        )
    return scenes[0].merged(*scenes[1:])


def passers_by(
    world: StreetWorld, around: np.ndarray, axis_deg: float, rng: np.random.Generator
) -> Scene | None:
    """People and passing cars near a standpoint (world (x, y) ``around``), kept 2 m clear
    of the scanner; None when the street has none."""
    if not world.people and not world.traffic:
        return None
    kerb = 0.5 * world.width - 3.0
    cyl = []
    for _ in range(world.people):
        x, y = _clear_spot(rng, 40.0, 0.5 * world.width - 0.5)
        cyl.append((x, y, rng.uniform(0.2, 0.3), 0.0, rng.uniform(1.6, 1.9)))
    lo, hi = [], []
    for _ in range(world.traffic):
        x, y = _clear_spot(rng, 50.0, kerb - 1.5, 3.5)
        length, width = rng.uniform(4.0, 5.0), rng.uniform(1.7, 1.9)
        lo.append((x - length / 2, y - width / 2, 0.0))
        hi.append((x + length / 2, y + width / 2, rng.uniform(1.4, 1.6)))
    local = Scene(np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3), np.array(cyl))
    return placed(local, np.asarray(around, float), axis_deg, world.ground)


def _clear_spot(
    rng: np.random.Generator, reach: float, half_width: float, clear: float = 2.0
) -> tuple[float, float]:
    """A point within ``reach`` m along and ``half_width`` m across, ``clear`` m from (0, 0)."""
    while True:
        x, y = rng.uniform(-reach, reach), rng.uniform(-half_width, half_width)
        if np.hypot(x, y) > clear:
            return float(x), float(y)


def scan_street(world: StreetWorld) -> tuple[Scene, list[np.ndarray], list[np.ndarray]]:
    """Simulate the street's scans. Returns ``(scene, scans, poses)``: the static scene, each
    scan (N, 3) in its scanner frame and each ``T_world_scan``, as
    :func:`~ndt_cli.sim.scanner.make_sequence`."""
    rng = np.random.default_rng([world.seed, 7])
    s = _stations(world, rng)
    scene = street_scene(world, s)
    segments = _segments(world, s)
    scans, poses = [], []
    n_az, n_el = world.rays
    for k, sk in enumerate(s):
        xy, axis = _position(segments, float(sk), rng.uniform(-3.0, 3.0))
        tilt = 0.003 if world.compensated else world.tilt_deg
        roll, pitch = rng.uniform(-tilt, tilt, 2) if tilt > 0 else (0.0, 0.0)
        height = float(world.ground.z(*xy)) + rng.uniform(1.45, 1.8)
        T = scanner_pose(*xy, rng.uniform(-180.0, 180.0), height, roll, pitch)
        extra = passers_by(world, xy, axis, rng)
        seen = scene if extra is None else scene.merged(extra)
        noise_seed = int(rng.integers(0, 2**31 - 1))
        pts = simulate_scan(
            seen,
            T,
            n_azimuth=n_az,
            n_elevation=n_el,
            range_noise=world.range_noise,
            seed=noise_seed + k,
        )
        scans.append(pts)
        poses.append(T)
    return scene, scans, poses
