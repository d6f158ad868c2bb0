"""How far a network's verdicts can be trusted, measured against ground truth.

A link or a scan is **correct** when its transform is within :data:`CORRECT` of the truth
(full 6-DOF: rotation angle and translation of the difference). Its verdict is a **false
alarm** when it is correct but not ok (a surveyor rescans for nothing, or loses the scan), and a
**wrong ok** when it is ok but not correct (a wrong pose vouched for: the failure that must
never happen); a scan's pose also counts as correct within three times the standard deviation
the network gives it (drift along a long chain is stated, not hidden). Scans are compared in
their cluster's frame: the pose of each scan relative to the anchor, or to the first scan of
its cluster. Used by the trust sweep
(``benchmarks/trust_sweep.py``) and its reduced tier in the tests.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from ndt_cli.core.transforms import transform_errors, wrap_angle
from ndt_cli.ndt.result import RegistrationResult, Status
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.verify import EdgeState, NodeStatus

CORRECT = (0.1, 0.05)  # degrees, metres: what a registration must reach to count as right
KEPT = (EdgeState.CONFIRMED, EdgeState.USED)


@dataclass(frozen=True)
class LinkTruth:
    """One link against the truth: its verdicts, its error (deg, m) and the error of its NDT
    result before the refinement (NaN when not kept)."""

    target: int
    source: int
    kind: str
    status: Status
    state: EdgeState
    rot_deg: float
    trans_m: float
    ndt_rot_deg: float
    ndt_trans_m: float

    @property
    def correct(self) -> bool:
        return self.rot_deg <= CORRECT[0] and self.trans_m <= CORRECT[1]


@dataclass(frozen=True)
class ScanTruth:
    """One scan against the truth: status, pose error relative to its cluster's first scan
    (the anchor for cluster 0; deg, m; NaN when unposed), the error of its own vertical and of
    the world's z as its pose has it (deg; NaN when unknown)."""

    index: int
    status: NodeStatus
    rot_deg: float
    trans_m: float
    vertical_deg: float
    cluster: int | None = None
    sigma_m: float = 0.0  # the network's 1-sigma of the position (norm over x, y, z), m
    sigma_deg: float = 0.0  # and of the heading, degrees
    world_vertical_deg: float = float("nan")  # the world's z against the truth (cluster 0)

    @property
    def correct(self) -> bool:
        """Within :data:`CORRECT`, or within three of the network's own standard deviations:
        a long chain drifts, and a pose within what the network says of it is not a wrong
        one vouched for."""
        return self.rot_deg <= max(CORRECT[0], 3 * self.sigma_deg) and self.trans_m <= max(
            CORRECT[1], 3 * self.sigma_m
        )


@dataclass(frozen=True)
class TrustCounts:
    """Counts over links and scans (see the module docstring)."""

    links: int = 0
    links_correct: int = 0
    links_ok: int = 0
    link_false_alarms: int = 0  # correct, not ok
    link_wrong_ok: int = 0  # ok, not correct
    link_wrong_kept: int = 0  # not correct, kept by the network (a degenerate link is kept
    # for its rotation and height only: not counted)
    scans: int = 0
    scans_ok: int = 0
    scan_false_alarms: int = 0
    scan_wrong_ok: int = 0
    scans_split: int = 0  # expected ok, ok, but in a cluster of its own (not the anchor's)

    def __add__(self, other: TrustCounts) -> TrustCounts:
        return TrustCounts(*(getattr(self, f.name) + getattr(other, f.name) for f in fields(self)))


def _errors(T: np.ndarray | None, T_true: np.ndarray) -> tuple[float, float]:
    return (float("nan"), float("nan")) if T is None else transform_errors(T, T_true)


