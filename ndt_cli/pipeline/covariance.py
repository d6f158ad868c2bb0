"""Covariance of a registration link, in GTSAM's ``Pose3`` tangent convention (pure numpy).

Conventions (used by :mod:`ndt_cli.pipeline.adjust` too):

- A link measures ``T_target_source`` (4x4): it maps points of the source node ``j`` into the
  target node ``i``, ``p_i = T_ij @ p_j``. Node frames are the scans' *reduced* frames (each scan
  minus its reduction point, not levelled), so coordinates stay small.
- Its covariance is 6x6 over the tangent vector ``xi = (omega [rad], nu [m])``, rotation first,
  with the RIGHT perturbation ``T_ij' = T_ij @ Exp(xi)``: ``xi`` lives in the body frame of the
  source node ``j``. This is what ``gtsam.BetweenFactorPose3`` expects.
- Registration back-ends report their information with a LEFT perturbation about a centre
  point: ``p' = c + R(w) (p - c) + v`` for points already in a frame ``g`` (the ICP: the target's
  reduced frame, ``c`` the centroid of the matched points; the planar NDT: the target's levelled
  frame, ``c`` the source origin). With ``G`` the pose of that perturbation frame in the target
  node's frame (origin at ``c``), the first-order map is ``xi = Ad(inv(T_ij) @ G) @ (w, v)``
  (:func:`left_to_right_jacobian`).

Nothing here needs GTSAM.
"""

from __future__ import annotations

import numpy as np

from ndt_cli.core.transforms import quaternions, rotation4, translation

DEFAULT_INFLATION = 3.0  # ICP: factor on the inlier RMS (correlated points, model errors)
DEFAULT_FLOOR_ROTATION_DEG = 0.005  # systematic rotation error floor (1 sigma), degrees
DEFAULT_FLOOR_TRANSLATION = 0.003  # systematic translation error floor (1 sigma), metres
DEFAULT_MAX_SIGMA = 1.0e3  # sigma of an unconstrained direction (m or rad): "unknown"
DEFAULT_NDT_SCALE = 2.0  # NDT: factor on the sigmas of inv(Hessian of -score)
DEFAULT_SIGMA_Z = 0.1  # NDT: sigma of the height (ground levels), metres
DEFAULT_SIGMA_TILT_DEG = 0.1  # NDT: sigma of roll and pitch (levelling), degrees


