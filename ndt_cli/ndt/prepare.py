"""From a point cloud to what the registration needs: reduction point, vertical, ground, slices.

A scan's reduced frame is its own frame shifted by the reduction point ``r``: the median of its
points in x, y (rounded to whole metres; a few stray points far away do not move it) and the
ground under that point in z. All float maths happens there, so georeferenced coordinates (e.g.
5e6 m UTM northings) lose no precision. Levelling turns the reduced frame so that its z axis is
the vertical (:mod:`ndt_cli.ndt.vertical`), and each point's height is taken above the ground
model under it (:mod:`ndt_cli.ndt.terrain`), so slices cut the same things in every scan of a
sloping street.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ndt_cli.config.scenes import for_scene
from ndt_cli.config.schema import Config, GroundConfig, InputConfig, SlicesConfig
from ndt_cli.core.geometry import SURFACES, Surfaces, VoxelThinner
from ndt_cli.core.transforms import levelling_rotation, rotation4, translation
from ndt_cli.errors import InputError
from ndt_cli.io.blocks import Block
from ndt_cli.io.points import check_spread
from ndt_cli.ndt.backend import NUMBA, Kernels
from ndt_cli.ndt.ceiling import CeilingView, ceiling_view
from ndt_cli.ndt.chunks import HELD_SUFFIXES, ScanChunks, no_points_in_range
from ndt_cli.ndt.slicing import GROUND_SAMPLE
from ndt_cli.ndt.terrain import REACH, Terrain, terrain_of
from ndt_cli.ndt.vertical import Patches, Vertical, vertical_of
from ndt_cli.ndt.visibility import Sight

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PreparedScan:
    """A scan cut into slices. ``slices[k]`` is (n_k, 2) float64, metres, reduced frame."""

    path: Path | None
    reduction: np.ndarray  # (3,) float64: the ground under the scan's centre, scan frame, m
    ground_z: float  # ground level, scan frame (= reduction[2])
    slices: tuple[np.ndarray, ...]
    n_points: int
    level: np.ndarray = field(default_factory=lambda: np.eye(3))  # scan axes -> levelled axes
    points3d: np.ndarray | None = None  # thinned 3D points minus the reduction (for ICP), m
    terrain: Terrain = field(default_factory=Terrain.flat)  # ground heights, reduced level frame
    vertical: Vertical | None = None  # None: ground.z given, no levelling
    ceiling: CeilingView | None = None  # what it sees above it (None: too little to tell)

    def to_local(self) -> np.ndarray:
        """4x4 from the scan frame to the reduced, levelled frame: q = L (p - reduction)."""
        return rotation4(self.level) @ translation(-self.reduction)

    def from_local(self) -> np.ndarray:
        """4x4 from the reduced, levelled frame back to the scan frame."""
        return translation(self.reduction) @ rotation4(self.level.T)

    @property
    def tilt_deg(self) -> float:
        """Angle (degrees) between the scan's z axis and the vertical it was levelled to."""
        return 0.0 if self.vertical is None else self.vertical.tilt_deg

    @cached_property
    def sight(self) -> Sight | None:
        """What this scan's scanner saw, for the free-space check (None when it cannot say:
        :meth:`Sight.of_scan`). Built on first use and kept with the scan, pickled copies
        included: a scan in several links of a network builds it once."""
        return Sight.of_scan(self)

    @property
    def label(self) -> str | None:
        """The scan's file as given (None: prepared from an array)."""
        return None if self.path is None else str(self.path)

    def centroid(self) -> np.ndarray:
        """Median (x, y) of all slice points, reduced frame: a robust centre of the scene."""
        xy = np.concatenate(self.slices)
        return np.median(xy, axis=0) if len(xy) else np.zeros(2)

    def preview(self, max_points: int = 4000) -> np.ndarray:
        """Thinned slice points as (x, y, z) in the scan's own frame (metres), for top views."""
        xy = np.concatenate(self.slices)
        step = max(1, len(xy) // max_points)
        xyz = np.column_stack([xy[::step], np.zeros(len(xy[::step]))])
        T = self.from_local()
        return xyz @ T[:3, :3].T + T[:3, 3]


@dataclass(frozen=True)
class _FirstPass:
    sample: np.ndarray  # regular-stride sample of at most GROUND_SAMPLE points, scanner frame
    n_points: int


def _first_pass(scan: ScanChunks, inp: InputConfig) -> _FirstPass:
    """A regular-stride sample for the vertical and the ground, and the count."""
    stride = scan.n_points // GROUND_SAMPLE + 1
    parts, seen = [], 0
    for c in scan.chunks():
        if len(c) == 0:
            continue
        parts.append(c.rows(slice((-seen) % stride, None, stride)).xyz())
        seen += len(c)
    if seen == 0:
        raise no_points_in_range(inp, scan.path)
    return _FirstPass(np.concatenate(parts), seen)


@dataclass(frozen=True)
class ScanFrame:
    """Where a scan's reduced, levelled frame lies in the scan's own frame: the reduction point
    (m), the levelling rotation (scan axes to levelled axes), the ground under it, the vertical
    found (None with ``ground.z``) and the distance (m) beyond which points are stray."""

    reduction: np.ndarray
    level: np.ndarray
    terrain: Terrain
    vertical: Vertical | None
    keep: float


STRAY = 10.0  # points farther than this many times the sample's 99th-percentile distance
MIN_KEEP = 1000.0  # (and than this many metres) from the centre are stray (a glitch, a "no
# return" record at an absurd range) and left out: one such point must not move the frame


def _keep(rel: np.ndarray) -> float:
    """The distance (m) from the centre within which points count (see :data:`STRAY`)."""
    r = np.sqrt(np.einsum("ij,ij->i", rel, rel))
    return max(MIN_KEEP, STRAY * float(np.percentile(r, 99))) if len(r) else MIN_KEEP


def scan_frame(
    sample: np.ndarray, ground: GroundConfig, surfaces: Surfaces = SURFACES
) -> ScanFrame:
    """The frame of a scan from a regular sample of its points (scan frame, m): the centre,
    the vertical from its local planes (``ground.vertical``; the scanner's z with
    ``ground.level`` false), the ground model under it, and the reduction point on it."""
    centre = np.round(np.median(sample, axis=0))
    rel = sample - centre
    keep = _keep(rel)
    if ground.z is not None:
        reduction = np.array([centre[0], centre[1], float(ground.z)])
        return ScanFrame(reduction, np.eye(3), Terrain.flat(), None, keep)
    near = rel[np.hypot(rel[:, 0], rel[:, 1]) <= REACH]
    method = ground.vertical if ground.level else "scanner"
    vertical = vertical_of(Patches.of(near, surfaces), method)
    u = vertical.up
    level = levelling_rotation(-u[0] / u[2], -u[1] / u[2])
    terrain = terrain_of(near @ level.T)
    h0 = float(terrain.at(np.zeros((1, 2)))[0])
    reduction = centre + level.T @ np.array([0.0, 0.0, h0])
    return ScanFrame(reduction, level, terrain.shifted(h0), vertical, keep)


def _second_pass(
    scan: ScanChunks,
    frame: ScanFrame,
    slices: SlicesConfig,
    icp_voxel: float,
    kernels: Kernels,
) -> tuple[list[np.ndarray], np.ndarray | None]:
    """The slices (reduced, levelled frame; heights above the ground model) and, when
    ``icp_voxel`` > 0, the points thinned to one per ``icp_voxel`` cube (reduced frame, not
    levelled). Stray points (see :class:`ScanFrame`) are left out and counted in the log."""
    parts: list[list[np.ndarray]] = [[] for _ in slices.heights]
    thinner = VoxelThinner(icp_voxel, kernels.merge_groups) if icp_voxel > 0 else None
    far = 0
    for c in scan.chunks():
        try:
            cut = kernels.slice_pass(
                c,
                frame.reduction,
                frame.level,
                slices.heights,
                slices.thickness,
                icp_voxel,
                frame.terrain,
                frame.keep,
            )
        except ValueError as exc:
            raise InputError(f"{exc} (scan spans more than 100 km?)", scan.path) from None
        for k, part in enumerate(cut.slices):
            parts[k].append(part)
        if thinner is not None and cut.grouped is not None:
            thinner.add_grouped(*cut.grouped)
        far += cut.far
    if far:
        log.info("%s: left out %d stray point(s) beyond %.0f m", scan.path, far, frame.keep)
    cut_slices = [np.concatenate(p) if len(p) != 1 else p[0] for p in parts]
    return cut_slices, None if thinner is None else thinner.result()


def prepare_chunks(
    scan: ScanChunks,
    *,
    ground: GroundConfig,
    slices: SlicesConfig,
    icp_voxel: float = 0.0,
    min_points: int = 3,
    kernels: Kernels = NUMBA,
    inp: InputConfig | None = None,
) -> PreparedScan:
    """Find the frame of a scan (reduction point, vertical, ground) and cut its slices.

    Two passes over the chunks (held in memory, or read again from the file: see
    :class:`ScanChunks`): the first takes a regular sample for the vertical and the ground
    (:func:`scan_frame`); the second cuts the slices and thins the points for ICP (``icp_voxel``
    m, 0: no ICP points). Fewer than ``min_points`` slice points is an error.
    """
    first = _first_pass(scan, inp or InputConfig())
    check_spread(first.sample, scan.path)
    frame = scan_frame(first.sample, ground, kernels.surfaces)
    cut, thin = _second_pass(scan, frame, slices, icp_voxel, kernels)
    if sum(len(s) for s in cut) < min_points:
        raise InputError(
            f"no points in any slice at heights {list(slices.heights)} m above the ground "
            f"(ground found at z = {frame.reduction[2]:.2f}); check slices.heights or set "
            "ground.z",
            scan.path,
        )
    reduction = frame.reduction
    return PreparedScan(
        scan.path,
        reduction,
        float(reduction[2]),
        tuple(cut),
        first.n_points,
        frame.level,
        thin,
        frame.terrain,
        frame.vertical,
        ceiling_view(first.sample, frame.level),
    )


def look(scan: str | Path | np.ndarray, cfg: Config) -> CeilingView | None:
    """What a scan sees above it (:mod:`ndt_cli.ndt.ceiling`), from the first pass alone."""
    first = _first_pass(ScanChunks.of(scan, cfg.input), cfg.input)
    frame = scan_frame(first.sample, cfg.ground)
    return ceiling_view(first.sample, frame.level)


def settle_scene(cfg: Config, view: CeilingView | None) -> tuple[Config, str]:
    """``cfg`` for the scene a scan's ``view`` shows when ``scene.kind`` is auto (indoor when
    it sees a ceiling, else street), as given otherwise; and why, in words."""
    if cfg.scene.kind != "auto":
        return cfg, f"{cfg.scene.kind}, as configured"
    kind = "indoor" if view is not None and view.indoors else "street"
    seen = "too few points look upward to tell" if view is None else view.describe()
    return for_scene(cfg, kind), f"{kind}: {seen}"


def prepare(points: np.ndarray, cfg: Config, path: Path | None = None) -> PreparedScan:
    """:func:`prepare_chunks` of a scan held in memory, with the settings of ``cfg``."""
    return load_and_prepare_chunks(ScanChunks.held_points(points, path), cfg)


def load_and_prepare_chunks(
    scan: ScanChunks, cfg: Config, kernels: Kernels = NUMBA
) -> PreparedScan:
    """:func:`prepare_chunks` with the ground, slices, ICP thinning and grid settings of ``cfg``."""
    icp_voxel = cfg.refine.voxel if cfg.refine.method == "icp" else 0.0
    return prepare_chunks(
        scan,
        ground=cfg.ground,
        slices=cfg.slices,
        icp_voxel=icp_voxel,
        min_points=cfg.grid.min_points,
        kernels=kernels,
        inp=cfg.input,
    )


def load_and_prepare(
    scan: str | Path | np.ndarray, cfg: Config, kernels: Kernels = NUMBA
) -> PreparedScan:
    """Read a scan (once, and held while it is prepared unless it is too large: see
    :class:`ScanChunks`) and prepare it."""
    return load_and_prepare_chunks(ScanChunks.of(scan, cfg.input), cfg, kernels)


def _load_runtime(kernels: Kernels, integers: bool) -> None:
    """Load what preparing a scan needs once per process: Numba's runtime (its first call of a
    cached kernel takes about a fifth of a second, almost all of it holding the GIL) and the
    slice pass for the scan's coordinates (a LAS file's ``integers`` or float64). Run in a
    helper thread while the files are read, it overlaps the reads, which spend their time in
    the disk and in numpy. A failure here is left to the real call to report."""
    one = np.ones(3)
    block = Block(np.zeros((1, 3), np.int32), one, one) if integers else Block(np.zeros((1, 3)))
    try:
        kernels.slice_pass(block, np.zeros(3), np.eye(3), [0.0], 0.1, 0.1, None, 1.0)
    except Exception:  # the same call fails again where its error is reported
        return


def load_and_prepare_pair(
    target: str | Path | np.ndarray,
    source: str | Path | np.ndarray,
    cfg: Config,
    kernels: Kernels = NUMBA,
) -> tuple[PreparedScan, PreparedScan]:
    """:func:`load_and_prepare` of two scans at once: the source in a helper thread while this
    thread prepares the target, while a third loads the runtime (:func:`_load_runtime`).
    Reading, the passes over the points and the thinning release the GIL, so on two cores a
    pair takes about two thirds of the time of two scans in turn.
    The scans are independent: the results are those of two calls in turn. The target's error,
    if any, is the one raised. The helper is a daemon: Ctrl-C is not held up until it ends."""
    done: dict[str, PreparedScan | BaseException] = {}
    integers = isinstance(target, str | Path) and Path(target).suffix.lower() in HELD_SUFFIXES
    loader = threading.Thread(
        target=_load_runtime, args=(kernels, integers), name="runtime", daemon=True
    )
    loader.start()

    def prepare_source() -> None:
        try:
            done["scan"] = load_and_prepare(source, cfg, kernels)
        except BaseException as exc:  # handed to the caller below
            done["scan"] = exc

    helper = threading.Thread(target=prepare_source, name="prepare-source", daemon=True)
    helper.start()
    tgt = load_and_prepare(target, cfg, kernels)
    helper.join()
    src = done["scan"]
    if isinstance(src, BaseException):
        raise src
    return tgt, src
