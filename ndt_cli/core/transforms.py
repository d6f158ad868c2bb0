"""Rigid transforms: 4x4 homogeneous matrices (float64) and the planar pose (tx, ty, yaw).

Naming follows ``T_a_b``: the matrix maps points from frame b into frame a, ``p_a = T_a_b @ p_b``.
"""

from __future__ import annotations

import numpy as np


def pose2d_matrix(tx: float, ty: float, yaw: float, tz: float = 0.0) -> np.ndarray:
    """4x4 of a rotation by ``yaw`` (radians) about z followed by a translation (metres)."""
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = tx, ty, tz
    return T


def translation(v: np.ndarray) -> np.ndarray:
    """4x4 pure translation by the 3-vector ``v`` (metres)."""
    T = np.eye(4)
    T[:3, 3] = v
    return T


def yaw_of(T: np.ndarray) -> float:
    """Heading (radians) of the rotation part of ``T``: angle of its x axis in the xy plane."""
    return float(np.arctan2(T[1, 0], T[0, 0]))


def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Angle(s) wrapped into [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle (degrees) of a 3x3 rotation matrix (geodesic distance to the identity)."""
    c = (np.trace(R[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def transform_errors(T_est: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """Rotation error (degrees) and translation error (metres) of ``T_est`` against ``T_ref``."""
    D = np.linalg.inv(T_ref) @ T_est
    return rotation_angle_deg(D), float(np.linalg.norm(T_est[:3, 3] - T_ref[:3, 3]))


def apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply the 4x4 ``T`` to (N,3) points."""
    return points @ T[:3, :3].T + T[:3, 3]


def quaternions(R: np.ndarray) -> np.ndarray:
    """(N,4) unit quaternions (w, x, y, z), w >= 0, of (N,3,3) rotation matrices, from the
    largest of the four diagonal forms (Shepperd's method: accurate at every angle, up to and
    at 180 degrees)."""
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    d = np.stack([R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2], R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], 1)
    case = np.argmax(d, axis=1)
    q = np.empty((len(R), 4))
    s0, s1, s2 = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    p0, p1, p2 = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
    tr = d[:, 0]
    forms = [
        (1.0 + tr, (s0, s1, s2), 0),
        (1.0 + 2 * d[:, 1] - tr, (s0, p0, p1), 1),
        (1.0 + 2 * d[:, 2] - tr, (s1, p0, p2), 2),
        (1.0 + 2 * d[:, 3] - tr, (s2, p1, p2), 3),
    ]
    for k, (big, others, slot) in enumerate(forms):
        m = case == k
        if not m.any():
            continue
        root = np.sqrt(np.maximum(big[m], 0.0))  # 4 q[slot]^2 = big
        rest = [i for i in range(4) if i != slot]
        q[m, slot] = 0.5 * root
        for i, value in zip(rest, others, strict=True):
            q[m, i] = 0.5 * value[m] / root
    q *= np.where(q[:, 0] < 0, -1.0, 1.0)[:, None]
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z), w >= 0, of a 3x3 rotation matrix."""
    return quaternions(R)[0]


def rotation_from_vector(v: np.ndarray) -> np.ndarray:
    """3x3 rotation of the rotation vector ``v`` (axis times angle, rad): Rodrigues' formula,
    with ``1 - cos t`` as ``2 sin^2(t/2)`` so that small angles keep their precision."""
    v = np.asarray(v, dtype=float)
    t = float(np.sqrt(v @ v))
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    if t < 1e-12:  # the series to second order is exact in double precision here
        return np.eye(3) + K + 0.5 * (K @ K)
    h = np.sin(0.5 * t) / t
    return np.eye(3) + (np.sin(t) / t) * K + (2.0 * h * h) * (K @ K)


def levelling_rotation(a: float, b: float) -> np.ndarray:
    """3x3 rotation that turns the plane ``z = a x + b y`` horizontal (its normal onto +z),
    without a turn about z."""
    n = np.array([-a, -b, 1.0]) / np.sqrt(a * a + b * b + 1.0)
    axis = np.cross(n, [0.0, 0.0, 1.0])
    s, c = np.linalg.norm(axis), n[2]
    if s < 1e-15:
        return np.eye(3)
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K


def rotation4(R: np.ndarray) -> np.ndarray:
    """4x4 of a 3x3 rotation."""
    T = np.eye(4)
    T[:3, :3] = R
    return T
