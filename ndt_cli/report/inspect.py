"""The link inspector's numbers: a link's two scans overlaid, slice by slice, in the target's
frame, and how far the source's points lie from the target's walls.

The scans' slice samples (:mod:`ndt_cli.pipeline.samples`) are in each scan's reduced, levelled
frame; the source's are carried into the target's by the link's ``T_target_source``. A source
point *matches* when the target has at least :data:`MIN_NEIGHBOURS` points within
:data:`MATCH_M` of it; its residual is its distance from the line fitted through those target
points (a wall's or a pole's outline in the slice), so that it measures how far apart the two
scans' surfaces are, not how far apart their thinned points happen to be; where the target's
points there do not lie on a line (a corner, clutter: their spread across is over
:data:`LINEAR` of their spread along), the point does not count. Right links show a
spread of a centimetre or two (the range noise and the thinning); a link off by a few
centimetres shows it in the spread, a link off by more loses its matches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ndt_cli.core.neighbours import grid, knn
from ndt_cli.pipeline.samples import SliceSample

MATCH_M = 0.3  # m: a source point farther from every target point does not match
MIN_NEIGHBOURS = 3  # target points within MATCH_M a line is fitted through
LINEAR = 0.05  # their spread across over along (eigenvalues): above it, a corner or clutter
NEIGHBOURS = 6  # target points looked at per source point
MARGIN_M = 2.0  # m around the matched points in the zoomed view
MIN_SPAN_M = 8.0  # m: the smallest side of the zoomed view


@dataclass(frozen=True)
class SliceView:
    """One slice of a link: the target's points and the source's carried into the target's
    frame ((n, 2) m, the target's reduced, levelled frame), its height above the ground (m),
    the number of source points and the residuals (cm) of those that match."""

    height: float
    target: np.ndarray
    source: np.ndarray
    residual_cm: np.ndarray

    @property
    def matched(self) -> int:
        return len(self.residual_cm)

    def spread_cm(self) -> tuple[float, float] | None:
        """Median and upper quartile of the residuals (cm); None without a match."""
        if not self.matched:
            return None
        return float(np.median(self.residual_cm)), float(np.percentile(self.residual_cm, 75))


@dataclass(frozen=True)
class LinkView:
    """A link's slices and the square of the target's frame (x0, y0, side; m) they are shown
    in: around where the scans overlap."""

    slices: tuple[SliceView, ...]
    box: tuple[float, float, float]

    def spread_cm(self) -> tuple[float, float] | None:
        """Median and upper quartile of every slice's residuals (cm)."""
        every = np.concatenate([s.residual_cm for s in self.slices]) if self.slices else []
        if not len(every):
            return None
        return float(np.median(every)), float(np.percentile(every, 75))


def carried(T_target_source: np.ndarray, target: SliceSample, source: SliceSample) -> np.ndarray:
    """3x3 homogeneous 2D transform from the source's reduced, levelled frame to the
    target's (both level: the turn about the vertical and the shift)."""
    M = target.to_local @ T_target_source @ np.linalg.inv(source.to_local)
    out = np.eye(3)
    out[:2, :2], out[:2, 2] = M[:2, :2], M[:2, 3]
    return out


def residuals(target: np.ndarray, source: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which source points match the target (bool mask) and their distances (m) from the line
    through their target neighbours (both (n, 2) m in one frame)."""
    if len(target) < MIN_NEIGHBOURS or not len(source):
        return np.zeros(len(source), bool), np.empty(0)
    pad = np.zeros((len(target), 1))
    g = grid(np.hstack([target, pad]), MATCH_M)
    dist, index = knn(g, np.hstack([source, np.zeros((len(source), 1))]), NEIGHBOURS, MATCH_M)
    found = np.isfinite(dist)
    ok = found.sum(axis=1) >= MIN_NEIGHBOURS
    near = np.where(found[ok, :, None], target[np.minimum(index[ok], len(target) - 1)], np.nan)
    centre = np.nanmean(near, axis=1)
    d = near - centre[:, None, :]
    d = np.where(np.isnan(d), 0.0, d)
    cov = np.einsum("qki,qkj->qij", d, d)
    values, vectors = np.linalg.eigh(cov)
    line = values[:, 0] <= LINEAR * values[:, 1]
    normal = vectors[line, :, 0]  # the eigenvector of the smaller eigenvalue: across the line
    off = np.abs(np.einsum("qi,qi->q", source[ok][line] - centre[line], normal))
    ok[np.flatnonzero(ok)[~line]] = False
    return ok, off


def _box(slices: list[SliceView], matched: list[np.ndarray]) -> tuple[float, float, float]:
    """The square around the matched source points (every source point when none match)."""
    pts = np.concatenate(matched) if matched else np.empty((0, 2))
    if len(pts) < 10:
        pts = np.concatenate([s.source for s in slices] + [np.zeros((1, 2))])
    lo, hi = np.percentile(pts, 1, axis=0), np.percentile(pts, 99, axis=0)
    side = max(float(np.max(hi - lo)) + 2 * MARGIN_M, MIN_SPAN_M)
    centre = 0.5 * (lo + hi)
    return float(centre[0] - side / 2), float(centre[1] - side / 2), side


def link_view(T_target_source: np.ndarray, target: SliceSample, source: SliceSample) -> LinkView:
    """The link ``T_target_source`` (4x4, the scans' own frames) seen in its scans' slice
    samples, slice by slice (the heights both have)."""
    A = carried(T_target_source, target, source)
    slices, matched = [], []
    for h, t, s in zip(target.heights, target.slices, source.slices, strict=False):
        t64 = np.asarray(t, float)
        s64 = np.asarray(s, float) @ A[:2, :2].T + A[:2, 2]
        ok, off = residuals(t64, s64)
        slices.append(SliceView(h, t64, s64, 100.0 * off))
        matched.append(s64[ok])
    return LinkView(tuple(slices), _box(slices, matched))
