"""The vertical of a scan: the direction the slices are cut across.

The paper cuts horizontal slices, which assumes each scan's z axis is the vertical. A tripod
stands up to a degree or so off, and the ground is no reference either: a street has grades,
camber and cross-fall of several percent (an 8 % grade is 4.6 degrees), so levelling a scan to
its ground tilts its slices across the facades, and two scans on differently sloping ground
get differently tilted slices (a biased 2D optimum, and an ICP correction that the slices then
judge worse).

Walls, facades, poles and trunks are vertical, whatever the ground does. Their normals are
horizontal: the vertical is the direction most nearly perpendicular to the normals of a scan's
near-vertical planar patches, the eigenvector of the smallest eigenvalue of
``sum(n n^T)``, found in a cone that narrows around the previous estimate (20 down to 0.7
degrees). The cone starts around the normal of the roughly horizontal surfaces
(:func:`horizontal_up`), which finds tilts of many degrees. When the
vertical surfaces face one way only (two parallel facades and nothing across them), the
direction along them is left to the ground: the vertical is the one perpendicular to the
facades that lies closest to the ground's normal. With too few vertical surfaces the ground's
normal is the vertical, as before. On simulated streets (grades up to 8 %, camber, scanners
tilted up to 1 degree) the vertical comes out within 0.03 degrees, against the ground's 1-5.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from ndt_cli.core.geometry import SURFACES, Surfaces, normals, voxel_thin

VOXEL = 0.2  # m: the points' thinning before their normals
NEIGHBOURS = 10  # points of each local plane
MAX_NORMALS = 40_000  # normals computed per scan (a regular stride of the thinned points)
PLANAR = 0.9  # planarity (1 - smallest / middle eigenvalue) of the patches used
CONES_DEG = (20.0, 10.0, 5.0, 3.0, 2.0, 1.0, 0.7)  # the cone around the vertical, narrowing
HORIZONTAL_DEG = 25.0  # roughly horizontal patches: normal within this of the first guess
MIN_NORMALS = 200  # fewer vertical patches do not tell the vertical
MIN_SPREAD = 0.02  # smaller / larger eigenvalue of the vertical patches' horizontal spread
# below which the patches face one way only (the direction along them is left to the ground)
LEAN_CONE_DEG = 5.0  # patches within this of vertical measure how clean the structures are
MAX_LEAN_DEG = 1.0  # "auto": structures whose patches lean more (robust std) are not trusted:
# simulated streets 0.4 deg, real robot and car lidars 1.3-3 deg (ring biases, car bodies,
# vegetation), whose frames then disagreed by 0.2-1 deg against 0.03-0.35 from the ground
SLOPED_DEG = 2.0  # "auto": see _sloped


class VerticalSource(StrEnum):
    """Where a scan's vertical came from."""

    STRUCTURES = "structures"  # normals of walls, facades, poles: perpendicular to the vertical
    STRUCTURES_GROUND = "structures+ground"  # facades one way only; along them, the ground
    GROUND = "ground"  # the roughly horizontal surfaces (vertical ones too few or unclean)
    SCANNER = "scanner"  # the scanner's own z (a compensated instrument, or asked for)


@dataclass(frozen=True)
class Vertical:
    """A scan's vertical: ``up`` (unit vector, the scan's axes), where it came from, the spread
    of the vertical patches' normals around it (smaller over larger eigenvalue; 0 when unused)
    and how much those patches lean from perpendicular (robust standard deviation, degrees)."""

    up: np.ndarray
    source: VerticalSource
    spread: float = 0.0
    lean: float = float("nan")  # robust std of the vertical patches' lean (deg), when measured

    @property
    def tilt_deg(self) -> float:
        """Angle (degrees) between the scan's z axis and the vertical."""
        return float(np.degrees(np.arccos(np.clip(self.up[2], -1.0, 1.0))))


