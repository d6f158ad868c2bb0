"""Exact global search for the planar pose between two prepared scans: multi-resolution
branch-and-bound correlative matching (Olson, ICRA 2009; Hess et al., Cartographer, ICRA 2016).

Frames and units: slices are (n_k, 2) float64 arrays in metres, each in its scan's reduced,
levelled frame (:class:`~ndt_cli.ndt.prepare.PreparedScan`). A pose (tx, ty, yaw) (m, m, rad)
maps the source into the target, ``x_target = R(yaw) x_source + t``, as
:func:`ndt_cli.ndt.search.search_starts`.

The discretised problem, scored exactly:

- **Field**: per target slice, a likelihood field at ``resolution`` m pixels, 0..255
  (:func:`likelihood_field`: 255 on a pixel holding a target point, falling off as a Gaussian
  of the distance to the nearest such pixel, sigma one pixel). On 120 simulated street links
  (``benchmarks/search_sweep.py``, 1 m pixels) its best pose was within 2 m / 2 deg of the
  truth on 110, against 105 for the target's NDT score rasterised (2 m cells), 95 for sigma
  2 pixels and 94 for occupancy convolved with a Gaussian: a hit on a sparsely sampled far
  facade counts as much as one on a dense near one, and a miss by a pixel costs.
  Integer values make every score exact, whatever the order of the sums. Optionally
  (:func:`penalised`) a pixel where the target's scanner saw empty space at its slice's height
  costs a point landing there instead of counting nothing (``search.free_space_penalty``).
- **Source points**: each source slice voxel-filtered at ``resolution``, taken relative to the
  source centre ``c_s`` (median of its slice points); a point of slice k scores in field k only.
- **Yaws**: ``yaw_m = 2 pi m / n_yaw``, ``n_yaw = ceil(2 pi / yaw_step)``; by default the step
  moves the farthest thinned point by one pixel (``resolution / radius``).
- **Translations**: the lattice ``u_ij = ((i - n) res, (j - n) res)``, ``0 <= i, j <= 2n``,
  ``n = floor(window / res)``: where the source centre lands relative to the target centre
  ``c_t``. Pose ``(m, i, j)`` is ``t = c_t + u_ij - R(yaw_m) c_s``.
- **Score** of ``(m, i, j)``: ``sum_k F_k[q_k + (i, j)]``, ``q_k`` the pixel (floor) of point k
  at yaw m and ``u_00``: the nearest-pixel field value of every point, summed (0 off the field).

**What is guaranteed.** Two poses are *the same candidate* when their source centres land at
most ``exclusion`` m apart and their yaws differ by at most ``exclusion_yaw`` (both rounded down
to whole lattice / yaw steps); otherwise they are *distinct*. The candidates returned are
exactly the first K picks of greedy non-maximum suppression over *every* pose of the
discretisation with a positive score, taken in the order (score descending, then yaw index, i,
j ascending): the best pose, then the best pose distinct from it, then the best distinct from
both, ... as if all ``n_yaw (2n+1)^2`` poses had been scored. Fewer than K come back only when
fewer exist.

Why one pass suffices: a node (a block of translations at one yaw) is pruned when its bound,
an exact upper bound of every score in it, is below the threshold: the lowest score of K
*anchors*, leaves found so far that are pairwise more than twice the exclusion apart. Each
greedy pick is the same candidate as at most one anchor (triangle inequality), so every pick
up to the K-th has an anchor still distinct from the earlier picks and scores at least the
threshold. No threshold ever exceeds the K-th pick's score, so every pose scoring at least
that much is reached and recorded, and the suppression over the recorded leaves reproduces the
exhaustive one. (Pruning at the K-th distinct score found so far, with the plain exclusion, is
cheaper but not exact: a later, better pose can suppress two earlier picks at once.)

Yaws are searched in rounds of :data:`ROUND` (best root bound first), in parallel within a
round, each yaw pruning against the anchors of the round's start plus its own leaves; rounds
are merged in a fixed order, so poses, scores and node counts do not depend on threads.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.core.transforms import wrap_angle
from ndt_cli.ndt import bnb_kernels
from ndt_cli.ndt.bnb_kernels import Lattice, SearchKernels
from ndt_cli.ndt.slicing import voxel_filter_2d

FIELD_MAX = 255  # field value of a pixel that holds a target point
ROUND = 16  # yaws searched in parallel between two merges of the anchors
ROOT_LEVEL = 4  # roots are blocks of 2^4 x 2^4 translations: their bounds order the yaws
FIELD_REACH = 4.0  # the field is built this many sigmas beyond the target's points
PENALTY_MAX = 32_000  # the most a pixel in free space may cost (int16 values)


@dataclass(frozen=True)
class ScoreField:
    """Per target slice, a field of scores: ``values[k, a, b]`` (uint8, 0..255; int16 with
    negative values where a point costs, :func:`penalised`) covers the target frame's
    ``origin + ((a, b) .. (a+1, b+1)) * resolution`` (metres, reduced levelled frame)."""

    values: np.ndarray  # (S, nx, ny) uint8 or int16
    origin: np.ndarray  # (2,) m: corner of pixel (0, 0)
    resolution: float  # m
    centre: np.ndarray  # (2,) m: median of the target's slice points (PreparedScan.centroid)


def _centre(slices: Sequence[np.ndarray]) -> np.ndarray:
    xy = np.concatenate([np.reshape(s, (-1, 2)) for s in slices])
    return np.median(xy, axis=0) if len(xy) else np.zeros(2)


def likelihood_field(
    target_slices: Sequence[np.ndarray], *, resolution: float = 1.0, sigma_px: float = 1.0
) -> ScoreField:
    """Per slice: 255 on every pixel holding a target point, ``255 exp(-d^2 / 2 sigma^2)`` at
    ``d`` pixels from the nearest such pixel (rounded; 0 beyond ~3.5 sigma)."""
    if resolution <= 0 or sigma_px <= 0:
        raise ValueError("need resolution > 0 and sigma_px > 0")
    xy = [np.reshape(s, (-1, 2)) for s in target_slices]
    every = np.concatenate([np.zeros((0, 2)), *xy])
    if len(every) == 0:
        return ScoreField(np.zeros((len(xy), 1, 1), np.uint8), np.zeros(2), resolution, np.zeros(2))
    pad = int(np.ceil(FIELD_REACH * sigma_px)) + 1
    low, high = column_bounds(every)
    lo = np.floor(low / resolution).astype(np.int64) - pad
    shape = np.floor(high / resolution).astype(np.int64) + pad - lo + 1
    values = np.zeros((len(xy), *shape), np.uint8)
    dx, dy, falloff = _falloff(sigma_px)
    for k, s in enumerate(xy):
        ij = np.floor(s / resolution).astype(np.int64) - lo
        held = np.unique(ij[:, 0] * shape[1] + ij[:, 1])
        flat = values[k].reshape(-1)  # a view: written in place
        for step, v in zip(dx * shape[1] + dy, falloff, strict=True):
            flat[held + step] = np.maximum(flat[held + step], v)
    return ScoreField(values, lo * resolution, resolution, _centre(target_slices))


def _falloff(sigma_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel offsets (dx, dy) whose field value is not 0, and the value: ``255 exp(-d^2 / 2
    sigma^2)`` rounded, ``d = sqrt(dx^2 + dy^2)``. The value falls with the distance, so a pixel's
    value is the largest over the target pixels within reach: that of the nearest, as a
    Euclidean distance transform would give it, computed from the same ``d``. Every offset with a
    non-zero value lies within :data:`FIELD_REACH` sigmas, inside the field's margin."""
    r = int(np.ceil(FIELD_REACH * sigma_px))
    dx, dy = (a.ravel() for a in np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1)))
    d = np.sqrt((dx * dx + dy * dy).astype(np.float64))
    v = np.rint(FIELD_MAX * np.exp(-0.5 * (d / sigma_px) ** 2)).astype(np.uint8)
    keep = v > 0
    return dx[keep], dy[keep], v[keep]


