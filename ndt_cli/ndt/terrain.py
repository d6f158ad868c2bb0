"""The ground under a scan: a height grid in the scan's reduced, levelled frame.

The paper's slices are cut "at heights above the ground". On a street with a grade, a slice at
a fixed z cuts the street at different heights above the pavement in two scans 30 m apart
(2.4 m apart on an 8 % grade): one scan's 1 m slice meets the other's 3.4 m, and the cars,
doors and shop windows of one meet nothing in the other. So each point's height is taken
above the ground model under it, as a surveyor's "height above ground", and two scans of the
same street cut the same things whatever the grade, camber or vertical curve.

The model: the lowest points of every :data:`CELL` m cell (their mean: a slope's cell is not
judged by its lowest corner), grown outwards from the cell under the scan's centre through
neighbours whose heights differ by at most :data:`MAX_STEP` m (the ground and kerbs join; car
roofs, walls and the floors seen through windows do not), and every other cell given the height
of the nearest ground cells (under a facade: the pavement in front of it). It also gives the
height difference of two scans' frames (:func:`height_offset`), which 2D slices cannot see.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

CELL = 2.0  # m: cell of the ground grid
MAX_STEP = 0.5  # m between neighbouring ground cells: grades to 25 %, kerbs
REACH = 150.0  # m from the centre: the ground farther out is not modelled (its edge is used)
BAND = 0.25  # m above a cell's lowest point: its ground points


@dataclass(frozen=True)
class Terrain:
    """Ground height (m) per cell of a grid in a scan's reduced, levelled frame: cell (i, j)
    spans x in ``origin[0] + [i, i + 1) * cell`` and y likewise; ``ground`` marks the cells
    where the ground itself was measured. Points beyond the grid take its edge cells."""

    origin: np.ndarray  # (2,) m
    cell: float
    heights: np.ndarray  # (nx, ny) m
    ground: np.ndarray  # (nx, ny) bool
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # a sample of the
    # ground points (m), for the height difference of two scans (:func:`height_offset`)

    @classmethod
    def flat(cls, z: float = 0.0) -> Terrain:
        """A level plane at height ``z`` (m)."""
        return cls(np.zeros(2), 1.0, np.full((1, 1), float(z)), np.zeros((1, 1), dtype=bool))

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grid indices (clamped to the grid) of (N,2) points."""
        nx, ny = self.heights.shape
        i = np.clip(np.floor((xy[:, 0] - self.origin[0]) / self.cell), 0, nx - 1).astype(np.int64)
        j = np.clip(np.floor((xy[:, 1] - self.origin[1]) / self.cell), 0, ny - 1).astype(np.int64)
        return i, j

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Ground height (m) under (N,2) points of the frame."""
        return self.heights[self.cells(np.asarray(xy, dtype=float))]

    def surface(self, xy: np.ndarray) -> np.ndarray:
        """Ground height (m) under (N,2) points, interpolated bilinearly between the cells'
        centres (exact on a plane; the cells' own heights are their ground's means)."""
        nx, ny = self.heights.shape
        u = np.clip((xy[:, 0] - self.origin[0]) / self.cell - 0.5, 0.0, nx - 1.0)
        v = np.clip((xy[:, 1] - self.origin[1]) / self.cell - 0.5, 0.0, ny - 1.0)
        i, j = np.minimum(u.astype(np.int64), nx - 2), np.minimum(v.astype(np.int64), ny - 2)
        i, j = np.maximum(i, 0), np.maximum(j, 0)
        fu, fv = u - i, v - j
        h = self.heights
        i1, j1 = np.minimum(i + 1, nx - 1), np.minimum(j + 1, ny - 1)
        return (
            (1 - fu) * (1 - fv) * h[i, j]
            + fu * (1 - fv) * h[i1, j]
            + (1 - fu) * fv * h[i, j1]
            + fu * fv * h[i1, j1]
        )

    def measured(self, xy: np.ndarray) -> np.ndarray:
        """Whether the ground was measured in the cell of each (N,2) point (False outside)."""
        nx, ny = self.heights.shape
        cell = np.floor((xy - self.origin) / self.cell).astype(np.int64)
        inside = (cell >= 0).all(axis=1) & (cell[:, 0] < nx) & (cell[:, 1] < ny)
        out = np.zeros(len(xy), dtype=bool)
        out[inside] = self.ground[cell[inside, 0], cell[inside, 1]]
        return out

    def shifted(self, dz: float) -> Terrain:
        """The same ground with every height lowered by ``dz`` m (a new frame origin)."""
        return Terrain(
            self.origin, self.cell, self.heights - dz, self.ground, self.points - [0.0, 0.0, dz]
        )


def _lowest(points: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid origin and, per cell, the mean z of the points within :data:`BAND` m of the
    cell's lowest point (inf: no point): the ground's height at the cell, not its lowest
    corner on a slope."""
    near = points[np.hypot(points[:, 0], points[:, 1]) <= REACH]
    if len(near) == 0:
        near = np.zeros((1, 3))
    lo = np.floor(near[:, :2].min(axis=0) / cell) * cell
    ij = np.floor((near[:, :2] - lo) / cell).astype(np.int64)
    shape = tuple(ij.max(axis=0) + 1)
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    lowest = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(lowest, flat, near[:, 2])
    band = near[:, 2] <= lowest[flat] + BAND
    total = np.bincount(flat[band], near[band, 2], len(lowest))
    count = np.bincount(flat[band], minlength=len(lowest))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.inf)
    return lo, mean.reshape(shape)


