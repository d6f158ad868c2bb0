"""A city district for the simulator: a grid of blocks whose streets cross, walked round its
ring and through its middle street, so that the walk closes loops.

The streets are the street simulator's (:func:`~ndt_cli.sim.scene.make_street`), one piece
between each two crossings and a spur beyond the outer ones, placed at the grid's heading on
one sloping ground; each piece is cleared of what would stand in another street (a building
seen through a gap, reaching into the parallel street) or beyond its ends (the crossings stay
open). People and passing cars are drawn anew for every scan. A :class:`DistrictWorld`
describes a district and its walk; :func:`scan_district` simulates it.

Frames and units as in :mod:`ndt_cli.sim.scanner`: metres, world z up, ``T_world_scan`` maps
scanner points into the world. The grid's own frame has its first crossing at the origin,
streets along its x at ``y = j * pitch[1]`` and along its y at ``x = i * pitch[0]``.
Deterministic in the seed.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ndt_cli.sim.campaigns import WIDTH, stations_along, within_reach
from ndt_cli.sim.ground import Ground
from ndt_cli.sim.scene import Scene, make_street
from ndt_cli.sim.tripod import tripod_pose, tripod_scan
from ndt_cli.sim.worlds import SPARSE, StreetWorld, passers_by

_HALF = WIDTH / 2
_FAR = 1e4  # m: "beyond everything" for the cleared rectangles


@dataclass(frozen=True)
class DistrictWorld:
    """A district of ``blocks`` (along the grid's x, y) whose streets' centre lines are
    ``pitch`` m apart (at least 44 m: 18 m streets and two rows of buildings), the grid turned
    to ``heading_deg`` (degrees from world +x), its streets running ``spur`` m beyond the outer
    crossings. The walk goes round the ring and, with two or more blocks across, through the
    middle street, a standpoint every ``spacing`` m (jittered by up to 2 m). ``grade``,
    ``cross_fall`` (m/m along world x, y) and ``curve`` (1/m) shape the ground; ``tilt_deg``:
    each scanner's roll and pitch, uniform in +-tilt; ``trees``: crowns on the street trees;
    ``people``, ``traffic``: pedestrians and passing cars near every standpoint; ``rays``:
    azimuths x elevations.
    """

    seed: int = 0
    blocks: tuple[int, int] = (2, 2)
    pitch: tuple[float, float] = (60.0, 56.0)
    heading_deg: float = 0.0
    spur: float = 40.0
    spacing: float = 16.0
    grade: float = 0.0
    cross_fall: float = 0.0
    curve: float = 0.0
    tilt_deg: float = 0.0
    trees: bool = False
    people: int = 0
    traffic: int = 0
    rays: tuple[int, int] = SPARSE
    range_noise: float = 0.008

    def __post_init__(self) -> None:
        if min(self.blocks) < 1 or min(self.pitch) < 44.0:
            raise ValueError("need at least one block and a pitch of at least 44 m")
        if self.spacing <= 0 or self.spur < 0:
            raise ValueError("need spacing > 0 and spur >= 0")

    @property
    def ground(self) -> Ground:
        return Ground(self.grade, self.cross_fall, self.curve)

    @property
    def clutter(self) -> StreetWorld:
        """The district's streets as :func:`~ndt_cli.sim.worlds.passers_by` reads them: their
        width, ground, people and traffic."""
        return StreetWorld(
            seed=self.seed,
            grade=self.grade,
            cross_fall=self.cross_fall,
            curve=self.curve,
            people=self.people,
            traffic=self.traffic,
            width=WIDTH,
        )

    def describe(self) -> str:
        """A short label of the district."""
        nx, ny = self.blocks
        parts = [f"seed {self.seed}", f"district {nx}x{ny} blocks"]
        parts.append(f"{len(walk(self))} scans {self.spacing:g} m apart")
        parts.append(f"heading {self.heading_deg:g} deg")
        for name, unit, scale in (
            ("grade", "%", 100),
            ("cross_fall", "%", 100),
            ("curve", "%/100m", 1e4),
            ("tilt_deg", "deg", 1),
            ("people", "", 1),
            ("traffic", "", 1),
        ):
            value = getattr(self, name)
            if value:
                parts.append(f"{name} {value * scale:g}{unit}")
        return ", ".join(parts + ["trees"] * self.trees)

    def to_world(self, xy: np.ndarray) -> np.ndarray:
        """Points (N, 2) of the grid's frame in the world (m)."""
        a = np.radians(self.heading_deg)
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        return np.asarray(xy, dtype=float) @ R.T


def walk(world: DistrictWorld) -> np.ndarray:
    """Standpoints (S, 2) in the grid's frame before their jitter, in walking order: from the
    middle of the ring's west side south, round the ring (east, north, west, south) back to
    where it began, then east through the middle street; a ring alone with one block
    across."""
    nx, ny = world.blocks
    X, Y = nx * world.pitch[0], ny * world.pitch[1]
    if ny < 2:
        path = [(0.0, 0.0), (X, 0.0), (X, Y), (0.0, Y), (0.0, 0.0)]
        return stations_along(path, world.spacing)[:-1]  # the last would stand on the first
    mid = (ny // 2) * world.pitch[1]
    path = [(0.0, mid), (0.0, 0.0), (X, 0.0), (X, Y), (0.0, Y), (0.0, mid), (X, mid)]
    return stations_along(path, world.spacing)


def _pieces(world: DistrictWorld) -> list[tuple[np.ndarray, float, float, tuple]]:
    """Every street piece: its centre (grid frame), axis (0: along x, 90: along y), length
    and the rectangles cleared in its own frame (beyond its ends, and the other parallel
    streets)."""
    out = []
    for axis, (n_along, n_across) in ((0.0, world.blocks), (90.0, world.blocks[::-1])):
        along_pitch, across_pitch = world.pitch if axis == 0.0 else world.pitch[::-1]
        ends = [-_HALF - world.spur, *(i * along_pitch for i in range(n_along + 1))]
        ends.append(n_along * along_pitch + _HALF + world.spur)
        for j in range(n_across + 1):
            for a, b in itertools.pairwise(ends):
                lo = a if a < 0 else a + _HALF
                hi = b if b > n_along * along_pitch else b - _HALF
                length = hi - lo
                if length <= 0.0:  # no spur
                    continue
                others = [(k - j) * across_pitch for k in range(n_across + 1) if k != j]
                clear = [(0.5 * length, _FAR, -_FAR, _FAR), (-_FAR, -0.5 * length, -_FAR, _FAR)]
                clear += [(-_FAR, _FAR, d - _HALF - 0.5, d + _HALF + 0.5) for d in others]
                centre = (0.5 * (lo + hi), j * across_pitch)
                out.append((np.array(centre if axis == 0.0 else centre[::-1]), axis, length, clear))
    return out


def district_scene(world: DistrictWorld) -> Scene:
    """The district's static scene: every street piece on the one ground."""
    scenes = []
    for k, (centre, axis, length, clear) in enumerate(_pieces(world)):
        origin = world.to_world(centre[None])[0]
        scenes.append(
            make_street(
                world.seed * 100 + k,
                length,
                WIDTH,
                origin=(float(origin[0]), float(origin[1])),
                axis_deg=world.heading_deg + axis,
                ground=world.ground,
                trees=world.trees,
                clear=tuple(clear),
            )
        )
    return scenes[0].merged(*scenes[1:])


def _axis(world: DistrictWorld, local: np.ndarray) -> float:
    """The heading (deg, world) of the street a standpoint (grid frame) stands in."""
    on_x_street = abs(local[1] - world.pitch[1] * round(local[1] / world.pitch[1])) <= _HALF
    return world.heading_deg + (0.0 if on_x_street else 90.0)


def scan_district(world: DistrictWorld) -> tuple[Scene, list[np.ndarray], list[np.ndarray]]:
    """Simulate the district's walk: ``(scene, scans, poses)`` as
    :func:`~ndt_cli.sim.worlds.scan_street` (each scan (N, 3) in its scanner frame; the
    scanners 1.5-1.8 m above the ground, at any heading, tilted by up to ``tilt_deg``)."""
    scene = district_scene(world)
    rng = np.random.default_rng([world.seed, 41])
    scans, poses = [], []
    for k, local in enumerate(walk(world)):
        xy = world.to_world((local + rng.uniform(-2.0, 2.0, 2))[None])[0]
        T = tripod_pose(scene, xy, rng, world.tilt_deg, (1.5, 1.8))
        extra = passers_by(world.clutter, xy, _axis(world, local), rng)
        seen = within_reach(scene if extra is None else scene.merged(extra), xy)
        pts = tripod_scan(seen, T, rng, k, world.rays, world.range_noise)
        scans.append(pts)
        poses.append(T)
    return scene, scans, poses
