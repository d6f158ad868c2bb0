"""Forest plots for the simulator: trunks of varied diameter on a slope, some of them leaning,
porous crowns, shrubs and fallen logs, no walls; standpoints on a grid or along a line.

A forest is where a registration has no planes to lean on: the slices cut trunks (circles of
0.1-0.8 m) and shrubs, the ground slopes in any direction, and crowns and shrubs stop rays at
random depths that differ between scans. A :class:`ForestWorld` describes a plot and where it
is scanned; :func:`scan_forest` simulates it.

The scene's cylinders are vertical: a leaning trunk is a stack of short cylinders, each offset
along the lean by at most 5 cm from the one below it; a fallen log is a row of turned boxes that
follow the ground. Frames and units as in :mod:`ndt_cli.sim.scanner`: metres, world z up,
``T_world_scan`` maps scanner points into the world. Deterministic in the seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.sim.ground import Ground
from ndt_cli.sim.scene import Scene
from ndt_cli.sim.tripod import tripod_pose, tripod_scan

SPARSE = (1440, 160)  # azimuths x elevations: about 0.2 M rays a scan
_STEP = 0.05  # m: the largest sideways offset between two pieces of a leaning trunk
_CLEAR = 1.0  # m: free space kept around each standpoint (trunk surfaces, shrubs, logs)


@dataclass(frozen=True)
class ForestWorld:
    """One forest plot and its standpoints.

    ``slope`` (m/m, rise over run: 0.15 is 15 %) rising towards ``slope_deg`` (degrees from
    +x); ``stems`` (trunks per hectare), ``diameter`` (m, at the foot: many thin, few thick),
    ``leaning`` (share of trunks that lean) by up to ``lean_deg`` (degrees from the vertical,
    at least 1), ``shrubs`` and ``logs`` (per hectare); ``shape`` (rows x columns of
    standpoints: (3, 3) a grid, (1, n) a line) ``spacing`` apart (m, each gap a uniform draw)
    on axes turned by a heading drawn from the seed; ``margin`` (m of forest beyond the outer
    standpoints); ``tilt_deg`` (each scanner's roll and pitch, uniform in +-tilt); ``rays``
    (azimuths x elevations).
    """

    seed: int = 0
    slope: float = 0.08
    slope_deg: float = 30.0
    stems: float = 400.0
    diameter: tuple[float, float] = (0.1, 0.8)
    leaning: float = 0.3
    lean_deg: float = 5.0
    shrubs: float = 300.0
    logs: float = 40.0
    shape: tuple[int, int] = (3, 3)
    spacing: tuple[float, float] = (10.0, 20.0)
    margin: float = 40.0
    tilt_deg: float = 0.5
    rays: tuple[int, int] = SPARSE
    range_noise: float = 0.008

    @property
    def ground(self) -> Ground:
        """The plot's plane ground, rising by ``slope`` towards ``slope_deg``."""
        a = np.radians(self.slope_deg)
        return Ground(grade=self.slope * np.cos(a), cross_fall=self.slope * np.sin(a))

    def describe(self) -> str:
        """A short label of the plot (what tells it from the others first)."""
        rows, cols = self.shape
        where = "line" if min(rows, cols) == 1 else "grid"
        parts = [f"seed {self.seed}", f"forest {rows}x{cols} {where}"]
        parts.append(f"slope {100 * self.slope:g}% to {self.slope_deg:g} deg")
        parts.append(f"{self.stems:g} stems/ha, {self.leaning:.0%} leaning")
        parts.append(f"{self.shrubs:g} shrubs/ha, {self.logs:g} logs/ha")
        parts.append(f"spacing {self.spacing[0]:g}-{self.spacing[1]:g} m")
        if self.tilt_deg:
            parts.append(f"tilt {self.tilt_deg:g} deg")
        return ", ".join(parts)


@dataclass(frozen=True)
class Stand:
    """What stands on the plot, in the world frame (m): per trunk ``x, y`` of its foot,
    ``diameter`` there, ``height``, ``lean_deg`` and ``lean_azimuth_deg`` (the direction its
    top leans to, degrees from +x); the standpoints' (x, y) in walking order."""

    trunks: np.ndarray  # (T, 6): x, y, diameter, height, lean_deg, lean_azimuth_deg
    stations: np.ndarray  # (S, 2)

    def axis(self, k: int, z: np.ndarray | float, ground: Ground) -> np.ndarray:
        """World (x, y) of trunk ``k``'s axis at height(s) ``z`` (world z, m)."""
        x, y, _, _, lean, az = self.trunks[k]
        up = np.asarray(z, dtype=float) - float(ground.z(x, y))
        off = up * np.tan(np.radians(lean))
        a = np.radians(az)
        return np.stack([x + off * np.cos(a), y + off * np.sin(a)], axis=-1)


def _stations(world: ForestWorld, rng: np.random.Generator) -> np.ndarray:
    """Standpoints (x, y) on turned grid axes centred on the origin, row after row (a
    serpentine walk), each gap drawn from ``spacing``, jittered by up to 1 m."""
    rows, cols = world.shape
    if rows < 1 or cols < 1 or rows * cols < 2:
        raise ValueError("shape needs at least two standpoints")
    lo, hi = world.spacing
    if not 0 < lo <= hi:
        raise ValueError("spacing must be (low, high) with 0 < low <= high")
    u = np.concatenate([[0.0], np.cumsum(rng.uniform(lo, hi, cols - 1))])
    v = np.concatenate([[0.0], np.cumsum(rng.uniform(lo, hi, rows - 1))])
    u, v = u - u.mean(), v - v.mean()
    heading = np.radians(rng.uniform(0.0, 180.0))
    ex = np.array([np.cos(heading), np.sin(heading)])
    ey = np.array([-ex[1], ex[0]])
    out = []
    for r in range(rows):
        for c in range(cols) if r % 2 == 0 else reversed(range(cols)):
            out.append(u[c] * ex + v[r] * ey + rng.uniform(-1.0, 1.0, 2))
    return np.array(out)


def _clear_of(stations: np.ndarray, xy: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Which points ``xy`` (N, 2) stand farther than ``reach`` (N,) m from every station."""
    d = np.hypot(*(xy[:, None, :] - stations[None, :, :]).transpose(2, 0, 1))
    return d.min(axis=1) > reach


def _trunks(
    world: ForestWorld, rng: np.random.Generator, box: np.ndarray, stations: np.ndarray
) -> np.ndarray:
    """Trunk feet, diameters, heights and leans: a Poisson number over the plot's rectangle
    ``box`` (x0, y0, x1, y1), no two closer than their radii and 0.3 m, none within reach of
    a standpoint (the lean moves a trunk by at most 0.15 m at the scanner's height)."""
    area = float(np.prod(box[2:] - box[:2]))
    n = rng.poisson(world.stems * area / 1e4)
    xy = rng.uniform(box[:2], box[2:], (n, 2))
    lo, hi = world.diameter
    d = lo + (hi - lo) * rng.beta(1.3, 3.0, n)
    height = 8.0 + 14.0 * (d - lo) / max(hi - lo, 1e-9) + rng.uniform(0.0, 6.0, n)
    leans = rng.random(n) < world.leaning
    lean = np.where(leans, rng.uniform(1.0, max(world.lean_deg, 1.0), n), 0.0)
    azimuth = rng.uniform(-180.0, 180.0, n)
    keep = _clear_of(stations, xy, 0.5 * d + _CLEAR + 0.15)
    kept: list[int] = []
    for k in np.flatnonzero(keep):  # no trunk inside another
        if kept:
            gap = np.hypot(*(xy[kept] - xy[k]).T) - 0.5 * (d[kept] + d[k])
            if gap.min() < 0.3:
                continue
        kept.append(k)
    return np.column_stack([xy, d, height, lean, azimuth])[kept]


def _trunk_pieces(trunk: np.ndarray, ground: Ground) -> list[tuple[float, ...]]:
    """The cylinders ``x, y, r, z0, z1`` of one trunk: three pieces that taper to 0.6 of the
    foot's radius when it stands upright; when it leans, pieces short enough that each is
    offset from the one below by at most :data:`_STEP` m, the first reaching 0.3 m into the
    ground."""
    x, y, d, height, lean, az = trunk
    g = float(ground.z(x, y))
    t = np.tan(np.radians(lean))
    n = 3 if lean == 0.0 else max(3, int(np.ceil(height * t / _STEP)))
    edges = np.linspace(0.0, height, n + 1)
    mids = 0.5 * (edges[:-1] + edges[1:])
    a = np.radians(az)
    out = []
    for k, (lo, hi, mid) in enumerate(zip(edges[:-1], edges[1:], mids, strict=True)):
        r = 0.5 * d * (1.0 - 0.4 * k / max(n - 1, 1))
        z0 = g - 0.3 if k == 0 else g + lo
        out.append((x + mid * t * np.cos(a), y + mid * t * np.sin(a), r, z0, g + hi))
    return out


def _crowns(trunks: np.ndarray, ground: Ground, rng: np.random.Generator) -> np.ndarray:
    """A porous crown on every trunk: centred over its top, its bottom at least 3.5 m above
    the ground."""
    x, y, d, height, lean, az = trunks.T
    t, a = np.tan(np.radians(lean)), np.radians(az)
    top = np.column_stack([x + height * t * np.cos(a), y + height * t * np.sin(a)])
    g = ground.z(x, y)
    r = rng.uniform(1.2, 2.5, len(x)) + 3.0 * d
    rz = rng.uniform(1.5, 4.0, len(x))
    z = np.maximum(g + height, g + rz + 3.5)
    density = rng.uniform(0.5, 2.0, len(x))
    return np.column_stack([top, z, r, r, rz, density])


def _shrubs(
    world: ForestWorld, rng: np.random.Generator, box: np.ndarray, stations: np.ndarray
) -> np.ndarray:
    """Low porous crowns (up to 1.6 m high, denser foliage than the trees'), clear of the
    standpoints."""
    area = float(np.prod(box[2:] - box[:2]))
    n = rng.poisson(world.shrubs * area / 1e4)
    xy = rng.uniform(box[:2], box[2:], (n, 2))
    r = rng.uniform(0.4, 1.5, n)
    rz = rng.uniform(0.3, 0.9, n)
    z = world.ground.z(xy[:, 0], xy[:, 1]) + 0.8 * rz
    density = rng.uniform(2.0, 5.0, n)
    keep = _clear_of(stations, xy, r + _CLEAR)
    return np.column_stack([xy, z, r, r, rz, density])[keep]


def _logs(
    world: ForestWorld, rng: np.random.Generator, box: np.ndarray, stations: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fallen logs: each a row of turned boxes of at most 1 m, every piece on the ground
    under it (reaching 5 cm into it, as thick as the log above it). Returns the boxes' lower
    and upper corners in their own axes and their headings (radians)."""
    area = float(np.prod(box[2:] - box[:2]))
    n = rng.poisson(world.logs * area / 1e4)
    lo, hi, yaw = [], [], []
    for _ in range(n):
        centre = rng.uniform(box[:2], box[2:])
        length, d = rng.uniform(2.0, 10.0), rng.uniform(0.2, 0.6)
        heading = np.radians(15.0 * rng.integers(0, 12))  # few headings: a faster cast
        along = np.array([np.cos(heading), np.sin(heading)])
        pieces = int(np.ceil(length))
        s = (np.arange(pieces) + 0.5) * length / pieces - 0.5 * length
        xy = centre + s[:, None] * along
        if not _clear_of(stations, xy, np.full(pieces, 0.5 * length / pieces + d + _CLEAR)).all():
            continue
        half = 0.5 * length / pieces
        across = np.array([-along[1], along[0]])
        ends = [a * half * along + b * 0.5 * d * across for a in (-1, 1) for b in (-1, 1)]
        c, si = np.cos(heading), np.sin(heading)
        for p in xy:
            corners = p + np.array(ends)
            z0 = float(world.ground.z(corners[:, 0], corners[:, 1]).min()) - 0.05
            z1 = float(world.ground.z(*p)) + d
            u = (c * p[0] + si * p[1], -si * p[0] + c * p[1])  # the centre in the log's axes
            lo.append((u[0] - half, u[1] - d / 2, z0))
            hi.append((u[0] + half, u[1] + d / 2, z1))
            yaw.append(heading)
    return np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3), np.array(yaw)


def forest_scene(world: ForestWorld) -> tuple[Scene, Stand]:
    """The plot's static scene (trunks, crowns, shrubs, logs on the sloping ground) and its
    :class:`Stand` (trunks and standpoints)."""
    if not 0.0 <= world.slope <= 0.5:
        raise ValueError("slope must be within 0-0.5 (m/m)")
    rng = np.random.default_rng([world.seed, 31])
    stations = _stations(world, rng)
    box = np.concatenate([stations.min(axis=0), stations.max(axis=0)])
    box += np.array([-1.0, -1.0, 1.0, 1.0]) * world.margin
    trunks = _trunks(world, rng, box, stations)
    ground = world.ground
    cylinders = [piece for t in trunks for piece in _trunk_pieces(t, ground)]
    crowns = np.vstack([_crowns(trunks, ground, rng), _shrubs(world, rng, box, stations)])
    lo, hi, yaw = _logs(world, rng, box, stations)
    scene = Scene(lo, hi, np.array(cylinders).reshape(-1, 5), 0.0, yaw, crowns, ground)
    return scene, Stand(trunks, stations)


def scan_forest(world: ForestWorld) -> tuple[Scene, list[np.ndarray], list[np.ndarray]]:
    """Simulate the plot's scans: ``(scene, scans, poses)`` as
    :func:`~ndt_cli.sim.worlds.scan_street` (each scan (N, 3) in its scanner frame; the
    scanners 1.45-1.8 m above the ground, at any heading, tilted by up to ``tilt_deg``)."""
    scene, stand = forest_scene(world)
    rng = np.random.default_rng([world.seed, 32])
    scans, poses = [], []
    for k, xy in enumerate(stand.stations):
        T = tripod_pose(scene, xy, rng, world.tilt_deg, (1.45, 1.8))
        pts = tripod_scan(scene, T, rng, k, world.rays, world.range_noise)
        scans.append(pts)
        poses.append(T)
    return scene, scans, poses
