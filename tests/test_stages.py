"""The registration's stages one by one: ICP and its degeneracy measure, the rejection of large
ICP corrections, the choice between candidates, distinct poses, composing chained poses, and a
whole registration run on the numpy twins against the Numba path.

Expected values come from the construction of each case (known transforms, known geometry).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ndt_cli.config import Config, RefineConfig
from ndt_cli.core.transforms import transform_errors
from ndt_cli.ndt.backend import NUMBA, NUMPY
from ndt_cli.ndt.coarse_to_fine import fit_weighted
from ndt_cli.ndt.kernels import MATCHED, NACC, SCORE
from ndt_cli.ndt.prepare import load_and_prepare
from ndt_cli.ndt.quality import weakest_direction
from ndt_cli.ndt.refine import FACING_MARGIN, facing, icp, refine_pose
from ndt_cli.ndt.register import register
from ndt_cli.ndt.result import Status
from ndt_cli.ndt.search import distinct_indices
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.network import LinkKind
from ndt_cli.pipeline.solution import chained


def _plane(rng, origin, u, v, size, n):
    a = rng.uniform(-size, size, (n, 2))
    return origin + a[:, :1] * np.asarray(u, float) + a[:, 1:] * np.asarray(v, float)


def _room(rng, noise=0.002):
    """Floor, two walls and a ceiling patch at irregular positions: every direction observable."""
    parts = [
        _plane(rng, [0, 0, 0], [1, 0, 0], [0, 1, 0], 8, 6000),
        _plane(rng, [6, 0, 2], [0, 1, 0], [0, 0, 1], 4, 4000),
        _plane(rng, [0, -5, 2], [1, 0, 0], [0, 0, 1], 4, 4000),
        _plane(rng, [-3, 2, 3.1], [0.8, 0.6, 0], [-0.6, 0.8, 0], 2, 2000),
    ]
    pts = np.concatenate(parts)
    return pts + rng.normal(0, noise, pts.shape)


def _corridor(rng):
    """Floor and two parallel walls along x: a shift along x changes nothing."""
    parts = [
        _plane(rng, [0, 0, 0], [1, 0, 0], [0, 1, 0], 30, 8000),
        _plane(rng, [0, 3, 1.5], [1, 0, 0], [0, 0, 1], 30, 6000),
        _plane(rng, [0, -3, 1.5], [1, 0, 0], [0, 0, 1], 30, 6000),
    ]
    return np.concatenate(parts) + rng.normal(0, 0.002, (20000, 3))


def _rigid(rotvec_deg, t):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()
    T[:3, 3] = t
    return T


def _apply(T, p):
    return p @ T[:3, :3].T + T[:3, 3]


def test_icp_recovers_a_known_small_motion():
    rng = np.random.default_rng(1)
    target = _room(rng)
    T_true = _rigid([0.3, -0.2, 1.5], [0.15, -0.1, 0.05])
    source = _apply(np.linalg.inv(T_true), _room(rng))  # source = T_true^-1 (target scene)
    res = icp(target, source, np.eye(4), voxel=0.1)
    rot, trans = transform_errors(res.T, T_true)
    assert rot < 0.02 and trans < 0.003, (rot, trans)
    assert res.rms < 0.01 and res.inliers > 1000  # 2 mm noise, 0.1 m voxel centroids
    assert res.overlap > 0.9
    np.testing.assert_allclose(res.hessian, res.hessian.T, atol=1e-9)


def test_icp_weakest_translation_finds_the_corridor_axis():
    rng = np.random.default_rng(2)
    corridor = _corridor(rng)
    res = icp(corridor, corridor.copy(), np.eye(4), voxel=0.1)
    direction, ratio = res.weakest_translation()
    assert abs(direction[0]) > 0.99 and ratio < 0.01, (direction, ratio)
    room = _room(rng)
    _, ratio_room = icp(room, room.copy(), np.eye(4), voxel=0.1).weakest_translation()
    assert ratio_room > 0.05


def test_a_large_icp_correction_is_not_applied():
    rng = np.random.default_rng(3)
    target = _room(rng)
    T_true = _rigid([0.0, 0.0, 0.5], [0.4, 0.0, 0.0])
    source = _apply(np.linalg.inv(T_true), _room(rng))
    zero = np.zeros(3)
    ok = refine_pose(target, source, zero, zero, np.eye(4), RefineConfig(max_correction=1.0), 0.2)
    assert not ok.rejected and transform_errors(ok.T, T_true)[1] < 0.003
    tight = RefineConfig(max_correction=0.2)  # ICP must move 0.4 m: more than allowed
    no = refine_pose(target, source, zero, zero, np.eye(4), tight, 0.2)
    assert "rejected" in no.rejected and "0.40 m" in no.rejected
    np.testing.assert_array_equal(no.T, np.eye(4))  # the NDT pose is kept
    assert no.icp is not None  # the attempt is still reported


def test_a_rejected_icp_correction_is_a_field_that_decides_the_link_covariance():
    """The rejection travels as ``icp_rejected`` (through the link files too), not as text: a
    link whose ICP was rejected gets the NDT covariance, whatever its warnings say."""
    from ndt_cli.ndt.result import RegistrationResult
    from ndt_cli.pipeline.link_use import link_covariance

    rng = np.random.default_rng(5)
    target = _room(rng)
    source = _apply(np.linalg.inv(_rigid([0.0, 0.0, 0.5], [0.4, 0.0, 0.0])), _room(rng))
    zero = np.zeros(3)
    no = refine_pose(target, source, zero, zero, np.eye(4), RefineConfig(max_correction=0.2), 0.2)
    assert no.rejection is not None and no.rejection.moved_m == pytest.approx(0.4, abs=0.01)
    assert no.rejected == no.rejection.describe()

    def result(rejected: bool, warnings: tuple[str, ...]) -> RegistrationResult:
        H = np.diag([1e4, 2e4, 3e4, 4e4, 5e4, 6e4])
        args = (np.eye(4), Status.OK, True, 1.0, 1.0, 1.0, (), (), (), np.diag([9.0, 8.0, 7.0]))
        return RegistrationResult(
            *args, 0, 0, 0, warnings=warnings, icp_rms=0.01, icp_hessian=H,
            icp_centroid=np.zeros(3), icp_rejected=rejected,
        )  # fmt: skip

    kept = link_covariance(result(False, (no.rejected,)))  # the text alone decides nothing
    dropped = link_covariance(result(True, ()))
    assert not np.allclose(kept, dropped)
    np.testing.assert_allclose(kept, link_covariance(result(False, ())))
    for rejected in (True, False):  # kept in the link files
        assert RegistrationResult.from_dict(result(rejected, ()).to_dict()).icp_rejected is rejected


def test_refinement_works_in_reduced_frames():
    """Scans whose reduction points lie 5e6 m from the origin: ICP runs on the reduced points,
    and the refined transform is in the scans' own frames."""
    rng = np.random.default_rng(4)
    r_t = np.array([500_000.0, 5_400_000.0, 80.0])
    r_s = np.array([500_010.0, 5_400_003.0, 81.0])
    T_reduced = _rigid([0.0, 0.0, 20.0], [0.3, -0.2, 0.0])  # between the reduced frames
    T_true = _rigid([0, 0, 0], r_t) @ T_reduced @ _rigid([0, 0, 0], -r_s)  # the scans' frames
    target_world = _room(rng) + r_t
    source_world = _apply(np.linalg.inv(T_true), target_world)
    start = _rigid([0, 0, 0], r_t) @ T_reduced @ _rigid([0.0, 0.0, 0.3], [0.05, -0.03, 0.0])
    start = start @ _rigid([0, 0, 0], -r_s)  # 5 cm and 0.3 deg off, in the reduced frames
    res = refine_pose(target_world - r_t, source_world - r_s, r_t, r_s, start, RefineConfig(), 0.2)
    assert not res.rejected
    rot, trans = transform_errors(res.T, T_true)
    assert rot < 0.02 and trans < 0.003, (rot, trans)


