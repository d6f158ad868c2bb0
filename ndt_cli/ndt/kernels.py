"""NDT scoring kernels (Numba) and their plain-numpy twins.

The objective for a batch of planar poses ``p = (tx, ty, phi)`` (metres, radians) that map source
slice points into the target frame, ``x' = R(phi) x + t``, is

    f(p) = - sum_slices sum_points sum_grids exp(-1/2 d^T Sigma^-1 d),   d = x' - q,

with ``q``, ``Sigma`` the normal distribution of the target cell that ``x'`` falls in (no cell:
no term). One call returns, per pose, the accumulators listed below: score, gradient and Hessian
of ``f`` (Newton), and ``J^T J``, ``J^T r`` and ``E = 1/2 sum r^2`` of the residuals
``r = 1 - s`` per point and grid (Levenberg-Marquardt), and the number of matched points.

Sums are taken per fixed chunk of points and then added in a fixed order, so results are
bit-identical whatever the number of threads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ndt_cli.core.threads import parallel_for
from ndt_cli.ndt.grid import NDTMap

# accumulator columns
SCORE = 0
GRAD = slice(1, 4)  # gradient of f = -score
HESS = slice(4, 10)  # Hessian of f: xx, xy, xp, yy, yp, pp
JTJ = slice(10, 16)  # J^T J of the residuals, same order
JTR = slice(16, 19)  # J^T r (gradient of E)
ERR = 19  # E = 1/2 sum (1 - s)^2 over all (point, grid) pairs
MATCHED = 20  # (point, grid) pairs that fell into a cell
NACC = 21
CHUNK = 2048  # points per reduction chunk (fixed: determines the summation order)

_SYM = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])


@dataclass(frozen=True)
class SourcePoints:
    """Source slice points flattened for the kernels: ``xy`` (N,2) metres, ``slice_id`` (N,)."""

    xy: np.ndarray
    slice_id: np.ndarray

    @classmethod
    def from_slices(cls, slices: list[np.ndarray]) -> SourcePoints:
        xy = np.ascontiguousarray(np.concatenate([s.reshape(-1, 2) for s in slices]), np.float64)
        sid = np.concatenate([np.full(len(s), k, np.int32) for k, s in enumerate(slices)])
        return cls(xy, sid.astype(np.int32))

    def __len__(self) -> int:
        return len(self.xy)

    def per_slice(self, n_slices: int) -> np.ndarray:
        """Number of points in each slice."""
        return np.bincount(self.slice_id, minlength=n_slices)


def sym3(v: np.ndarray) -> np.ndarray:
    """(..., 6) upper-triangle rows (xx, xy, xp, yy, yp, pp) to (..., 3, 3) symmetric matrices."""
    return v[..., _SYM]


@numba.njit(cache=True, inline="always")
def _find_cell(xp, yp, g, grid, inv_cell):  # pragma: no cover - compiled
    """Row of the cell of grid ``g`` that holds (xp, yp), or -1 (outside or too few points)."""
    origin, shape, offset, _, cell_index, _, _ = grid
    fx = (xp - origin[g, 0]) * inv_cell
    fy = (yp - origin[g, 1]) * inv_cell
    if fx < 0.0 or fy < 0.0:
        return -1
    ix = int(fx)
    iy = int(fy)
    if ix >= shape[g, 0] or iy >= shape[g, 1]:
        return -1
    return cell_index[offset[g] + ix * shape[g, 1] + iy]


@numba.njit(cache=True, inline="always")
def _pair(xp, yp, ci, grid):  # pragma: no cover - compiled
    """Offset (dx, dy) of a point from its cell's mean, and the cell's inverse covariance."""
    means, icov = grid[5], grid[6]
    return xp - means[ci, 0], yp - means[ci, 1], icov[ci, 0], icov[ci, 1], icov[ci, 2]


@numba.njit(cache=True, nogil=True)
def _accumulate(start, stop, params, xy, sid, grid, cell_size, chunk, lm, out):  # pragma: no cover
    """Tasks ``start .. stop-1`` of ``poses x chunks``: each fills its own row of ``out``."""
    slice_grids = grid[3]
    n, n_chunks, inv_cell = xy.shape[0], out.shape[1], 1.0 / cell_size
    for task in range(start, stop):
        st = task // n_chunks
        c = task - st * n_chunks
        tx, ty = params[st, 0], params[st, 1]
        co, si = np.cos(params[st, 2]), np.sin(params[st, 2])
        score = g0 = g1 = g2 = h00 = h01 = h02 = h11 = h12 = h22 = 0.0
        j00 = j01 = j02 = j11 = j12 = j22 = r0 = r1 = r2 = err = matched = 0.0
        for i in range(c * chunk, min(n, (c + 1) * chunk)):
            x, y = xy[i, 0], xy[i, 1]
            xp = co * x - si * y + tx
            yp = si * x + co * y + ty
            jx = -si * x - co * y  # d x'/d phi
            jy = co * x - si * y
            k = sid[i]
            for g in range(slice_grids[k], slice_grids[k + 1]):
                ci = _find_cell(xp, yp, g, grid, inv_cell)
                if ci < 0:
                    if lm:
                        err += 0.5
                    continue
                dx, dy, a, b, cc = _pair(xp, yp, ci, grid)
                u0 = a * dx + b * dy  # Sigma^-1 d
                u1 = b * dx + cc * dy
                e = np.exp(-0.5 * (dx * u0 + dy * u1))
                u2 = u0 * jx + u1 * jy
                ajx = a * jx + b * jy
                ajy = b * jx + cc * jy
                score += e
                g0 += e * u0
                g1 += e * u1
                g2 += e * u2
                h00 += e * (a - u0 * u0)
                h01 += e * (b - u0 * u1)
                h02 += e * (ajx - u0 * u2)
                h11 += e * (cc - u1 * u1)
                h12 += e * (ajy - u1 * u2)
                h22 += e * (jx * ajx + jy * ajy - u0 * jy + u1 * jx - u2 * u2)
                matched += 1.0
                if not lm:  # Newton needs score, gradient and Hessian only
                    continue
                e2 = e * e
                j00 += e2 * u0 * u0
                j01 += e2 * u0 * u1
                j02 += e2 * u0 * u2
                j11 += e2 * u1 * u1
                j12 += e2 * u1 * u2
                j22 += e2 * u2 * u2
                w = e * (1.0 - e)
                r0 += w * u0
                r1 += w * u1
                r2 += w * u2
                err += 0.5 * (1.0 - e) * (1.0 - e)
        newton = (score, g0, g1, g2, h00, h01, h02, h11, h12, h22)
        rest = (j00, j01, j02, j11, j12, j22, r0, r1, r2, err, matched)
        for q in range(10):
            out[st, c, q] = newton[q]
        for q in range(11):
            out[st, c, 10 + q] = rest[q]


@numba.njit(cache=True, nogil=True)
def _point_scores(start, stop, p, xy, sid, grid, cell_size, s_out, j_out):  # pragma: no cover
    """Points ``start .. stop-1``: each fills its own row of ``s_out`` and ``j_out``."""
    slice_grids = grid[3]
    inv_cell = 1.0 / cell_size
    co, si = np.cos(p[2]), np.sin(p[2])
    for i in range(start, stop):
        x, y = xy[i, 0], xy[i, 1]
        xp = co * x - si * y + p[0]
        yp = si * x + co * y + p[1]
        jx = -si * x - co * y
        jy = co * x - si * y
        s = d0 = d1 = d2 = 0.0
        k = sid[i]
        for g in range(slice_grids[k], slice_grids[k + 1]):
            ci = _find_cell(xp, yp, g, grid, inv_cell)
            if ci < 0:
                continue
            dx, dy, a, b, cc = _pair(xp, yp, ci, grid)
            u0 = a * dx + b * dy
            u1 = b * dx + cc * dy
            e = np.exp(-0.5 * (dx * u0 + dy * u1))
            s += e
            d0 -= e * u0
            d1 -= e * u1
            d2 -= e * (u0 * jx + u1 * jy)
        s_out[i] = s
        j_out[i, 0] = d0
        j_out[i, 1] = d1
        j_out[i, 2] = d2


def _map_args(m: NDTMap) -> tuple:
    """The map's arrays as the kernels take them, and its cell size."""
    grid = (
        m.grid_origin,
        m.grid_shape,
        m.grid_offset,
        m.slice_grids,
        m.cell_index,
        m.means,
        m.icov,
    )
    return grid, m.cell_size