def pixel_centres(field: ScoreField) -> np.ndarray:
    """(nx * ny, 2) centres (m, the field's frame) of the field's pixels, in ``values[k]``'s
    flat order."""
    _, nx, ny = field.values.shape
    ax = field.origin[0] + (np.arange(nx) + 0.5) * field.resolution
    ay = field.origin[1] + (np.arange(ny) + 0.5) * field.resolution
    X, Y = np.meshgrid(ax, ay, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel()])


def penalised(field: ScoreField, free: np.ndarray, penalty: int) -> ScoreField:
    """The field with ``-penalty`` on every pixel of ``free`` (S, nx, ny) bool that no target
    point is near (value 0): a source point there lands where the target's scanner saw
    nothing. int16 values; the bounds stay exact (max-pooling bounds negative values too)."""
    if not 0 <= penalty <= PENALTY_MAX:
        raise ValueError(f"need 0 <= penalty <= {PENALTY_MAX}")
    values = field.values.astype(np.int16)
    values[free & (values == 0)] = -penalty
    return replace(field, values=values)


def max_pyramid(values: np.ndarray, top: int) -> np.ndarray:
    """Levels 0..``top`` of max-pooled fields: ``out[h, k, a, b]`` is the largest of
    ``values[k, a .. a+2^h-1, b .. b+2^h-1]`` (clipped at the far edges). (S,nx,ny) in,
    (top+1, S, nx, ny) of the same integer type out."""
    out = np.empty((top + 1, *values.shape), values.dtype)
    out[0] = values
    for h in range(1, top + 1):
        s, m = 1 << (h - 1), out[h - 1].copy()
        m[:, :-s, :] = np.maximum(m[:, :-s, :], m[:, s:, :])
        m[:, :, :-s] = np.maximum(m[:, :, :-s], m[:, :, s:])
        out[h] = m
    return out