def _seen_from(rng, y_scanner, face_y):
    """What a scanner at (0, y_scanner, 1.5) sees of a room split by a 0.15 m partition
    (x within 1.5 m, faces at y = 0 and 0.15): the floor, the far walls at x = 6 and y = -7 (seen
    round the partition's ends) and the partition's face ``face_y``; in the scanner's frame."""
    parts = [
        _plane(rng, [0, 0, 0], [1, 0, 0], [0, 1, 0], 8, 3000),
        _plane(rng, [6, 0, 1.5], [0, 1, 0], [0, 0, 1], 3, 1500),
        _plane(rng, [0, -7, 1.5], [1, 0, 0], [0, 0, 1], 3, 800),
        _plane(rng, [0, face_y, 1.25], [1, 0, 0], [0, 0, 1.25], 1.5, 8000),
    ]
    pts = np.concatenate(parts) + rng.normal(0, 0.002, (13300, 3))
    return pts - [0.0, y_scanner, 1.5]


def test_facing_keeps_surfaces_both_scanners_saw_from_the_same_side():
    q = np.zeros((4, 3))
    n = np.array([[0, 1.0, 0], [0, -1.0, 0], [0, 1.0, 0], [0, 1.0, 0]])  # sign is arbitrary
    seen_from = np.array([0.0, -2.0, 0.0])
    other = np.array([[0, -3.0, 0], [0, -3.0, 0], [0, 2.0, 0], [0, 0.5 * FACING_MARGIN, 0]])
    kept = [facing(q[k : k + 1], n[k : k + 1], seen_from, other[k])[0] for k in range(4)]
    assert kept == [True, True, False, True]  # same side, either normal; opposite; edge-on


