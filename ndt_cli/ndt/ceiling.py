"""Whether a scan was taken indoors: a ceiling over most of the scanner's upward view.

An interior needs other settings than a street (:mod:`ndt_cli.config.scenes`): its ceiling at
2.5-4 m leaves no slice above it, its rooms are a few metres wide, and its right angles and
repeated rooms make poses turned by 90 or 180 degrees fit nearly as well as the truth. A
terrestrial scanner indoors sees a ceiling in every direction above it; outdoors it sees sky
(no return), facades far away or crowns at every height.

Frames and units: the sample is in the scan's own frame (m), the scanner at its origin; heights
are along the vertical found for the scan (the levelling rotation of its frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UP_DEG = 50.0  # points seen at least this far above the horizon look at the ceiling
MIN_UP = 200  # fewer upward points say nothing (a car lidar's narrow field of view)
SECTORS = 12  # azimuth sectors the upward points must cover (most of them)
MIN_SECTORS = 10
BAND = 0.15  # m: half the thickness of the band of heights that holds a flat ceiling
MIN_SHARE = 0.6  # share of the upward points in the ceiling's band that makes it a ceiling
HEIGHT = (0.5, 8.0)  # m above the scanner: where a ceiling can be


@dataclass(frozen=True)
class CeilingView:
    """What a scan sees above it: the share of its upward points (0-1) in the band of heights
    :data:`BAND` m either side that holds the most of them, that band's height above the
    scanner (m), and how many azimuth sectors of :data:`SECTORS` its points cover."""

    share: float
    height: float
    sectors: int

    @property
    def indoors(self) -> bool:
        """A ceiling over most of the scanner: a flat band holds most of the upward points, at
        a plausible height, all round."""
        return (
            self.share >= MIN_SHARE
            and HEIGHT[0] <= self.height <= HEIGHT[1]
            and self.sectors >= MIN_SECTORS
        )

    def describe(self) -> str:
        where = "a ceiling" if self.indoors else "no ceiling"
        return (
            f"{where}: {self.share:.0%} of the upward view at {self.height:.2f} m above the "
            f"scanner, {self.sectors} of {SECTORS} directions"
        )


def ceiling_view(sample: np.ndarray, level: np.ndarray) -> CeilingView | None:
    """The :class:`CeilingView` of a scan from a sample of its points (N,3, scan frame, m, the
    scanner at the origin) and its levelling rotation (scan axes to levelled axes); None when
    too few points look upward to tell."""
    up = np.asarray(sample, dtype=float) @ np.asarray(level, dtype=float).T
    r = np.sqrt(np.einsum("ij,ij->i", up, up))
    above = up[up[:, 2] > np.sin(np.radians(UP_DEG)) * r]
    if len(above) < MIN_UP:
        return None
    heights = np.sort(above[:, 2])
    k = np.searchsorted(heights, heights + 2 * BAND, side="right") - np.arange(len(heights))
    best = int(np.argmax(k))
    low, high = heights[best], heights[best + k[best] - 1]
    ceiling = above[(above[:, 2] >= low) & (above[:, 2] <= high)]
    azimuth = np.arctan2(ceiling[:, 1], ceiling[:, 0])
    sector = np.floor((azimuth + np.pi) / (2 * np.pi) * SECTORS).astype(int) % SECTORS
    share = float(k[best]) / len(above)
    return CeilingView(share, float(np.median(ceiling[:, 2])), len(set(sector.tolist())))