@dataclass(frozen=True)
class SearchGrid:
    """The discretisation of a search (see the module docstring)."""

    points: np.ndarray  # (N,2) m: thinned source slice points minus the source centre
    slice_id: np.ndarray  # (N,) int64
    source_centre: np.ndarray  # (2,) m, source frame
    target_centre: np.ndarray  # (2,) m, target frame
    resolution: float  # m: pixel and lattice step
    half: int  # n: lattice indices run 0..2n, u = (index - n) * resolution
    n_yaw: int

    @property
    def yaw_step(self) -> float:
        """Yaw step, radians."""
        return 2 * np.pi / self.n_yaw

    def yaws(self) -> np.ndarray:
        """(n_yaw,) radians in [0, 2 pi)."""
        return self.yaw_step * np.arange(self.n_yaw)

    def poses(self, index: np.ndarray) -> np.ndarray:
        """(K,3) poses (tx m, ty m, yaw rad in [-pi, pi)) of lattice rows (yaw index, i, j)."""
        index = np.reshape(index, (-1, 3))
        yaw = self.yaw_step * index[:, 0]
        c, s = np.cos(yaw), np.sin(yaw)
        cx, cy = self.source_centre
        u = (index[:, 1:] - self.half) * self.resolution
        tx = self.target_centre[0] + u[:, 0] - (c * cx - s * cy)
        ty = self.target_centre[1] + u[:, 1] - (s * cx + c * cy)
        return np.column_stack([tx, ty, wrap_angle(yaw)])


def search_grid(
    field: ScoreField,
    source_slices: Sequence[np.ndarray],
    *,
    window: float,
    yaw_step: float | None = None,
) -> SearchGrid:
    """Thin the source slices at the field's resolution and fix the yaws and the lattice."""
    res = field.resolution
    n_slices = min(len(source_slices), field.values.shape[0])  # a slice scores in its twin only
    thin = [voxel_filter_2d(np.reshape(s, (-1, 2)), res) for s in source_slices[:n_slices]]
    centre = _centre(source_slices)
    pts = np.concatenate([np.zeros((0, 2)), *thin]) - centre
    sid = np.concatenate([np.zeros(0, np.int64), *(np.full(len(t), k) for k, t in enumerate(thin))])
    radius = max(float(np.sqrt((pts**2).sum(axis=1)).max(initial=0.0)), res)
    step = yaw_step if yaw_step is not None else res / radius
    n_yaw = max(1, int(np.ceil(2 * np.pi / step - 1e-9)))
    half = int(np.floor(window / res + 1e-9))
    return SearchGrid(pts, sid.astype(np.int64), centre, field.centre, res, half, n_yaw)


def _pixels(field: ScoreField, grid: SearchGrid) -> tuple[np.ndarray, np.ndarray]:
    """Field pixel (qx, qy), each (n_yaw, N) int64, of every thinned point at every yaw and at
    the lattice's first translation ``u_00``."""
    yaw = grid.yaws()[:, None]
    c, s = np.cos(yaw), np.sin(yaw)
    x, y = grid.points[:, 0], grid.points[:, 1]
    off = grid.target_centre - grid.half * grid.resolution - field.origin
    qx = np.floor((c * x - s * y + off[0]) / grid.resolution).astype(np.int64)
    qy = np.floor((s * x + c * y + off[1]) / grid.resolution).astype(np.int64)
    return qx, qy


