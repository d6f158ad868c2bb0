"""Link covariances (against Monte-Carlo and finite differences), the global adjustment and the
verification of links, on simulated streets whose links carry noise of known covariance."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ndt_cli.core.transforms import pose2d_matrix, rotation4, translation
from ndt_cli.pipeline.adjust import Adjustment, adjust
from ndt_cli.pipeline.covariance import (
    icp_covariance,
    left_to_right_jacobian,
    ndt_covariance,
    relative_covariance,
    rotation_log,
    se3_log,
    sqrt_information,
)
from ndt_cli.pipeline.graph import Edge, bridges, components, uncheckable
from ndt_cli.pipeline.verify import EdgeState, NodeStatus, _node_verdicts, verify

N_MC = 20_000


def rot(rotvec) -> np.ndarray:
    """3x3 rotation(s) of rotation vector(s) (radians)."""
    return Rotation.from_rotvec(rotvec).as_matrix()


def hom(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N,4,4) rigid transforms from (N,3,3) rotations and (N,3) translations."""
    T = np.zeros((len(R), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, t, 1.0
    return T


def log_right(T: np.ndarray, T_perturbed: np.ndarray) -> np.ndarray:
    """Reference right-perturbation tangents ``Log(inv(T) @ T')`` of (N,4,4) or 4x4 ``T'``:
    rotation vector, then the translation of the difference (the SE(3) log to first order)."""
    D = np.linalg.inv(T) @ np.asarray(T_perturbed).reshape(-1, 4, 4)
    return np.column_stack([Rotation.from_matrix(D[:, :3, :3]).as_rotvec(), D[:, :3, 3]])


def assert_covariance_close(samples: np.ndarray, expected: np.ndarray, tol: float = 0.05):
    """Sample covariance against ``expected``, each entry relative to sqrt(C_aa C_bb)."""
    S = np.cov(samples.T)
    d = np.sqrt(np.diag(expected))
    assert np.abs((S - expected) / np.outer(d, d)).max() < tol


def some_T(yaw: float = 0.7, t=(12.0, -4.0, 0.4)) -> np.ndarray:
    T = rotation4(rot([0.01, -0.02, yaw]))
    T[:3, 3] = t
    return T


def plane_hessian(rng: np.random.Generator, centre: np.ndarray, corridor: bool = False):
    """ICP-like normal matrix about ``centre``: points on a few planes (2 facades and the ground;
    ``corridor``: facades along x only, so a shift along x is unconstrained)."""
    normals = [[0, 1, 0], [0, 0, 1]] if corridor else [[0, 1, 0], [1, 0.3, 0], [0, 0, 1]]
    rows = []
    for n in normals:
        n = np.asarray(n, dtype=float) / np.linalg.norm(n)
        p = centre + rng.uniform(-10, 10, (300, 3))
        rows.append(
            np.column_stack([np.cross(p - centre, np.tile(n, (300, 1))), np.tile(n, (300, 1))])
        )
    J = np.vstack(rows)
    return J.T @ J


# --- covariance conversions ----------------------------------------------------------------


def test_icp_covariance_matches_monte_carlo_of_left_perturbations_about_the_centre():
    rng = np.random.default_rng(1)
    T, c = some_T(), np.array([6.0, 3.0, 2.0])  # c: centroid of the matched points, frame i
    H = plane_hessian(rng, c)
    rms = 0.01
    cov = icp_covariance(H, c, T, rms, inflation=2.0, floor_rotation_deg=0, floor_translation=0)
    x = rng.multivariate_normal(np.zeros(6), (2.0 * rms) ** 2 * np.linalg.inv(H), N_MC)
    dT = translation(c) @ hom(rot(x[:, :3]), x[:, 3:]) @ translation(-c)
    xi = log_right(T, dT @ T)  # p' = c + R(w) (p - c) + v, as ICP moves the points
    assert_covariance_close(xi, cov)
    # the conversion matters: the covariance about the centre in frame i is far from it
    assert np.abs(cov - (2.0 * rms) ** 2 * np.linalg.inv(H)).max() > 0.1 * np.abs(cov).max()


def test_left_to_right_jacobian_matches_finite_differences():
    T = some_T(yaw=2.5)
    G = rotation4(rot([0.02, 0.01, -0.4])) @ translation([3.0, -1.0, 0.5])
    h = 1e-6
    J = np.zeros((6, 6))
    for a in range(6):
        dx = np.zeros(6)
        dx[a] = h
        plus = G @ translation(dx[3:]) @ rotation4(rot(dx[:3])) @ np.linalg.inv(G) @ T
        minus = G @ translation(-dx[3:]) @ rotation4(rot(-dx[:3])) @ np.linalg.inv(G) @ T
        J[:, a] = (log_right(T, plus)[0] - log_right(T, minus)[0]) / (2 * h)
    assert np.allclose(J, left_to_right_jacobian(T, G), atol=1e-6)


def test_ndt_covariance_matches_monte_carlo_of_the_planar_parameters():
    rng = np.random.default_rng(2)
    L_t, L_s = rot([0.015, -0.01, 0.0]), rot([-0.008, 0.02, 0.0])  # reduced -> levelled axes
    p = np.array([14.0, -3.0, 0.9])  # tx, ty, yaw of the levelled pose
    P = pose2d_matrix(*p)
    T = rotation4(L_t.T) @ P @ rotation4(L_s)  # between the reduced frames
    A = rng.normal(size=(3, 3))
    H = A @ A.T * 1e4 + np.diag([2e4, 5e3, 3e7])  # -score Hessian, (m, m, rad)
    sig_z, sig_tilt = 0.05, 0.08
    cov = ndt_covariance(
        H,
        T,
        level_target=L_t,
        level_source=L_s,
        scale=1.5,
        sigma_z=sig_z,
        sigma_tilt_deg=sig_tilt,
        floor_rotation_deg=0,
        floor_translation=0,
    )
    dp = rng.multivariate_normal(np.zeros(3), 1.5**2 * np.linalg.inv(H), N_MC)
    tilt = rng.normal(0, np.radians(sig_tilt), (N_MC, 2))
    dz = rng.normal(0, sig_z, N_MC)
    yaw = p[2] + dp[:, 2]
    Pk = hom(
        rot(np.column_stack([0 * yaw, 0 * yaw, yaw])), np.column_stack([p[:2] + dp[:, :2], dz])
    )
    Pk = Pk @ hom(rot(np.column_stack([tilt, 0 * dz])), np.zeros((N_MC, 3)))  # roll, pitch
    xi = log_right(T, rotation4(L_t.T) @ Pk @ rotation4(L_s))
    assert_covariance_close(xi, cov)


def test_floors_and_a_degenerate_corridor():
    rng = np.random.default_rng(3)
    T, c = some_T(yaw=1.1), np.array([5.0, 0.0, 1.0])
    perfect = icp_covariance(plane_hessian(rng, c) * 1e12, c, T, 0.01)  # no noise left
    assert np.allclose(np.diag(perfect)[:3], np.radians(0.005) ** 2, rtol=1e-3)
    assert np.all(np.diag(perfect)[3:] >= 0.003**2 * 0.999)
    H = plane_hessian(rng, c, corridor=True)
    assert np.linalg.matrix_rank(H, tol=1e-6 * np.abs(H).max()) == 5
    cov = icp_covariance(H, c, T, 0.01)
    along = np.concatenate([np.zeros(3), T[:3, :3].T @ [1.0, 0, 0]])  # x of frame i, in j
    across = np.concatenate([np.zeros(3), T[:3, :3].T @ [0, 1.0, 0]])
    assert along @ cov @ along > 1e4  # metres squared: unknown
    assert across @ cov @ across < 1e-4
    assert np.all(np.isfinite(cov))
    sqrt_information(cov)  # still positive definite for the graph
    assert np.all(np.isfinite(icp_covariance(np.zeros((6, 6)), c, T, 0.01)))
    with pytest.raises(ValueError):
        icp_covariance(H, c, T, float("nan"))


def test_relative_covariance_matches_monte_carlo():
    rng = np.random.default_rng(4)
    Pi, Pj = some_T(yaw=0.3), some_T(yaw=-2.0, t=(40.0, 8.0, -0.5))
    A = rng.normal(size=(12, 12)) * 1e-3
    joint = A @ A.T
    x = rng.multivariate_normal(np.zeros(12), joint, N_MC)
    rel = np.linalg.inv(Pi) @ Pj

    def right(P, d):
        return P @ hom(rot(d[:, :3]), d[:, 3:])

    xi = log_right(rel, np.linalg.inv(right(Pi, x[:, :6])) @ right(Pj, x[:, 6:]))
    assert_covariance_close(xi, relative_covariance(Pi, Pj, joint))


def test_se3_log_is_gtsams_logmap():
    import gtsam

    rng = np.random.default_rng(5)
    D = [gtsam.Pose3.Expmap(rng.normal(0, s, 6)).matrix() for s in (1e-9, 1e-4, 0.3, 1.5)]
    ref = [gtsam.Pose3.Logmap(gtsam.Pose3(d)) for d in D]
    assert np.allclose(se3_log(np.array(D)), ref, atol=1e-8)


def test_rotation_log_matches_scipy_at_every_angle():
    """Against scipy's rotation vectors: random axes at angles from 0 to 180 degrees, the
    identity, and exact half turns about each axis (where only one diagonal form is stable);
    a half turn's vector is defined up to its sign."""
    rng = np.random.default_rng(11)
    axes = rng.normal(size=(400, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate(
        [[0.0, 1e-14, 1e-9], rng.uniform(0, np.pi, 394), np.pi - np.array([1e-9, 1e-6, 1e-3])]
    )
    v = axes * angles[:, None]
    got = rotation_log(rot(v))
    assert np.allclose(got, Rotation.from_matrix(rot(v)).as_rotvec(), atol=1e-9)
    assert np.allclose(got, v, atol=1e-6)
    half = np.pi * np.eye(3)
    assert np.allclose(np.abs(rotation_log(rot(half))), np.abs(half), atol=1e-12)


def test_components_match_scipys_connected_components():
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(4)
    for n, m in [(1, 0), (5, 0), (12, 6), (40, 30), (200, 180)]:
        pairs = [tuple(int(x) for x in rng.choice(n, 2)) for _ in range(m)]
        a = np.array([p[0] for p in pairs], dtype=int)
        b = np.array([p[1] for p in pairs], dtype=int)
        ref = connected_components(coo_matrix((np.ones(m), (a, b)), shape=(n, n)), directed=False)[
            1
        ]
        assert np.array_equal(components(n, pairs), ref)


def test_sqrt_information_is_a_positive_definite_root_whatever_the_eigenvectors_signs():
    """R.T @ R is the inverse covariance (checked against numpy's inverse); R is symmetric
    positive definite, so a diagonal covariance gives positive sigmas (1 / R_ii), which is
    what gtsam's noise model reads from a diagonal root (and refuses when negative). The
    diagonal one is a link's of the walk tests, whose eigenvectors some LAPACK builds return
    with negative signs."""
    d = np.array([3.05378963e-06, 3.05378963e-06, 4.00761544e-06, 4.09e-04, 4.09e-04, 1.0009e-02])
    A = np.random.default_rng(3).normal(size=(5, 6, 6))
    C = np.concatenate([A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(6), [np.diag(d)]])
    R = sqrt_information(C)
    assert np.allclose(np.swapaxes(R, 1, 2) @ R, np.linalg.inv(C), rtol=1e-9, atol=1e-12)
    assert np.allclose(R, np.swapaxes(R, 1, 2)) and np.all(np.linalg.eigvalsh(R) > 0)
    assert np.allclose(R[-1], np.diag(d**-0.5), rtol=1e-12)
    import gtsam

    model = gtsam.noiseModel.Gaussian.SqrtInformation(R[-1])
    assert np.allclose(model.sigmas(), np.sqrt(d), rtol=1e-9)


def test_sqrt_information_rejects_what_is_not_a_covariance():
    C = np.diag([1e-8, 1e-8, 1e-8, 1e-5, 1e-5, 1e-5])
    R = sqrt_information(C)
    assert np.allclose(R.T @ R, np.linalg.inv(C), rtol=1e-9)
    for bad in (np.zeros((6, 6)), -C, np.full((6, 6), np.nan), np.eye(3)):
        with pytest.raises(ValueError):
            sqrt_information(bad)


# --- adjustment and verification on simulated streets --------------------------------------

CHAIN = [(i, i + 1) for i in range(7)]
SKIPS = [(i, i + 2) for i in range(6)]


def street(rng: np.random.Generator, n: int = 8, loop: bool = False) -> list[np.ndarray]:
    """True ``T_world_node`` of ``n`` scanners about 15 m apart along a winding street (or
    around a block, ``loop``: the last one near the first), random headings, small tilts;
    world = node 0."""
    poses = []
    for k in range(n):
        if loop:
            a = 2 * np.pi * k / n
            xy = 19.6 * np.array([np.sin(a), 1 - np.cos(a)])
        else:
            xy = np.array([15.0 * k, 3.0 * np.sin(k)])
        R = rot([rng.normal(0, 0.004), rng.normal(0, 0.004), rng.uniform(-np.pi, np.pi)])
        T = rotation4(R)
        T[:3, 3] = [*xy, rng.normal(0, 0.3)]
        poses.append(T)
    world = np.linalg.inv(poses[0])
    return [world @ T for T in poses]


def link_covariance(rng: np.random.Generator) -> np.ndarray:
    """A correlated 6x6 link covariance: about 0.01-0.02 deg and 3-6 mm."""
    M = np.zeros((6, 6))
    M[:3, :3] = rot(rng.normal(0, 1, 3)) @ np.diag(np.radians([0.01, 0.012, 0.02]))
    M[3:, 3:] = rot(rng.normal(0, 1, 3)) @ np.diag([0.003, 0.004, 0.006])
    B = np.eye(6) + 0.1 * rng.normal(size=(6, 6))
    C = M @ B @ B.T @ M.T
    return 0.5 * (C + C.T)


def measured(truth, i, j, rng, trusted=True, error=None):
    """Edge (i, j): the true T_i_j times Exp(noise drawn from its covariance); ``error``: a
    gross error added to the translation (metres, frame i)."""
    import gtsam

    C = link_covariance(rng)
    noise = gtsam.Pose3.Expmap(rng.multivariate_normal(np.zeros(6), C)).matrix()
    T = np.linalg.inv(truth[i]) @ truth[j] @ noise
    if error is not None:
        T[:3, 3] += error
    return Edge(i, j, T, C, trusted)


def chained(edges, n: int) -> list[np.ndarray]:
    """Poses by multiplying the links (i, i+1) as ``ndt-chain`` does today."""
    by_pair = {(e.target, e.source): e.T_target_source for e in edges}
    poses = [np.eye(4)]
    for i in range(n - 1):
        poses.append(poses[-1] @ by_pair[(i, i + 1)])
    return poses


def errors_m(poses, truth) -> np.ndarray:
    return np.array(
        [np.linalg.norm(P[:3, 3] - T[:3, 3]) for P, T in zip(poses, truth, strict=True)]
    )


def tangent_error(P, T) -> np.ndarray:
    return log_right(T, P)[0]


def test_adjusted_street_beats_chaining_with_calibrated_covariances_and_residuals():

    err_adj, err_chain, node_chi2, link_chi2 = [], [], [], []
    for seed in range(40):
        rng = np.random.default_rng(seed)
        truth = street(rng)
        edges = [measured(truth, i, j, rng) for i, j in CHAIN + SKIPS]
        result = adjust(8, 0, edges)
        err_adj.append(errors_m(result.poses, truth).mean())
        err_chain.append(errors_m(chained(edges, 8), truth).mean())
        for k in range(1, 8):
            e = tangent_error(result.poses[k], truth[k])
            node_chi2.append(e @ np.linalg.solve(result.covariances[k], e))
        link_chi2.append([r.chi2 for r in result.residuals])
    assert np.mean(err_adj) < 0.8 * np.mean(err_chain)
    assert np.mean(np.array(err_adj) < np.array(err_chain)) > 0.7
    # node covariances are honest: E[e' inv(C) e] = 6 for the truth's error
    assert 5.0 < np.mean(node_chi2) < 7.0
    # chi2 of correct links: each small, their sum is chi2 with 6 * (13 - 7) = 36 dof
    assert np.max(link_chi2) < 22.46
    assert 33.0 < np.mean(np.sum(link_chi2, axis=1)) < 39.0


def test_covariances_grow_with_distance_from_the_anchor():

    rng = np.random.default_rng(7)
    truth = street(rng)
    result = adjust(8, 0, [measured(truth, i, j, rng) for i, j in CHAIN + SKIPS])
    tr = np.array([np.trace(C[3:, 3:]) for C in result.covariances])  # m^2
    assert tr[0] < 1e-10  # the anchor is held
    assert np.all(tr[3:] > tr[1:-2])  # two nodes further is always less certain
    assert tr[7] > 4 * tr[1]
    assert result.sigmas(7)[3:].max() > result.sigmas(1)[3:].max()


@pytest.mark.parametrize("bad", [(3, 4), (2, 4)])
def test_gross_outlier_is_rejected_and_poses_stay_correct(bad):

    rng = np.random.default_rng(11)
    truth = street(rng)
    pairs = CHAIN + SKIPS
    edges = [
        measured(truth, i, j, rng, error=[2.0, -1.5, 0.3] if (i, j) == bad else None)
        for i, j in pairs
    ]
    start = chained(edges, 8)  # the initial guess goes through the outlier when it is (3, 4)
    result = verify(8, 0, edges, start)
    states = result.states()
    k_bad = pairs.index(bad)
    assert states[k_bad] is EdgeState.REJECTED
    assert all(s is EdgeState.CONFIRMED for k, s in enumerate(states) if k != k_bad)
    assert all(s is NodeStatus.OK for s in result.statuses())
    assert result.edges[k_bad].residual.translation_m > 2.0
    clean = adjust(8, 0, [e for k, e in enumerate(edges) if k != k_bad])
    assert np.abs(errors_m(result.poses, clean.poses)).max() < 1e-4
    assert errors_m(result.poses, truth).max() < 0.05
    # without verification: Huber bounds the pull of the outlier, least squares does not,
    # Cauchy (refining the Huber solution) all but ignores it
    worst = {
        kernel: errors_m(adjust(8, 0, edges, start, kernel=kernel).poses, truth).max()
        for kernel in ("huber", "cauchy", "none")
    }
    assert worst["cauchy"] < 0.05 and worst["huber"] < 0.2 < 0.5 < worst["none"]


def test_outliers_apart_and_together_are_rejected():

    rng = np.random.default_rng(15)
    truth = street(rng, n=16)
    pairs = [(i, i + 1) for i in range(15)] + [(i, i + 2) for i in range(14)]
    wrong = {(2, 3), (3, 5), (11, 12)}  # two outliers side by side, one far away
    edges = [
        measured(truth, i, j, rng, error=rng.normal(0, 1.0, 3) if (i, j) in wrong else None)
        for i, j in pairs
    ]
    result = verify(16, 0, edges)
    rejected = {pairs[k] for k, s in enumerate(result.states()) if s is EdgeState.REJECTED}
    assert rejected == wrong
    assert all(s is NodeStatus.OK for s in result.statuses())
    assert errors_m(result.poses, truth).max() < 0.1


def test_a_wrong_link_in_a_cut_of_two_is_ambiguous_and_said_so():

    rng = np.random.default_rng(12)
    truth = street(rng)
    edges = [
        measured(truth, i, j, rng, error=[2.0, -1.5, 0.3] if (i, j) == (0, 1) else None)
        for i, j in CHAIN + SKIPS
    ]
    result = verify(8, 0, edges)  # node 0 has two links, (0, 1) and (0, 2): one must go
    pair = (result.edges[0], result.edges[len(CHAIN)])
    assert sorted(e.state.value for e in pair) == ["rejected", "used"]
    used = next(e for e in pair if e.state is EdgeState.USED)
    assert "ambiguous" in used.reason
    assert all(e.state is EdgeState.CONFIRMED for e in result.edges if e not in pair)


def test_node_reached_only_by_wrong_untrusted_links_is_suspect_not_ok():

    rng = np.random.default_rng(12)
    truth = street(rng, n=9)
    edges = [measured(truth, i, j, rng) for i, j in CHAIN + SKIPS]
    edges += [
        measured(truth, 6, 8, rng, trusted=False, error=[3.0, 0.0, 0.0]),
        measured(truth, 7, 8, rng, trusted=False, error=[-1.0, 4.0, 0.0]),
    ]
    result = verify(9, 0, edges)
    # the two disagree: one is rejected, the other is an unchecked bridge to node 8
    assert sorted(s.value for s in result.states()[-2:]) == ["rejected", "unused"]
    node = result.nodes[8]
    assert node.status is NodeStatus.SUSPECT and "unused link" in node.reason
    via = edges[node.via]
    expected = result.nodes[via.target].pose @ via.T_target_source
    assert np.allclose(node.pose, expected)
    assert all(n.status is NodeStatus.OK for n in result.nodes[:8])


def test_disconnected_nodes_form_a_cluster_in_their_first_nodes_frame():

    rng = np.random.default_rng(13)
    truth = street(rng, n=11)
    edges = [measured(truth, i, j, rng) for i, j in CHAIN + SKIPS + [(9, 10)]]
    result = adjust(11, 0, edges)
    assert [p is None for p in result.poses] == [False] * 8 + [True] * 3
    assert result.residuals[-1] is None and result.covariances[9] is None
    checked = verify(11, 0, edges)
    assert checked.clusters() == (0,) * 8 + (None, 1, 1)
    assert checked.statuses()[8] is NodeStatus.UNPOSED and checked.nodes[8].reason == "no link"
    assert checked.statuses()[9:] == (NodeStatus.OK,) * 2  # ok within their own cluster
    assert np.allclose(checked.poses[9], np.eye(4))
    relative = np.linalg.inv(truth[9]) @ truth[10]
    assert np.linalg.norm(checked.poses[10][:3, 3] - relative[:3, 3]) < 0.05
    assert checked.states()[-1] is EdgeState.USED  # a bridge of its own group
    assert errors_m(checked.poses[:8], truth[:8]).max() < 0.05
    assert checked.roots == {0: 0, 1: 9}


def test_loop_closure_reduces_the_end_error_versus_chaining():

    end_adj, end_chain = [], []
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        truth = street(rng, loop=True)
        edges = [measured(truth, i, j, rng) for i, j in CHAIN]
        edges.append(measured(truth, 7, 0, rng))  # node n-1 back to node 0
        result = verify(8, 0, edges)
        assert all(s is EdgeState.CONFIRMED for s in result.states())
        end_adj.append(errors_m(result.poses, truth)[7])
        end_chain.append(errors_m(chained(edges, 8), truth)[7])
    assert np.mean(end_adj) < 0.5 * np.mean(end_chain)


def test_untrusted_links_are_confirmed_when_consistent_and_rejected_when_not():

    for seed in range(5):
        rng = np.random.default_rng(200 + seed)
        truth = street(rng)
        edges = [measured(truth, i, j, rng) for i, j in CHAIN + SKIPS]
        edges += [
            measured(truth, 1, 5, rng, trusted=False),  # correct, closes a cycle
            measured(truth, 0, 7, rng, trusted=False),  # correct, long: the solution is weak
            measured(truth, 2, 6, rng, trusted=False, error=[0.0, 0.3, 0.0]),  # 30 cm off
        ]
        result = verify(8, 0, edges)
        assert result.states()[-3:] == (EdgeState.CONFIRMED,) * 2 + (EdgeState.REJECTED,)
        assert all(s is EdgeState.CONFIRMED for s in result.states()[:-3])
        assert all(s is NodeStatus.OK for s in result.statuses())
        assert "chi2" in result.edges[-1].reason


def test_a_chain_without_cycles_is_used_not_confirmed():

    rng = np.random.default_rng(14)
    truth = street(rng)
    edges = [measured(truth, i, j, rng) for i, j in CHAIN]
    edges[4] = measured(truth, 4, 5, rng, error=[5.0, 0, 0])  # wrong, but nothing can tell
    result = verify(8, 0, edges)
    assert result.states() == (EdgeState.USED,) * 7
    assert result.statuses() == (NodeStatus.OK,) * 8
    assert np.allclose(result.poses[7], chained(edges, 8)[7], atol=1e-6)


def test_bridges_of_a_small_graph():

    cov = np.eye(6) * 1e-4
    pairs = [(0, 1), (1, 2), (2, 0), (2, 3), (3, 4), (3, 4), (4, 5), (6, 7)]
    edges = [Edge(i, j, np.eye(4), cov) for i, j in pairs]
    assert bridges(8, edges, range(len(edges))) == {3, 6, 7}  # parallel links 4, 5: a cycle
    assert bridges(8, edges, [0, 1, 3]) == {0, 1, 3}


def test_edges_and_inputs_are_checked():

    cov = np.eye(6) * 1e-4
    with pytest.raises(ValueError):
        Edge(1, 1, np.eye(4), cov)
    with pytest.raises(ValueError):
        Edge(0, 1, np.eye(4), np.zeros((6, 6)))
    with pytest.raises(ValueError):
        Edge(0, 1, np.full((4, 4), np.nan), cov)
    # a node whose every link was rejected is unposed and the reason names them
    edges = [Edge(0, 1, np.eye(4), cov), Edge(1, 2, np.eye(4), cov)]
    adj = Adjustment((np.eye(4), np.eye(4), None), (None,) * 3, (None,) * 2, 0, 0.0)
    nodes = _node_verdicts(edges, [EdgeState.USED, EdgeState.REJECTED], adj, [0, 0, None])
    assert nodes[2].status is NodeStatus.UNPOSED and nodes[2].reason == "only rejected links: 1"
    assert "T_0_1" in repr(edges[0]) and "unposed" in repr(nodes[2])


def test_bad_arguments_are_refused():

    edges = [Edge(0, 1, np.eye(4), np.eye(6) * 1e-6)]  # 0.06 deg, 1 mm
    with pytest.raises(ValueError):
        adjust(2, 2, edges)
    with pytest.raises(ValueError):
        adjust(1, 0, edges)
    with pytest.raises(ValueError):
        verify(2, 0, edges, [np.eye(4)])
    with pytest.raises(ValueError):
        adjust(2, 0, edges, kernel="tukey")
    result = verify(2, 0, edges)
    assert "used 1" in repr(result) and "ok 2" in repr(result)


def test_links_none_of_which_passed_its_gate_confirm_each_other_around_cycles():

    rng = np.random.default_rng(21)
    truth = street(rng, n=16)
    pairs = [(i, i + 1) for i in range(15)] + [(i, i + 2) for i in range(14)]
    doubted = {(7, 8), (6, 8), (7, 9)}  # right, but none passed its own gate
    edges = [measured(truth, i, j, rng, trusted=(i, j) not in doubted) for i, j in pairs]
    result = verify(16, 0, edges)
    assert all(s is EdgeState.CONFIRMED for s in result.states())
    assert all(s is NodeStatus.OK for s in result.statuses())
    assert result.clusters() == (0,) * 16


def test_a_cut_of_two_gives_up_the_link_its_gate_doubted():

    rng = np.random.default_rng(22)
    truth = street(rng, n=8)
    edges = [measured(truth, i, j, rng) for i, j in CHAIN + SKIPS]
    k_bad = len(CHAIN) + SKIPS.index((5, 7))
    edges[k_bad] = measured(truth, 5, 7, rng, trusted=False, error=[0.0, 2.0, 0.0])
    result = verify(8, 0, edges)
    assert result.states()[k_bad] is EdgeState.REJECTED
    assert result.states()[CHAIN.index((6, 7))] is EdgeState.USED  # now a bridge
    assert all(s is NodeStatus.OK for s in result.statuses())
    assert errors_m(result.poses, truth).max() < 0.05


def test_a_busy_street_keeps_its_right_links_whatever_their_gates_said():

    rng = np.random.default_rng(23)
    truth = street(rng, n=10)
    pairs = [(i, i + 1) for i in range(9)] + [(i, i + 2) for i in range(8)]
    wrong = {(0, 2), (1, 3), (2, 4), (4, 6), (5, 7), (7, 9)}  # 6 of 8 skip links, metres off
    doubted = {(3, 4), (6, 7)}  # right adjacent links that failed their gates
    edges = []
    for i, j in pairs:
        error = rng.uniform(-50, 50, 3) * [1, 1, 0] if (i, j) in wrong else None
        edges.append(measured(truth, i, j, rng, trusted=(i, j) not in wrong | doubted, error=error))
    result = verify(10, 0, edges)
    rejected = {pairs[k] for k, s in enumerate(result.states()) if s is EdgeState.REJECTED}
    assert rejected == wrong
    kept = {pairs[k] for k, s in enumerate(result.states()) if s is not EdgeState.REJECTED}
    assert doubted <= kept
    assert all(s is NodeStatus.OK for s in result.statuses())
    clean = adjust(10, 0, [e for k, e in enumerate(edges) if pairs[k] not in wrong])
    assert np.abs(errors_m(result.poses, clean.poses)).max() < 1e-4


def test_links_weak_along_one_direction_leave_the_scans_suspect_however_well_they_agree():

    rng = np.random.default_rng(24)
    truth = street(rng, n=6)
    edges = []
    for i, j in [(i, i + 1) for i in range(5)] + [(i, i + 2) for i in range(4)]:
        e = measured(truth, i, j, rng)
        C = e.covariance.copy()
        axis = np.linalg.inv(truth[j])[:3, :3] @ np.linalg.inv(truth[i])[:3, :3].T @ [1, 0, 0]
        axis = truth[j][:3, :3].T @ [1.0, 0.0, 0.0]  # the world's x in the source's body frame
        C[3:, 3:] += 1e4 * np.outer(axis, axis)  # a corridor along world x: 100 m sigma
        T = e.T_target_source.copy()
        T[:3, 3] += truth[i][:3, :3].T @ [rng.uniform(-8, 8), 0.0, 0.0]  # slid along it
        edges.append(Edge(i, j, T, C, trusted=False))
    result = verify(6, 0, edges)
    assert all(s is EdgeState.CONFIRMED for s in result.states())  # they agree, trivially
    assert result.statuses()[0] is NodeStatus.OK
    assert all(s is NodeStatus.SUSPECT for s in result.statuses()[1:])
    assert all("not pinned down" in n.reason for n in result.nodes[1:])


@pytest.mark.parametrize("closer_fixes_position", [False, True])
def test_a_cycle_closed_by_a_degenerate_link_checks_no_position(closer_fixes_position):
    """Two pieces of a street, each with its cycles, joined by one wrong link (the second
    piece turned by 180 degrees and 60 m off) and a second link that agrees with the wrong
    one. Where that second link is degenerate (it fixes the rotation and the height, not where
    the scans are horizontally), their cycle checks no position: with no bridge trusted, the
    wrong link is not checkable and no scan of the second piece is ok. The same cycle closed
    by a link that fixes the position confirms the pair (they agree): what the test tells
    apart is the degenerate link alone."""
    rng = np.random.default_rng(31)
    truth = street(rng)
    W = pose2d_matrix(60.0, 4.0, np.pi)  # where the wrong links put the second piece
    pieces = [(0, 1), (1, 2), (0, 2), (2, 3), (1, 3), (4, 5), (5, 6), (4, 6), (6, 7), (5, 7)]
    edges = [measured(truth, i, j, rng) for i, j in pieces]
    for i, j, fixes in [(3, 4, True), (2, 5, closer_fixes_position)]:
        C = link_covariance(rng)
        if not fixes:
            C[3, 3] += 1e4  # horizontal translation in the source's frame: unknown
            C[4, 4] += 1e4
        T = np.linalg.inv(truth[i]) @ W @ truth[j]
        edges.append(Edge(i, j, T, C, trusted=fixes, horizontal=fixes))
    result = verify(8, 0, edges, trust_bridges=False)
    wrong = result.edges[len(pieces)]
    assert all(s is NodeStatus.OK for s in result.statuses()[:4])
    if closer_fixes_position:
        assert wrong.state is EdgeState.CONFIRMED
    else:
        assert wrong.state is EdgeState.UNUSED and "not checkable" in wrong.reason
        assert not any(s is NodeStatus.OK for s in result.statuses()[4:])


def test_uncheckable_edges_of_a_small_graph():
    """A triangle closed by a degenerate edge leaves its other two edges uncheckable; with a
    second, horizontal closer they are on a checking cycle again."""
    cov = np.eye(6) * 1e-4
    flat = Edge(2, 0, np.eye(4), cov, horizontal=False)
    edges = [
        Edge(0, 1, np.eye(4), cov),
        Edge(1, 2, np.eye(4), cov),
        flat,
        Edge(0, 2, np.eye(4), cov),
    ]
    assert uncheckable(3, edges, [0, 1, 2]) == {0, 1}
    assert bridges(3, edges, [0, 1, 2]) == set()
    assert uncheckable(3, edges, [0, 1, 2, 3]) == set()
