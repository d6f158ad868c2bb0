"""Marginal covariances of an adjusted network that never fail: GTSAM's ``Marginals`` when the
system is determined; when it is not (a corridor whose links leave the position along it free,
scans tied only by links that fix their rotation and height), the pseudo-inverse of the
information matrix, with a variance of :data:`UNDETERMINED_VAR` along every direction the links
leave free. A scan free along some direction then reads as not pinned down, with that
direction, instead of the adjustment raising."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

UNDETERMINED_VAR = 1e12  # m^2 or rad^2 along a direction no link determines: sigma 1e6
_NULL_RTOL = 1e-12  # eigenvalues of the information below this share of the largest: free
_DIM = 6  # a Pose3's tangent: rotation (rad) then translation (m), as GTSAM orders it


def marginal_covariances(
    gtsam: object, graph: object, values: object, keys: Iterable[int]
) -> dict[int, np.ndarray]:
    """The 6x6 covariance (GTSAM's tangent order, body frame) of each node ``keys`` of the
    solved ``graph`` at ``values``."""
    keys = list(keys)
    try:
        marginals = gtsam.Marginals(graph, values)
    except RuntimeError:  # an indeterminate system: some direction is free
        return _pseudo_inverse(gtsam, graph, values, keys)
    return {k: np.asarray(marginals.marginalCovariance(k)) for k in keys}


def _pseudo_inverse(
    gtsam: object, graph: object, values: object, keys: list[int]
) -> dict[int, np.ndarray]:
    """The covariances from the dense information matrix of every node in ``values``."""
    every = [int(k) for k in values.keys()]  # noqa: SIM118 (GTSAM's Values: no iteration)
    ordering = gtsam.Ordering()
    for k in every:
        ordering.push_back(k)
    information = np.asarray(graph.linearize(values).hessian(ordering)[0])
    return {k: block for k, block in zip(every, _blocks(information), strict=True) if k in keys}


def _blocks(information: np.ndarray) -> list[np.ndarray]:
    """The 6x6 diagonal blocks of the pseudo-inverse of a symmetric ``information`` matrix,
    plus :data:`UNDETERMINED_VAR` times the projection onto its null space.

    Decomposed with unit diagonal (Jacobi scaling): unscaled, the anchor's prior (1e12) and
    radians beside metres made a long corridor's weakest determined directions (a thousand
    scans: eigenvalues near 1e-4) fall within the decomposition's rounding of the largest,
    and every scan read as undetermined by hundreds of metres."""
    H = (information + information.T) / 2.0
    d = np.sqrt(np.clip(np.diag(H), 0.0, None))
    d[d == 0.0] = 1.0  # a direction no factor touches: free, left as it is
    w, V = np.linalg.eigh(H / np.outer(d, d))
    free = w <= _NULL_RTOL * max(float(w.max()), 1e-300)
    Vd = V[:, ~free] / d[:, None]  # back to the information's own units
    null, _ = np.linalg.qr(V[:, free] / d[:, None])  # the null space of H, orthonormal
    out = []
    for i in range(0, len(w), _DIM):
        rows = slice(i, i + _DIM)
        cov = (Vd[rows] / w[~free]) @ Vd[rows].T + UNDETERMINED_VAR * null[rows] @ null[rows].T
        out.append(cov)
    return out