def _window_of(values: np.ndarray, lo: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """``values`` (S,nx,ny) re-cut to pixels ``lo .. lo+shape-1`` (zero outside)."""
    out = np.zeros((values.shape[0], *shape), values.dtype)
    a0, b0 = np.maximum(lo, 0)
    a1, b1 = np.minimum(lo + shape, values.shape[1:])
    if a1 > a0 and b1 > b0:
        out[:, a0 - lo[0] : a1 - lo[0], b0 - lo[1] : b1 - lo[1]] = values[:, a0:a1, b0:b1]
    return out


def lattice(
    field: ScoreField, grid: SearchGrid, exclusion: float, exclusion_yaw: float
) -> tuple[Lattice, np.ndarray]:
    """The pyramid cut to the pixels the search can read, and every point's flat base index
    per yaw (n_yaw, N) int64: every read of the kernels is in bounds by construction."""
    last = 2 * grid.half
    top = min(int(np.ceil(np.log2(last + 1))), ROOT_LEVEL) if last > 0 else 0
    qx, qy = _pixels(field, grid)
    if qx.size == 0:
        qx = qy = np.zeros((grid.n_yaw, 0), np.int64)
    lo = np.array([qx.min(initial=0), qy.min(initial=0)])
    shape = np.array([qx.max(initial=0), qy.max(initial=0)]) + last - lo + 1
    pyramid = max_pyramid(_window_of(field.values, lo, shape), top)
    nx, ny = int(shape[0]), int(shape[1])
    bases = (grid.slice_id * nx + (qx - lo[0])) * ny + (qy - lo[1])
    starts = np.arange(0, last + 1, 1 << top, dtype=np.int64)
    roots = np.stack(np.meshgrid(starts, starts, indexing="ij"), axis=-1).reshape(-1, 2)
    r2_same = int(np.floor((exclusion / grid.resolution) ** 2 + 1e-9))
    yaw_same = int(np.floor(exclusion_yaw / grid.yaw_step + 1e-9))
    lat = Lattice(
        pyramid.ravel(),
        pyramid[0].size,
        ny,
        top,
        last,
        grid.n_yaw,
        4 * r2_same,
        2 * yaw_same,
        roots,
    )
    return lat, bases


def _branch_and_bound(
    lat: Lattice, bases: np.ndarray, k: int, kernels: SearchKernels
) -> tuple[np.ndarray, int]:
    """Every leaf (score, yaw, i, j) that reaches the final threshold (see the module
    docstring), and the number of nodes whose bound was computed."""
    rb = kernels.root_bounds(lat, bases)
    key = rb.max(axis=1, initial=0)
    order = np.argsort(-key, kind="stable")
    anchors, na = np.zeros((k, 4), np.int64), 0
    pool, nodes = np.zeros((0, 4), np.int64), rb.size
    limit = bnb_kernels.threshold.py_func
    for start in range(0, len(order), ROUND):
        batch = order[start : start + ROUND]
        batch = batch[key[batch] >= limit(anchors, na)]
        if len(batch) == 0:
            break
        leaves, n = kernels.search_round(lat, bases[batch], batch, rb[batch], anchors, na)
        nodes += int(n.sum())
        for part in leaves:
            na = kernels.feed_anchors(anchors, na, part, lat.n_yaw, lat.r2_sep, lat.yaw_sep)
        pool = np.concatenate([pool, *leaves])
        pool = pool[pool[:, 0] >= limit(anchors, na)]
    return pool, nodes


def distinct_picks(
    leaves: np.ndarray, k: int, n_yaw: int, r2_same: int, yaw_same: int
) -> np.ndarray:
    """Greedy non-maximum suppression: up to ``k`` rows (score, yaw index, i, j) of ``leaves``
    (M,4) int64, best first (ties: yaw index, i, j ascending), each distinct from those before
    (squared lattice distance above ``r2_same`` or cyclic yaw distance above ``yaw_same``)."""
    rows = leaves[np.lexsort((leaves[:, 3], leaves[:, 2], leaves[:, 1], -leaves[:, 0]))]
    alive = rows[:, 0] > 0
    picks = []
    while len(picks) < k and alive.any():
        p = rows[int(np.argmax(alive))]
        picks.append(p)
        dm = np.abs(rows[:, 1] - p[1]) % n_yaw
        dm = np.minimum(dm, n_yaw - dm)
        d2 = (rows[:, 2] - p[2]) ** 2 + (rows[:, 3] - p[3]) ** 2
        alive &= (d2 > r2_same) | (dm > yaw_same)
    return np.array(picks, np.int64).reshape(-1, 4)


@dataclass(frozen=True, repr=False)
class GlobalSearch:
    """The best distinct poses of a global search, best first (see the module docstring).

    ``poses`` (K,3): tx, ty (m), yaw (rad, [-pi, pi)) in the reduced frames,
    ``x_target = R(yaw) x_source + t``; ``scores`` (K,): summed field values / 255 (a point on a
    target pixel counts 1); ``indices`` (K,3) int64: yaw index, lattice i, j; ``ratio``: second
    score over the best (0 with fewer than two), the ambiguity; ``nodes``: bounds computed."""

    poses: np.ndarray
    scores: np.ndarray
    indices: np.ndarray
    ratio: float
    nodes: int
    time_s: float
    n_points: int  # thinned source points
    n_yaws: int
    yaw_step: float  # rad
    resolution: float  # m

    def __repr__(self) -> str:
        head = f"GlobalSearch({len(self.poses)} candidates"
        if len(self.poses):
            tx, ty, yaw = self.poses[0]
            head += (
                f", best=(tx={tx:.2f} m, ty={ty:.2f} m, yaw={np.degrees(yaw):.2f} deg)"
                f", score={self.scores[0]:.1f}/{self.n_points} points"
            )
        return (
            f"{head}, ratio={self.ratio:.3f}, nodes={self.nodes:,}, yaws={self.n_yaws}"
            f" x {np.degrees(self.yaw_step):.3f} deg, pixel={self.resolution:g} m"
            f", {self.time_s:.3f} s)"
        )


def search_field(
    field: ScoreField,
    source_slices: Sequence[np.ndarray],
    *,
    window: float = 50.0,
    yaw_step: float | None = None,
    candidates: int = 4,
    exclusion: float = 8.0,
    exclusion_yaw: float = np.radians(10.0),
    kernels: SearchKernels = bnb_kernels.NUMBA,
) -> GlobalSearch:
    """The ``candidates`` best distinct poses of the source slices (reduced source frame, m) on
    a target's ``field``: translations within +-``window`` m (per axis) of the pose that puts
    the source centre on the target centre, every yaw at ``yaw_step`` rad (None: one pixel at
    the farthest thinned point). ``exclusion`` (m) and ``exclusion_yaw`` (rad) define distinct."""
    if window < 0 or candidates < 1 or (yaw_step is not None and yaw_step <= 0):
        raise ValueError("need window >= 0, candidates >= 1 and yaw_step > 0 (or None)")
    t0 = time.perf_counter()
    grid = search_grid(field, source_slices, window=window, yaw_step=yaw_step)
    lat, bases = lattice(field, grid, exclusion, exclusion_yaw)
    leaves, nodes = _branch_and_bound(lat, bases, candidates, kernels)
    picks = distinct_picks(leaves, candidates, lat.n_yaw, lat.r2_sep // 4, lat.yaw_sep // 2)
    scores = picks[:, 0] / FIELD_MAX
    ratio = float(scores[1] / scores[0]) if len(scores) > 1 else 0.0
    return GlobalSearch(
        grid.poses(picks[:, 1:]),
        scores,
        picks[:, 1:].copy(),
        ratio,
        nodes,
        time.perf_counter() - t0,
        len(grid.points),
        grid.n_yaw,
        grid.yaw_step,
        grid.resolution,
    )


def global_search(
    target_slices: Sequence[np.ndarray],
    source_slices: Sequence[np.ndarray],
    *,
    resolution: float = 1.0,
    window: float = 50.0,
    yaw_step: float | None = None,
    candidates: int = 4,
    exclusion: float = 8.0,
    exclusion_yaw: float = np.radians(10.0),
    sigma_px: float = 1.0,
    kernels: SearchKernels = bnb_kernels.NUMBA,
) -> GlobalSearch:
    """:func:`search_field` on the :func:`likelihood_field` of the target slices (reduced target
    frame, m) at ``resolution`` m; the time includes building the field."""
    t0 = time.perf_counter()
    field = likelihood_field(target_slices, resolution=resolution, sigma_px=sigma_px)
    found = search_field(
        field,
        source_slices,
        window=window,
        yaw_step=yaw_step,
        candidates=candidates,
        exclusion=exclusion,
        exclusion_yaw=exclusion_yaw,
        kernels=kernels,
    )
    return replace(found, time_s=time.perf_counter() - t0)