def test_icp_does_not_match_the_two_faces_of_a_thin_wall():
    """Two scanners on either side of a 0.15 m partition: point-to-plane ICP started at the
    truth matches one face to the other and slides by part of the wall's thickness; told
    where the scanners stand, it matches only what both saw from the same side."""
    rng = np.random.default_rng(6)
    target, source = _seen_from(rng, -2.0, 0.0), _seen_from(rng, 2.0, 0.15)
    r_t, r_s = np.array([0.3, 0.1, -1.5]), np.array([-0.2, 0.4, -1.5])  # reduction points
    T_true = _rigid([0, 0, 0], [0.0, 4.0, 0.0])  # scanner B's frame to scanner A's
    cfg, zero = RefineConfig(), np.zeros(3)
    args = (target - r_t, source - r_s, r_t, r_s, T_true, cfg, 0.2)
    blind = refine_pose(*args)
    told = refine_pose(*args, scanners=(zero, zero))  # each scanner at its frame's origin
    assert transform_errors(blind.T, T_true)[1] > 0.05  # the faces pull it off the truth
    rot, trans = transform_errors(told.T, T_true)
    assert rot < 0.02 and trans < 0.005, (rot, trans)


def _pillar_seen(rng, face):
    """A room with a 1 m square pillar (x 0-1, y 3-4, 2.5 m high) of which one scanner saw the
    front face (y = 3) and the other the side face (x = 1), both the floor and two far walls;
    world frame (m)."""
    parts = [
        _plane(rng, [0, 0, 0], [1, 0, 0], [0, 1, 0], 8, 3000),
        _plane(rng, [-6, 0, 1.5], [0, 1, 0], [0, 0, 1], 4, 600),
        _plane(rng, [0, 10, 1.5], [1, 0, 0], [0, 0, 1], 4, 600),
    ]
    if face == "front":
        parts.append(_plane(rng, [0.5, 3, 1.25], [0.5, 0, 0], [0, 0, 1.25], 1, 6000))
    else:
        parts.append(_plane(rng, [1, 3.5, 1.25], [0, 0.5, 0], [0, 0, 1.25], 1, 6000))
    pts = np.concatenate(parts)
    return pts + rng.normal(0, 0.002, pts.shape)