def skew(v: np.ndarray) -> np.ndarray:
    """3x3 cross-product matrix: ``skew(a) @ b == np.cross(a, b)``."""
    x, y, z = np.asarray(v, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def adjoint(T: np.ndarray) -> np.ndarray:
    """6x6 adjoint of a 4x4 rigid transform in (rotation, translation) order:
    ``T @ Exp(xi) @ inv(T) == Exp(adjoint(T) @ xi)`` (GTSAM's ``Pose3.AdjointMap``)."""
    R, t = T[:3, :3], T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[3:, 3:] = R
    A[3:, :3] = skew(t) @ R
    return A


def left_to_right_jacobian(T_target_source: np.ndarray, G_target_frame: np.ndarray) -> np.ndarray:
    """6x6 ``J`` with ``xi_right = J @ (w, v)``, to first order.

    ``(w [rad], v [m])`` perturbs ``T_target_source`` on the left in the frame ``G`` (pose of
    that frame in the target's frame; its origin is the rotation centre):
    ``T' = G @ dT(w, v) @ inv(G) @ T``. ``xi_right`` is the right perturbation,
    ``T' = T @ Exp(xi_right)``, in the source's body frame.
    """
    return adjoint(np.linalg.inv(T_target_source) @ G_target_frame)


def inverse_information(
    information: np.ndarray, scale: float = 1.0, max_sigma: float = DEFAULT_MAX_SIGMA
) -> np.ndarray:
    """``scale**2 * inv(information)`` of a symmetric information (normal) matrix, robustly.

    Eigenvalues are floored so that no variance exceeds ``max_sigma**2``: a (near-)singular
    matrix gives variances of ``max_sigma**2`` along its weak directions instead of failing.
    Non-finite entries are treated as no information at all.
    """
    H = np.asarray(information, dtype=float)
    n = H.shape[0]
    if not np.all(np.isfinite(H)):
        return np.eye(n) * max_sigma**2
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    lam = np.maximum(lam, scale**2 / max_sigma**2)
    cov = (V / lam) @ V.T * scale**2
    return 0.5 * (cov + cov.T)


def floor_covariance(rotation_deg: float, translation_m: float) -> np.ndarray:
    """Diagonal 6x6 covariance: isotropic rotation (degrees, 1 sigma) and translation (m)."""
    r = np.radians(rotation_deg) ** 2
    return np.diag([r, r, r, translation_m**2, translation_m**2, translation_m**2])


def propagate_left(
    cov_left: np.ndarray, T_target_source: np.ndarray, G_target_frame: np.ndarray
) -> np.ndarray:
    """Covariance of a left perturbation in frame ``G`` (see :func:`left_to_right_jacobian`)
    as a right-perturbation covariance of ``T_target_source`` (source body frame)."""
    J = left_to_right_jacobian(T_target_source, G_target_frame)
    cov = J @ cov_left @ J.T
    return 0.5 * (cov + cov.T)


def icp_covariance(
    hessian: np.ndarray,
    centre: np.ndarray,
    T_target_source: np.ndarray,
    rms: float,
    *,
    inflation: float = DEFAULT_INFLATION,
    floor_rotation_deg: float = DEFAULT_FLOOR_ROTATION_DEG,
    floor_translation: float = DEFAULT_FLOOR_TRANSLATION,
    max_sigma: float = DEFAULT_MAX_SIGMA,
) -> np.ndarray:
    """6x6 right-perturbation covariance of an ICP link (GTSAM ``Pose3`` tangent, source body).

    ``hessian``: ICP's 6x6 normal matrix ``J^T W J`` of the point-to-plane residuals (rotation
    vector [rad] then translation [m], axes of the target's reduced frame, left perturbation
    about ``centre``, the centroid of the matched points in that frame [m]).
    ``T_target_source``: the ICP result between the reduced frames. ``rms``: inlier RMS [m].

    ``Sigma_x = (inflation * rms)**2 * inv(hessian)``: ``inflation`` accounts for the points'
    correlation (neighbours share normals and scanner errors) and for model error, which the
    textbook ``rms**2 * inv(H)`` ignores: on the five correct links of ``sample_data`` (next
    and second-next scans) the true errors were 1.4-2.9 times its sigmas (about 1 mm,
    0.003 deg), hence 3. The floor (``floor_rotation_deg`` [deg], ``floor_translation`` [m],
    1 sigma, isotropic about the centre) stands for systematic errors (levelling, the ICP's
    voxel bias) that no number of points averages away. A weak direction of a
    (near-)singular ``hessian`` gets ``max_sigma**2``. ``rms`` below 1 micrometre counts as
    1 micrometre. Raises ValueError for a non-finite ``rms`` (no ICP).
    """
    if not np.isfinite(rms):
        raise ValueError("icp_covariance needs a finite ICP RMS (was the link refined by ICP?)")
    scale = max(float(rms), 1e-6) * inflation
    cov = inverse_information(hessian, scale, max_sigma)
    cov = cov + floor_covariance(floor_rotation_deg, floor_translation)
    return propagate_left(cov, T_target_source, translation(np.asarray(centre, dtype=float)))


def ndt_covariance(
    hessian: np.ndarray,
    T_target_source: np.ndarray,
    *,
    level_target: np.ndarray | None = None,
    level_source: np.ndarray | None = None,
    scale: float = DEFAULT_NDT_SCALE,
    sigma_z: float = DEFAULT_SIGMA_Z,
    sigma_tilt_deg: float = DEFAULT_SIGMA_TILT_DEG,
    floor_rotation_deg: float = DEFAULT_FLOOR_ROTATION_DEG,
    floor_translation: float = DEFAULT_FLOOR_TRANSLATION,
    max_sigma: float = DEFAULT_MAX_SIGMA,
) -> np.ndarray:
    """6x6 right-perturbation covariance of a planar NDT link (GTSAM ``Pose3`` tangent).

    ``hessian``: 3x3 Hessian of ``-score`` in (tx [m], ty [m], yaw [rad]) of the planar pose
    ``P = pose2d(tx, ty, yaw)`` that maps the source's levelled reduced frame into the
    target's (``RegistrationResult.hessian``). ``T_target_source``: the link between the
    (not levelled) reduced frames, ``rot4(L_t.T) @ P @ rot4(L_s)``; ``level_target`` /
    ``level_source``: the 3x3 levelling rotations ``L`` (reduced axes -> levelled axes,
    ``PreparedScan.level``; identity when None).

    A step in (tx, ty, yaw) moves ``P`` by a yaw about the source origin ``c = P[:3, 3]`` and a
    shift, both in the levelled target frame; its covariance is ``scale**2 * inv(hessian)``
    (on the sample links the true planar errors were 0.7-2.0 times its sigmas, hence 2).
    NDT sees no height, roll or pitch (they come from the ground and levelling of each scan):
    they get the generous ``sigma_z`` [m] and ``sigma_tilt_deg`` [deg] about ``c``. The floor
    is added as in :func:`icp_covariance`.
    """
    L_t = np.eye(3) if level_target is None else np.asarray(level_target, dtype=float)
    L_s = np.eye(3) if level_source is None else np.asarray(level_source, dtype=float)
    P = rotation4(L_t) @ T_target_source @ rotation4(L_s.T)
    planar = inverse_information(hessian, scale, max_sigma)
    cov = np.zeros((6, 6))
    idx = [3, 4, 2]  # tx -> v_x, ty -> v_y, yaw -> w_z
    cov[np.ix_(idx, idx)] = planar
    cov[0, 0] = cov[1, 1] = np.radians(sigma_tilt_deg) ** 2
    cov[5, 5] = sigma_z**2
    cov = cov + floor_covariance(floor_rotation_deg, floor_translation)
    G = rotation4(L_t.T) @ translation(P[:3, 3])  # levelled axes, origin at c; target frame
    return propagate_left(cov, T_target_source, G)


def sqrt_information(covariance: np.ndarray) -> np.ndarray:
    """6x6 ``R`` with ``R.T @ R == inv(covariance)``: ``|R @ xi|**2`` is the chi-square of
    ``xi``. From the eigen-decomposition, so a badly conditioned covariance is no problem; the
    symmetric root ``V diag(lam**-0.5) V.T``, positive definite whatever signs the eigenvectors
    come with (a diagonal ``R`` is read as sigmas, which must be positive).
    Also for a stack (N,6,6) -> (N,6,6). Raises ValueError unless every covariance is finite,
    symmetric and positive definite."""
    C = np.asarray(covariance, dtype=float)
    if C.shape[-2:] != (6, 6) or C.ndim not in (2, 3) or not np.all(np.isfinite(C)):
        raise ValueError("a link covariance must be a finite 6x6 matrix")
    sym = 0.5 * (C + np.swapaxes(C, -1, -2))
    lam, V = np.linalg.eigh(sym)
    asym = np.abs(C - sym).max(axis=(-2, -1))
    if np.any(lam[..., 0] <= 0.0) or np.any(asym > 1e-9 * lam[..., -1]):
        raise ValueError("a link covariance must be symmetric positive definite (add a floor)")
    return (V / np.sqrt(lam)[..., None, :]) @ np.swapaxes(V, -1, -2)


def rotation_log(R: np.ndarray) -> np.ndarray:
    """(N,3) rotation vectors (rad) of (N,3,3) rotation matrices, through their unit
    quaternions (:func:`~ndt_cli.core.transforms.quaternions`: accurate at every angle, up to
    and at 180 degrees)."""
    q = quaternions(R)
    v = np.linalg.norm(q[:, 1:], axis=1)
    angle = 2.0 * np.arctan2(v, q[:, 0])
    scale = np.where(v > 1e-12, angle / np.where(v > 1e-12, v, 1.0), 2.0 / q[:, 0])
    return q[:, 1:] * scale[:, None]


def se3_log(D: np.ndarray) -> np.ndarray:
    """(N,6) tangent vectors ``Log(D)`` of (N,4,4) rigid transforms, (rotation vector [rad],
    ``inv(V(omega)) @ t`` [m]): GTSAM's ``Pose3.Logmap``, vectorised."""
    D = np.asarray(D, dtype=float).reshape(-1, 4, 4)
    w = rotation_log(D[:, :3, :3])
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    # inv(V) = I - W/2 + c W^2, c = (1 - th sin th / (2 (1 - cos th))) / th^2 (1/12 near 0)
    c = np.where(small, 1.0 / 12.0, (1.0 - th * np.sin(th) / (2.0 * (1.0 - np.cos(th)))) / th**2)
    t = D[:, :3, 3]
    wt = np.cross(w, t)
    u = t - 0.5 * wt + c[:, None] * np.cross(w, wt)
    return np.column_stack([w, u])


def relative_covariance(
    T_world_i: np.ndarray, T_world_j: np.ndarray, joint: np.ndarray
) -> np.ndarray:
    """6x6 covariance of ``inv(T_world_i) @ T_world_j`` (right perturbation, frame j) from the
    12x12 joint covariance of both poses (each a right perturbation, blocks in order i, j)."""
    rel = np.linalg.inv(T_world_i) @ T_world_j
    A = np.hstack([-adjoint(np.linalg.inv(rel)), np.eye(6)])
    cov = A @ joint @ A.T
    return 0.5 * (cov + cov.T)