def accumulate(
    ndt_map: NDTMap, src: SourcePoints, params: np.ndarray, lm: bool = True
) -> np.ndarray:
    """Accumulators (S, NACC) for the S poses in ``params`` (S,3): see the module docstring.
    ``lm=False`` leaves the Levenberg-Marquardt columns (JTJ, JTR, ERR) at zero and is faster."""
    params = np.ascontiguousarray(np.atleast_2d(params), dtype=np.float64)
    n_chunks = max(1, -(-len(src) // CHUNK))
    out = np.zeros((params.shape[0], n_chunks, NACC))
    if len(src) and params.shape[0]:
        tasks = params.shape[0] * n_chunks
        args = (params, src.xy, src.slice_id, *_map_args(ndt_map), CHUNK, lm, out)
        parallel_for(_accumulate, tasks, *args)
    return out.sum(axis=1)


def point_scores(
    ndt_map: NDTMap, src: SourcePoints, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per point: score ``s`` (N,) summed over its slice's grids, and its Jacobian ds/dp (N,3)."""
    p = np.ascontiguousarray(p, dtype=np.float64).reshape(3)
    s = np.zeros(len(src))
    J = np.zeros((len(src), 3))
    if len(src):
        parallel_for(_point_scores, len(src), p, src.xy, src.slice_id, *_map_args(ndt_map), s, J)
    return s, J


# ----------------------------------------------------------------------------- numpy twins


def _lookup_numpy(m: NDTMap, xp: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Cell row for each transformed point in grid ``g`` (per point), -1 when outside / empty."""
    f = (xp - m.grid_origin[g]) / m.cell_size
    ij = np.floor(f).astype(np.int64)
    nx, ny = m.grid_shape[g, 0], m.grid_shape[g, 1]
    inside = (f[:, 0] >= 0) & (f[:, 1] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] < ny)
    ci = np.full(len(xp), -1, dtype=np.int64)
    ci[inside] = m.cell_index[m.grid_offset[g[inside]] + ij[inside, 0] * ny[inside] + ij[inside, 1]]
    return ci


def _terms_numpy(m: NDTMap, src: SourcePoints, p: np.ndarray):
    """Per (point, grid) pair: matched mask, score e, u = d/dp of the exponent / -1, A J, J."""
    c, s = np.cos(p[2]), np.sin(p[2])
    x, y = src.xy[:, 0], src.xy[:, 1]
    xp = np.column_stack([c * x - s * y + p[0], s * x + c * y + p[1]])
    jphi = np.column_stack([-s * x - c * y, c * x - s * y])
    per_slice = np.diff(m.slice_grids)[src.slice_id]
    for r in range(int(per_slice.max(initial=0))):
        use = per_slice > r
        g = m.slice_grids[src.slice_id[use]] + r
        ci = _lookup_numpy(m, xp[use], g)
        yield use, ci, xp[use], jphi[use]


def accumulate_numpy(
    ndt_map: NDTMap, src: SourcePoints, params: np.ndarray, lm: bool = True
) -> np.ndarray:
    """Plain-numpy twin of :func:`accumulate` (slow: a reference and a fallback)."""
    params = np.atleast_2d(params)
    out = np.zeros((len(params), NACC))
    total_pairs = int(np.diff(ndt_map.slice_grids)[src.slice_id].sum())
    for k, p in enumerate(params):
        acc = out[k]
        matched = 0
        for _use, ci, xp, jphi in _terms_numpy(ndt_map, src, p):
            ok = ci >= 0
            ci, xp, jphi = ci[ok], xp[ok], jphi[ok]
            d = xp - ndt_map.means[ci]
            A = rows_to_2x2(ndt_map.icov[ci])
            u = np.einsum("nij,nj->ni", A, d)
            e = np.exp(-0.5 * np.einsum("ni,ni->n", d, u))
            U = np.column_stack([u, np.einsum("ni,ni->n", u, jphi)])
            J = np.zeros((len(ci), 2, 3))
            J[:, 0, 0] = 1.0
            J[:, 1, 1] = 1.0
            J[:, :, 2] = jphi
            JAJ = np.einsum("nki,nkl,nlj->nij", J, A, J)
            JAJ[:, 2, 2] += u[:, 0] * -jphi[:, 1] + u[:, 1] * jphi[:, 0]  # d^T A d2x'/dphi2
            H = np.einsum("n,nij->ij", e, JAJ - U[:, :, None] * U[:, None, :])
            JtJ = np.einsum("n,ni,nj->ij", e**2, U, U)
            acc[SCORE] += e.sum()
            acc[GRAD] += (e[:, None] * U).sum(axis=0)
            acc[HESS] += H[np.triu_indices(3)]
            acc[JTJ] += JtJ[np.triu_indices(3)]
            acc[JTR] += ((e * (1 - e))[:, None] * U).sum(axis=0)
            acc[ERR] += 0.5 * ((1 - e) ** 2).sum()
            matched += len(ci)
        acc[ERR] += 0.5 * (total_pairs - matched)
        acc[MATCHED] = matched
    if not lm:
        out[:, JTJ] = out[:, JTR] = out[:, ERR] = 0.0
    return out


def point_scores_numpy(
    ndt_map: NDTMap, src: SourcePoints, p: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Plain-numpy twin of :func:`point_scores`."""
    p = np.asarray(p, dtype=np.float64)
    s = np.zeros(len(src))
    Js = np.zeros((len(src), 3))
    for use, ci, xp, jphi in _terms_numpy(ndt_map, src, p):
        ok = ci >= 0
        idx = np.flatnonzero(use)[ok]
        d = xp[ok] - ndt_map.means[ci[ok]]
        u = np.einsum("nij,nj->ni", rows_to_2x2(ndt_map.icov[ci[ok]]), d)
        e = np.exp(-0.5 * np.einsum("ni,ni->n", d, u))
        np.add.at(s, idx, e)
        np.add.at(Js, idx, -e[:, None] * np.column_stack([u, np.einsum("ni,ni->n", u, jphi[ok])]))
    return s, Js


def rows_to_2x2(rows: np.ndarray) -> np.ndarray:
    """(M,3) rows (a, b, c) to (M,2,2) matrices [[a, b], [b, c]]."""
    return np.stack([rows[:, [0, 1]], rows[:, [1, 2]]], axis=1)