def link_truths(result: ChainResult, truth: Sequence[np.ndarray]) -> list[LinkTruth]:
    """Every link of ``result`` against the true ``T_world_scan`` of its scans."""
    out = []
    for link, fit in zip(result.links, result.solution.links, strict=True):
        T_true = np.linalg.inv(truth[link.target]) @ truth[link.source]
        rot, trans = _errors(link.T_target_source, T_true)
        ndt = None if link.result is None else link.result.T_ndt
        ndt_rot, ndt_trans = _errors(ndt, T_true)
        out.append(
            LinkTruth(
                link.target,
                link.source,
                link.kind.value,
                link.status,
                fit.state,
                rot,
                trans,
                ndt_rot,
                ndt_trans,
            )
        )
    return out


def verticals(result: ChainResult, truth: Sequence[np.ndarray]) -> list[float]:
    """Angle (deg) between each scan's vertical as its preparation found it and the truth."""
    level: dict[int, np.ndarray] = {}
    for link in result.links:
        if link.result is not None:
            level[link.target] = link.result.level_target
            level[link.source] = link.result.level_source
    out = []
    for k, T in enumerate(truth):
        if k not in level:
            out.append(float("nan"))
            continue
        found, true = level[k].T @ [0.0, 0.0, 1.0], T[:3, :3].T @ [0.0, 0.0, 1.0]
        out.append(float(np.degrees(np.arccos(np.clip(found @ true, -1.0, 1.0)))))
    return out


def scan_truths(result: ChainResult, truth: Sequence[np.ndarray]) -> list[ScanTruth]:
    """Every scan's status and pose error in its cluster's frame: the anchor's, or that of
    the cluster's root (:attr:`NetworkSolution.roots`; a scan posed only through an unused
    link may come before it, and is no reference), else its first scan."""
    scans = result.solution.scans
    roots: dict[int, int] = {0: result.anchor, **result.solution.roots}
    for k, scan in enumerate(scans):
        if scan.cluster is not None:
            roots.setdefault(scan.cluster, k)
    vertical = verticals(result, truth)
    out = []
    for k, scan in enumerate(scans):
        root = roots[scan.cluster if scan.cluster is not None else 0]
        found = None
        if scan.T_world_scan is not None and scans[root].T_world_scan is not None:
            found = np.linalg.inv(scans[root].T_world_scan) @ scan.T_world_scan
        rot, trans = _errors(found, np.linalg.inv(truth[root]) @ truth[k])
        sigma = np.zeros(4) if scan.sigma is None else scan.sigma
        sigmas = float(np.linalg.norm(sigma[:3])), float(sigma[3])
        level = _up_error(scan.T_world_scan, truth[k]) if scan.cluster == 0 else float("nan")
        out.append(ScanTruth(k, scan.status, rot, trans, vertical[k], scan.cluster, *sigmas, level))
    return out


def _up_error(T_world_scan: np.ndarray | None, truth: np.ndarray) -> float:
    """Angle (deg) between the world's z as a scan's pose has it and the true vertical."""
    if T_world_scan is None:
        return float("nan")
    found, true = T_world_scan[2, :3], truth[2, :3]  # the world's z in the scan's axes
    return float(np.degrees(np.arccos(np.clip(found @ true, -1.0, 1.0))))


def count(
    links: Sequence[LinkTruth],
    scans: Sequence[ScanTruth],
    expected: Sequence[bool] | None = None,
) -> TrustCounts:
    """The counts of :class:`TrustCounts` over one network. ``expected``: which scans should
    come out ok (default all: a clean street); a scan expected ok that is not is a false alarm,
    posed or not."""
    ok_links = [x for x in links if x.status is Status.OK]
    ok_scans = [s for s in scans if s.status is NodeStatus.OK]
    expected = [True] * len(scans) if expected is None else list(expected)
    return TrustCounts(
        links=len(links),
        links_correct=sum(x.correct for x in links),
        links_ok=len(ok_links),
        link_false_alarms=sum(x.correct and x.status is not Status.OK for x in links),
        link_wrong_ok=sum(not x.correct for x in ok_links),
        link_wrong_kept=sum(
            not x.correct and x.state in KEPT and x.status is not Status.DEGENERATE for x in links
        ),
        scans=len(scans),
        scans_ok=len(ok_scans),
        scan_false_alarms=sum(
            e and s.status is not NodeStatus.OK for s, e in zip(scans, expected, strict=True)
        ),
        scan_wrong_ok=sum(not s.correct for s in ok_scans),
        scans_split=sum(
            e and s.status is NodeStatus.OK and s.cluster != 0
            for s, e in zip(scans, expected, strict=True)
        ),
    )