def test_icp_does_not_match_a_face_to_the_one_round_the_corner():
    """Near the pillar's edge the side face the source saw lies within centimetres of the
    front face the target saw; matched to it (its normal 90 degrees off), the pose slides
    by 13-18 cm. Pairs whose normals disagree by more than 30 degrees are not matched."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        target = _pillar_seen(rng, "front") - [0.5, 0.0, 1.5]  # scanner at (0.5, 0, 1.5)
        source = _pillar_seen(rng, "side") - [5.0, 3.5, 1.5]  # scanner at (5, 3.5, 1.5)
        T_true = _rigid([0, 0, 0], [4.5, 3.5, 0.0])
        zero = np.zeros(3)
        res = refine_pose(target, source, zero, zero, T_true, RefineConfig(), 0.2)
        rot, trans = transform_errors(res.T, T_true)
        assert rot < 0.02 and trans < 0.003, (seed, rot, trans)


def test_distinct_indices_merges_near_poses_and_keeps_the_best_first():
    params = np.array(
        [[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.0, np.pi], [5.0, 5.0, 0.1]]
    )
    scores = np.array([10.0, 11.0, 5.0, 7.0, 0.0])
    picked = distinct_indices(params, scores, k=10, cell=2.0)
    # 1 beats 0 (0.3 m apart: one pose); 3 differs by 180 deg; 2 is 10 m away; 4 scores zero
    assert picked.tolist() == [1, 3, 2]
    assert distinct_indices(params, scores, k=2, cell=2.0).tolist() == [1, 3]
    assert distinct_indices(params, np.zeros(5), k=3, cell=2.0).tolist() == [0]  # best kept


def test_fit_weighted_prefers_the_better_fit_over_more_matches():
    acc = np.zeros((2, NACC))
    acc[0, SCORE], acc[0, MATCHED] = 60.0, 100.0  # many matched points, each fitting poorly
    acc[1, SCORE], acc[1, MATCHED] = 55.0, 60.0  # fewer, fitting well
    w = fit_weighted(acc)
    assert w[1] == 1.0 and w[0] == pytest.approx((60.0**2 / 100) / (55.0**2 / 60))


def test_weakest_direction_of_the_ndt_hessian():
    V = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    H = np.zeros((3, 3))
    H[:2, :2] = V @ np.diag([4.0, 0.02]) @ V.T
    H[2, 2] = 7.0
    direction, ratio = weakest_direction(H)
    assert abs(direction @ V[:, 1]) == pytest.approx(1.0) and ratio == pytest.approx(0.005)
    assert weakest_direction(-np.eye(3))[1] == 0.0  # no curvature at all


def _link(k, i, j, T, status=Status.OK):
    from ndt_cli.ndt.result import RegistrationResult

    if T is None:
        return Link(k, i, j, failure="unreadable")
    r = RegistrationResult(T, status, True, 1.0, 1.0, 1.0, (), (), (), np.eye(3), 0, 0, 0)
    return Link(k, i, j, result=r)


def compose_poses(n, links, anchor):
    return chained(n, links, anchor, {LinkKind.ADJACENT})


def test_compose_poses_forward_and_backward_from_the_anchor():
    rel = [_rigid([0, 0, 10.0 * k], [k + 1.0, 0.5, 0.0]) for k in range(4)]
    links = [_link(k, k, k + 1, rel[k]) for k in range(4)]
    poses = compose_poses(5, links, anchor=2)
    np.testing.assert_array_equal(poses[2], np.eye(4))
    np.testing.assert_allclose(poses[3], rel[2])
    np.testing.assert_allclose(poses[4], rel[2] @ rel[3])
    np.testing.assert_allclose(poses[1], np.linalg.inv(rel[1]))
    np.testing.assert_allclose(poses[0], np.linalg.inv(rel[0] @ rel[1]))


def test_compose_poses_stops_at_a_failed_or_suspect_link():
    rel = [_rigid([0, 0, 5.0], [2.0, 0, 0]) for _ in range(4)]
    links = [_link(0, 0, 1, rel[0]), _link(1, 1, 2, None), _link(2, 2, 3, rel[2])]
    poses = compose_poses(4, links, anchor=0)
    assert poses[1] is not None and poses[2] is None and poses[3] is None
    links = [_link(0, 0, 1, rel[0]), _link(1, 1, 2, rel[1], Status.SUSPECT)]
    assert compose_poses(3, links, anchor=0)[2] is None  # no pose through a link not ok


@pytest.fixture(scope="module")
def small_pair():
    from ndt_cli import sim

    _, scans, poses = sim.make_sequence(
        seed=21, n_scans=2, spacing=(13.0, 15.0), scan_kwargs={"n_azimuth": 720}
    )
    cfg = Config().replace(
        search={"yaw_starts": 12, "translation_range": 20.0, "keep_candidates": 4},
        grid={"cell_sizes": [10.0, 5.0, 2.0]},
        refine={"method": "none"},
    )
    return scans, poses, cfg


@pytest.mark.slow
def test_preparing_on_the_numpy_twins_gives_the_same_slices(small_pair):
    scans, _, _ = small_pair
    fast, slow = (load_and_prepare(scans[0], Config(), k) for k in (NUMBA, NUMPY))
    # normals by Jacobi rotations or by LAPACK: the vertical, the ground under the centre and
    # the levelling agree to rounding
    np.testing.assert_allclose(fast.reduction, slow.reduction, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.terrain.heights, slow.terrain.heights, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.level, slow.level, rtol=0, atol=1e-12)
    for a, b in zip(fast.slices, slow.slices, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.points3d, slow.points3d, rtol=0, atol=1e-9)


@pytest.mark.slow
def test_a_whole_registration_on_the_numpy_twins_matches_the_numba_path(small_pair):
    scans, poses, cfg = small_pair
    fast = register(scans[0], scans[1], cfg, kernels=NUMBA)
    slow = register(scans[0], scans[1], cfg, kernels=NUMPY)
    assert fast.status == slow.status == Status.OK
    rot, trans = transform_errors(slow.T_target_source, fast.T_target_source)
    assert rot < 0.001 and trans < 0.001, (rot, trans)  # sums in another order: sub-millimetre
    truth = np.linalg.inv(poses[0]) @ poses[1]
    assert transform_errors(fast.T_target_source, truth)[1] < 0.02  # and both are right


def test_a_worker_prepares_each_scan_once_for_all_its_links(tmp_path):
    import os

    from ndt_cli import io, sim
    from ndt_cli.pipeline import tasks

    _, scans, _ = sim.make_sequence(seed=3, n_scans=1, scan_kwargs={"n_azimuth": 300})
    f = tmp_path / "s.laz"
    io.write(f, scans[0])
    cfg = Config()
    first = tasks.prepare_scan(f, cfg)
    assert tasks.prepare_scan(f, cfg) is first  # the second link reuses it
    assert tasks.prepare_scan(f, cfg.replace(slices={"thickness": 0.3})) is not first
    os.utime(f, ns=(1, 1))  # the file changed: prepared again
    assert tasks.prepare_scan(f, cfg) is not first
    assert "file not found" in tasks.prepare_scan(tmp_path / "none.laz", cfg)


def test_a_worker_ships_each_prepared_scan_with_its_free_space_view(tmp_path):
    from ndt_cli import io, sim
    from ndt_cli.pipeline import tasks

    _, scans, _ = sim.make_sequence(seed=4, n_scans=1, scan_kwargs={"n_azimuth": 300})
    f = tmp_path / "s.laz"
    io.write(f, scans[0])
    with_check = tasks.prepare_scan(f, Config())
    assert "sight" in vars(with_check) and with_check.sight is not None  # built by the task
    without = tasks.prepare_scan(f, Config().replace(search={"free_space_ratio": 0.0}))
    assert "sight" not in vars(without)  # the check is off: nothing built
