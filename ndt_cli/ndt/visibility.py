"""Free-space consistency of a pose between two scans, each in its scanner's own frame.

A scanner measures along straight rays: where it saw a surface at range r in some direction,
the space in front of that surface was empty. A pose that puts many points of the other scan
into that empty space is wrong however well the slices fit; the typical case is a long street
matched onto itself turned by 180 degrees or shifted by a block, which NDT's evidence can rank
as high as the truth when the scanners stand far apart.

Each scan's 3D points thinned for ICP are summarised as a :class:`RangeImage`: the nearest
range (m) per direction bin of 1 x 1.5 degrees (azimuth x elevation), the scanner at the origin
of the scan's frame, as ``input.min_range`` and ``input.max_range`` assume too. A point
conflicts when it lies more than a margin (:func:`margin`: 0.5 m with the default thinning) in
front of the nearest surface seen in its direction bin *and in the eight bins around it*
(:attr:`RangeImage.guard`). A surface seen at a grazing angle spreads its ranges over metres
within one bin (a ceiling or a corridor wall 15 m away changes range by 3-6 m per degree), so
the nearest range of a bin, taken from the few points that fell into it, can lie behind a point
of the same surface seen from elsewhere; an occlusion edge puts a near surface beside a far one
in the same way. Only points more than :data:`MIN_HEIGHT` above the ground are checked: ground
at grazing angles is the same problem where it is worst.

Two shares are measured. *In the bin alone*: on simulated streets a right pose puts 1-6 % of
the checked points into free space (occlusion edges, the bins' width), the wrong poses NDT
ranked first or second 10-39 %; on real pairs (Velodyne street and car scans) right poses
0.4-11 % and the runners-up 30-51 %; this share gates a street's final pose
(``quality.max_free_space``), not an interior's. In simulated interiors it puts right poses at
4-17 %, nearly all of it the ceiling (and desk tops in open-plan floors) seen at grazing
angles from far away, as many as the wrong poses turned by 180 degrees or slid by a room.
*Around it* (the neighbourhood test): right interior poses put 0-0.15 % there and the wrong
ones 0.2-10 %; this share compares candidates with each other (:mod:`ndt_cli.ndt.rivals`)
and gates an interior's final pose (``quality.max_free_space_around``). On a street it
forgives a wrong pose too much (a scan of another street: 2.6 % around, 20 % in the bin
alone). Figures: docs/trust.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ndt_cli.ndt.prepare import PreparedScan

AZ_DEG, EL_DEG = 1.0, 1.5  # direction bins (degrees): about a 0.3 m cell at 15 m
MARGIN = 0.5  # m in front of the seen surface: far above range noise and the 0.1 m thinning
MIN_HEIGHT = 0.5  # m above the ground: the points checked
MAX_CHECKED = 40_000  # points of each scan checked (a regular stride): a few ms per pose
MIN_POINTS = 100  # fewer 3D points say nothing about what a scanner saw


@dataclass(frozen=True)
class RangeImage:
    """Nearest measured range (m) per direction bin, scanner at the origin; inf: nothing seen.
    ``ranges`` is (n_az * n_el,), bin index ``az_bin * n_el + el_bin``; ``guard`` the nearest
    range of each bin and its eight neighbours (azimuth wraps round; inf where the bin itself
    saw nothing: a direction never measured says nothing)."""

    ranges: np.ndarray
    n_az: int
    n_el: int
    guard: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray) -> RangeImage:
        """The image of (N,3) points in the scanner's frame (m)."""
        n_az, n_el = round(360 / AZ_DEG), round(180 / EL_DEG)
        ranges = np.full(n_az * n_el, np.inf)
        r = _ranges(points)
        np.minimum.at(ranges, _bins(points, r, n_az, n_el), r)
        return cls(ranges, n_az, n_el, _guard(ranges.reshape(n_az, n_el)).ravel())

    def in_front(
        self, points: np.ndarray, margin: float = MARGIN, around: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per (N,3) point in this scanner's frame (m): whether it lies more than ``margin`` m
        in front of the surfaces seen in its direction bin (and in the bins around it when
        ``around``), and whether its direction was measured at all; (N,) bool each."""
        r = _ranges(points)
        seen = (self.guard if around else self.ranges)[_bins(points, r, self.n_az, self.n_el)]
        measured = np.isfinite(seen)
        return measured & (r < seen - margin), measured

    def conflicts(
        self, points: np.ndarray, margin: float = MARGIN, around: bool = True
    ) -> tuple[int, int]:
        """(points more than ``margin`` m in front of the surfaces seen in their direction bin,
        and in the bins around it when ``around``, points whose direction was measured) of (N,3)
        points in this scanner's frame (m)."""
        front, measured = self.in_front(points, margin, around)
        return int(front.sum()), int(measured.sum())


def _guard(image: np.ndarray) -> np.ndarray:
    """The smallest value of each cell of ``image`` (n_az, n_el) and its eight neighbours
    (azimuth wraps round, elevation stops at the poles); inf where the cell itself is inf."""
    rows = np.minimum(np.minimum(image, np.roll(image, 1, axis=0)), np.roll(image, -1, axis=0))
    out = rows.copy()
    out[:, 1:] = np.minimum(out[:, 1:], rows[:, :-1])
    out[:, :-1] = np.minimum(out[:, :-1], rows[:, 1:])
    return np.where(np.isfinite(image), out, np.inf)


def _ranges(points: np.ndarray) -> np.ndarray:
    """Distance (m) of each (N,3) point from the origin."""
    return np.sqrt(np.einsum("ij,ij->i", points, points))


def _bins(points: np.ndarray, r: np.ndarray, n_az: int, n_el: int) -> np.ndarray:
    """Direction bin of each point (see :class:`RangeImage`)."""
    az = np.arctan2(points[:, 1], points[:, 0]) % (2 * np.pi)
    el = np.arcsin(np.clip(points[:, 2] / np.maximum(r, 1e-9), -1.0, 1.0)) + np.pi / 2
    ia = np.minimum((az * (n_az / (2 * np.pi))).astype(np.int64), n_az - 1)
    ie = np.minimum((el * (n_el / np.pi)).astype(np.int64), n_el - 1)
    return ia * n_el + ie


@dataclass(frozen=True)
class Sight:
    """What one scan contributes to the check: its range image and the points checked against
    the other scan's image (scanner frame, m)."""

    image: RangeImage
    checked: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, heights: np.ndarray) -> Sight:
        """From (N,3) points in the scanner's frame and their heights above the ground (m)."""
        high = points[heights > MIN_HEIGHT]
        return cls(RangeImage.of(points), high[:: max(1, -(-len(high) // MAX_CHECKED))])

    @classmethod
    def of_scan(cls, scan: PreparedScan) -> Sight | None:
        """From a prepared scan's 3D points (its frame; heights above its ground model); None
        without 3D points or when they do not surround the frame's origin (not in the
        scanner's own frame)."""
        if scan.points3d is None or len(scan.points3d) < MIN_POINTS:
            return None
        points = scan.points3d + scan.reduction
        if not scanner_inside(points):
            return None
        levelled = scan.points3d @ scan.level.T
        return cls.of(points, levelled[:, 2] - scan.terrain.at(levelled[:, :2]))


def free_at_heights(
    scan: PreparedScan, xy: np.ndarray, heights: Sequence[float], margin: float = MARGIN
) -> np.ndarray | None:
    """(len(heights), N) bool: whether the place at each (N,2) ``xy`` (the scan's reduced,
    levelled frame, m) and each height above its ground (m) lies more than ``margin`` m in
    front of what the scanner saw in that direction and around it: space it saw empty. None
    when the scan cannot say what it saw (:meth:`Sight.of_scan`)."""
    sight = scan.sight
    if sight is None:
        return None
    xy = np.reshape(xy, (-1, 2))
    ground = scan.terrain.at(xy)
    F = scan.from_local()
    out = np.zeros((len(heights), len(xy)), dtype=bool)
    for k, h in enumerate(heights):
        local = np.column_stack([xy, ground + h])
        out[k] = sight.image.in_front(local @ F[:3, :3].T + F[:3, 3], margin)[0]
    return out


SCANNER_MARGIN = 1.0  # m: a scan of one sector has its scanner at the sector's apex, its edge


def scanner_inside(points: np.ndarray) -> bool:
    """Whether the origin lies inside the horizontal extent of the points (within
    :data:`SCANNER_MARGIN`): a scan in its scanner's frame does, even one cut to a sector; a
    georeferenced one does not (then the check is skipped)."""
    x, y = points[:, 0], points[:, 1]  # column by column: several times faster on (N,3) rows
    m = SCANNER_MARGIN
    return bool(x.min() - m < 0.0 < x.max() + m and y.min() - m < 0.0 < y.max() + m)


def margin(voxel: float) -> float:
    """Margin (m) for points thinned to one centroid per ``voxel`` m cube: :data:`MARGIN`, or
    twice the voxel when coarser (a centroid can sit that far in front of its surface)."""
    return max(MARGIN, 2.0 * voxel)


def free_space_share(
    target: Sight,
    source: Sight,
    T_target_source: np.ndarray,
    margin: float = MARGIN,
    around: bool = True,
) -> float:
    """Share of the checked points of both scans that a pose puts into the other scanner's
    free space (0-1); ``T_target_source`` maps the source scanner's frame to the target's.
    ``around``: in front of what was seen in the direction and around it (see the module
    docstring); false: in the direction's bin alone."""
    R, t = T_target_source[:3, :3], T_target_source[:3, 3]
    bad_s, seen_s = target.image.conflicts(source.checked @ R.T + t, margin, around)
    bad_t, seen_t = source.image.conflicts((target.checked - t) @ R, margin, around)
    return (bad_s + bad_t) / max(seen_s + seen_t, 1)