def _grow(lowest: np.ndarray, seed: tuple[int, int], step: float) -> np.ndarray:
    """Cells joined to ``seed`` through 4-neighbours whose lowest points differ by at most
    ``step`` m (a flood fill, one ring of cells per round)."""
    ground = np.zeros(lowest.shape, dtype=bool)
    ground[seed] = True
    while True:
        grown = ground.copy()
        for axis in (0, 1):
            for shift in (1, -1):
                src = np.roll(ground, shift, axis)
                z = np.roll(np.where(ground, lowest, np.nan), shift, axis)
                if shift == 1:
                    edge = (0, slice(None)) if axis == 0 else (slice(None), 0)
                else:
                    edge = (-1, slice(None)) if axis == 0 else (slice(None), -1)
                src[edge] = False  # np.roll wraps around: no neighbour across the edge
                with np.errstate(invalid="ignore"):
                    grown |= src & (np.abs(lowest - z) <= step)
        if (grown == ground).all():
            return ground
        ground = grown


def _filled(lowest: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """Heights of the ground cells, and for every other cell the mean of its nearest ground
    cells (rings of 8-neighbours, one per round)."""
    heights = np.where(ground, lowest, np.nan)
    known = ground.copy()
    while not known.all():
        padded = np.pad(np.where(known, heights, 0.0), 1)
        count = np.pad(known.astype(float), 1)
        total, n = np.zeros(heights.shape), np.zeros(heights.shape)
        for di in (0, 1, 2):
            for dj in (0, 1, 2):
                total += padded[di : di + heights.shape[0], dj : dj + heights.shape[1]]
                n += count[di : di + heights.shape[0], dj : dj + heights.shape[1]]
        new = ~known & (n > 0)
        heights[new] = total[new] / n[new]
        known |= new
    return heights


SAMPLE = 20_000  # ground points kept with the model


def terrain_of(points: np.ndarray, cell: float = CELL, step: float = MAX_STEP) -> Terrain:
    """The ground model of (N,3) points in a scan's reduced, levelled frame (z up, m), grown
    from the cell under the frame's origin (or the nearest cell with points), with a regular
    sample of the points on its measured ground."""
    lo, lowest = _lowest(points, cell)
    seen = np.isfinite(lowest)
    i0, j0 = np.floor(-lo / cell).astype(np.int64)
    ii, jj = np.nonzero(seen)
    k = np.argmin((ii - i0) ** 2 + (jj - j0) ** 2)
    ground = _grow(np.where(seen, lowest, np.inf), (int(ii[k]), int(jj[k])), step)
    model = Terrain(lo, cell, _filled(lowest, ground), ground)
    near = np.abs(points[:, 2] - model.surface(points[:, :2])) <= BAND
    on = points[near & model.measured(points[:, :2])]
    return Terrain(lo, cell, model.heights, ground, on[:: -(-len(on) // SAMPLE) or 1])


def height_offset(target: Terrain, source: Terrain, pose: np.ndarray) -> float | None:
    """The height (m) of the source frame's origin in the target frame under the planar
    ``pose`` (tx, ty, yaw) from the source's reduced, levelled frame to the target's: the median,
    over each scan's ground points where the other scan measured the ground too, of the target's
    ground height minus the source's at the same place (both ways, so that what biases one
    scan's model cancels); None when they share no measured ground."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    R = np.array([[c, -s], [s, c]])
    p = target.points  # target points seen from the source
    q = (p[:, :2] - pose[:2]) @ R
    seen = source.measured(q)
    there = p[seen, 2] - source.surface(q[seen])
    r = source.points  # source points seen from the target
    t = r[:, :2] @ R.T + pose[:2]
    seen_t = target.measured(t)
    back = target.surface(t[seen_t]) - r[seen_t, 2]
    both = np.concatenate([there, back])
    return float(np.median(both)) if len(both) else None