def metrics(r: RegistrationResult) -> dict[str, float]:
    """What a registration's gate could look at, for measuring each check's false alarms and
    misses: the slices' fit (score per point before and after ICP, overlap, ambiguity, the NDT
    Hessian's constraint ratio), ICP's (RMS, 3D overlap, constraint ratio once rotation is free,
    how far it moved the NDT pose and how much it tilted the scans against their verticals)
    and the free-space share of the final pose."""
    w = np.linalg.eigvalsh(r.hessian[:2, :2])
    move = transform_errors(r.T_target_source, r.T_ndt) if r.T_ndt is not None else (np.nan,) * 2
    up_t, up_s = r.level_target.T[:, 2], r.level_source.T[:, 2]
    tilt = np.degrees(np.arccos(np.clip((r.T_target_source[:3, :3] @ up_s) @ up_t, -1, 1)))
    icp_ratio = np.nan
    if r.icp_hessian is not None:
        H = r.icp_hessian
        S = H[3:, 3:] - H[3:, :3] @ np.linalg.solve(H[:3, :3] + 1e-12 * np.eye(3), H[:3, 3:])
        ws = np.linalg.eigvalsh(0.5 * (S + S.T))
        icp_ratio = float(ws[0] / ws[-1]) if ws[-1] > 0 else 0.0
    return {
        "score_per_point": r.score_per_point,
        "score_per_point_final": r.score_per_point_final,
        "overlap": r.overlap,
        "ambiguity": r.ambiguity,
        "constraint": float(max(w[0], 0.0) / w[1]) if w[1] > 0 else 0.0,
        "icp_rms": r.icp_rms,
        "overlap_3d": r.overlap_3d,
        "icp_constraint": icp_ratio,
        "icp_move_deg": float(move[0]),
        "icp_move_m": float(move[1]),
        "tilt_deg": float(tilt),
        "free_space": r.free_space,
        "free_space_around": r.free_space_around,
        "free_space_second": r.free_space_second,
    }


def candidates(r: RegistrationResult, T_true: np.ndarray) -> list[dict[str, float]]:
    """Each distinct candidate of a registration (the kept pose first) against the kept pose
    and the truth: its share of the kept pose's evidence, its free-space share, its turn (deg)
    and distance (m) from the kept pose, and its planar error from the truth (deg, m), all in
    the scans' reduced frames (the levelling's tilt, below a degree, is left out). For
    measuring what separates a wrong pose's rivals from a right one's."""
    if not r.candidates:
        return []
    A, B = np.eye(4), np.eye(4)
    A[:3, 3], B[:3, 3] = -r.reduction_target, r.reduction_source
    T = A @ T_true @ B
    true = np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])
    first = r.candidates[0]
    kept = np.array([first.tx, first.ty, np.radians(first.yaw_deg)])
    out = []
    for c in r.candidates:
        pose = np.array([c.tx, c.ty, np.radians(c.yaw_deg)])
        out.append(
            {
                "evidence": c.evidence / max(first.evidence, 1e-300),
                "free_space": c.free_space,
                "turn_deg": float(np.degrees(wrap_angle(pose[2] - kept[2]))),
                "apart_m": float(np.hypot(*(pose[:2] - kept[:2]))),
                "error_deg": float(np.degrees(abs(wrap_angle(pose[2] - true[2])))),
                "error_m": float(np.hypot(*(pose[:2] - true[:2]))),
            }
        )
    return out