@dataclass(frozen=True)
class Patches:
    """Unit normals (upward where not vertical) and planarities of a scan's local planes."""

    normals: np.ndarray
    planarity: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, surfaces: Surfaces = SURFACES) -> Patches:
        """The local planes of (N,3) points (any frame near the scan's own, m)."""
        thin = voxel_thin(points, VOXEL)
        if len(thin) < 50:
            return cls(np.zeros((0, 3)), np.zeros(0))
        k = min(NEIGHBOURS, len(thin))
        n, planarity = normals(
            thin[:: -(-len(thin) // MAX_NORMALS)], surfaces.grid(thin, VOXEL), k, surfaces
        )
        return cls(n * np.where(n[:, 2] < 0, -1.0, 1.0)[:, None], planarity)


def horizontal_up(patches: Patches) -> np.ndarray | None:
    """The normal shared by most roughly horizontal planar patches (the ground, floors, flat
    roofs), averaged in a cone narrowing from 10 to 2.5 degrees; None when too few."""
    n = patches.normals[
        (patches.planarity > 0.7) & (patches.normals[:, 2] > np.cos(np.radians(HORIZONTAL_DEG)))
    ]
    if len(n) < 20:
        return None
    u = np.median(n, axis=0)
    for cone in (10.0, 5.0, 2.5):
        near = n[n @ (u / np.linalg.norm(u)) > np.cos(np.radians(cone))]
        if len(near) < 10:
            break
        u = near.mean(axis=0)
    return u / np.linalg.norm(u)


def _step(side: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, float]:
    """The direction most nearly perpendicular to the normals ``side`` (unit, upward), and
    their spread (smaller over larger eigenvalue of ``sum(n n^T)`` across the vertical). When
    the spread is small the patches face one way only: the direction along them is not told,
    and is kept from ``u`` (the vertical is ``u`` made perpendicular to the normal they
    share)."""
    w, V = np.linalg.eigh(side.T @ side)
    spread = float(w[1] / w[2]) if w[2] > 0 else 0.0
    if spread >= MIN_SPREAD:
        return V[:, 0] * (1.0 if V[2, 0] >= 0 else -1.0), spread
    facing = V[:, 2]
    along = u - (u @ facing) * facing
    return along / np.linalg.norm(along), spread


def _lean_spread(n: np.ndarray, u: np.ndarray) -> float:
    """Robust standard deviation (degrees) of how far the near-vertical patches lean from
    being perpendicular to ``u`` (within :data:`LEAN_CONE_DEG`)."""
    lean = np.degrees(np.arcsin(np.clip(n @ u, -1.0, 1.0)))
    lean = lean[np.abs(lean) < LEAN_CONE_DEG]
    return 1.4826 * float(np.median(np.abs(lean))) if len(lean) else np.inf


def _from_structures(n: np.ndarray, ground: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The vertical perpendicular to the near-vertical patches' normals ``n`` (cones
    narrowing around ``ground``) and the patches' spread; None with too few patches or when
    the result strays out of the widest cone."""
    u, spread = ground, -1.0
    for cone in CONES_DEG:
        side = n[np.abs(n @ u) < np.sin(np.radians(cone))]
        if len(side) < MIN_NORMALS:
            break
        u, spread = _step(side, u)
    if spread < 0.0 or np.degrees(np.arccos(np.clip(u @ ground, -1, 1))) > CONES_DEG[0]:
        return None
    return u, spread


def vertical_of(patches: Patches, method: str = "auto") -> Vertical:
    """The vertical of a scan from its local planes (``method``: "auto", "structures",
    "ground" or "scanner"; see the module docstring). "auto" takes the structures' vertical
    when their patches are clean (they lean by less than :data:`MAX_LEAN_DEG`, robust
    standard deviation, from it) or the ground slopes under an upright scanner
    (:func:`_sloped`), else the ground's."""
    z = np.array([0.0, 0.0, 1.0])
    if method == "scanner":
        return Vertical(z, VerticalSource.SCANNER)
    ground = horizontal_up(patches)
    ground = z if ground is None else ground
    if method == "ground":
        return Vertical(ground, VerticalSource.GROUND)
    n = patches.normals[patches.planarity > PLANAR]
    found = _from_structures(n, ground)
    if found is None:
        return Vertical(ground, VerticalSource.GROUND)
    u, spread = found
    lean = _lean_spread(n, u)
    if method == "auto" and lean > MAX_LEAN_DEG and not _sloped(ground, u, z):
        return Vertical(ground, VerticalSource.GROUND, lean=lean)
    source = VerticalSource.STRUCTURES if spread >= MIN_SPREAD else VerticalSource.STRUCTURES_GROUND
    return Vertical(u, source, max(spread, 0.0), lean)


def _sloped(ground: np.ndarray, structures: np.ndarray, z: np.ndarray) -> bool:
    """The ground slopes under an upright scanner: its normal is more than :data:`SLOPED_DEG`
    from both the scanner's z and the unclean structures' vertical, which agree with each other
    within that. A forest plot on an 8.5 % slope, 30 % of its trunks leaning 1-6 degrees: the
    ground 4.8 degrees off, the structures (leaning 1.1 degrees) 0.1 and the scanner's z at
    most 1. A car lidar tilted 10 degrees on a level road: its z far from both, the ground
    kept (unclean structures were up to several degrees off there)."""

    def apart(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.degrees(np.arccos(np.clip(abs(float(a @ b)), 0.0, 1.0))))

    upright = apart(structures, z) <= SLOPED_DEG
    return upright and min(apart(ground, z), apart(ground, structures)) > SLOPED_DEG


def dominant_up(points: np.ndarray, surfaces: Surfaces = SURFACES) -> np.ndarray:
    """The normal of the roughly horizontal surfaces of (N,3) points (:func:`horizontal_up`),
    +z when there are too few."""
    up = horizontal_up(Patches.of(points, surfaces))
    return np.array([0.0, 0.0, 1.0]) if up is None else up
