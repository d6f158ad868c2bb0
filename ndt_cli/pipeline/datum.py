"""The world frame of a campaign: levelled to the vertical, or the coordinate system of its
control stations (:mod:`ndt_cli.pipeline.control`).

Without control the world is the anchor's frame tipped about the anchor's ground point (below
its centre; its coordinates there are kept) until its z is the vertical: the verticals of every
scan of the anchor's cluster (each found when the scan was prepared,
:mod:`ndt_cli.ndt.vertical`) carried into the anchor's frame by the adjusted poses and
averaged, each weighted by how well it was found (:data:`VERTICAL_SIGMA_DEG`): not the anchor's
own instrument axis, tilted by however its tripod stood. The world's x is the anchor's x tipped
horizontal. An anchor whose ground point lies more than :data:`GEOREFERENCED_M` from its frame's
origin is in a georeferenced frame already (its z the vertical): that frame is the world.

With one station the frame is that levelled one moved so that the station's scanner sits at
its coordinates; its heading stays the anchor's (one point cannot give it).

With two or more stations the control enters the adjustment: each station is a prior on its
scan's position (a GTSAM ``GPSFactor`` with its standard deviations, under a Huber kernel),
each scan's vertical a prior on its tilt, the kept links between factors as before, and nothing
else holds the frame. The adjustment starts from the largest group of stations that agree with
one placement of the levelled network (:mod:`ndt_cli.pipeline.consensus`): two stations with
swapped numbers among five do not turn it onto them; two groups as large leave it unplaced. A
station whose misfit exceeds its standard deviations (chi-square, 3 DOF, p = 0.999) is
rejected, worst first, and the network solved again: a wrong point number or a GNSS fix off by
decimetres does not bend the network; one outside the group within the bound is taken in. With
two stations left that disagree, which one is wrong cannot be told: both are rejected. The
world is then the control's coordinate system (the graph works in it less the stations' mean,
rounded, so that its numbers stay small). Stations that cannot place the network leave it
levelled, and :func:`not_georeferenced` says why.

A map projection's coordinates are not at ground scale: UTM shrinks distances by 0.9996 on the
central meridian (40 cm per km), heights above the ellipsoid add R / (R + h). With the
projection's ``grid_scale`` the network is solved in ground coordinates (the stations' x, y
divided by it about their mean) and each scanner is then put where the grid has it; each scan
keeps its metric shape (a point 50 m from its scanner is off the grid's scale by at most 2 cm at
a zone's edge, where the scale departs 4e-4 from 1).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np

from ndt_cli.core.transforms import levelling_rotation, rotation4, translation
from ndt_cli.pipeline.adjust import Solver
from ndt_cli.pipeline.consensus import Group, largest_group, likely_cause
from ndt_cli.pipeline.control import Control, Station, unmatched
from ndt_cli.pipeline.marginals import marginal_covariances

VERTICAL_SIGMA_DEG = {  # how well each way of finding a scan's vertical finds it (1 sigma)
    "scanner": 0.005,  # a dual-axis compensator
    "structures": 0.02,  # walls and poles: measured within 0.04 deg on varied streets
    "structures+ground": 0.05,
    "ground": 0.1,  # the ground's normal: right on level ground only
    "given": 1.0,  # ground.z: no levelling at all
}
CHI2_3_999 = 16.266  # chi-square quantile, 3 degrees of freedom, p = 0.999
OUTSIDE = "its scan is not in the anchor's cluster"
GEOREFERENCED_M = 10_000.0  # a scan in its scanner's frame stands within its range of it

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ControlFit:
    """A station after the adjustment: where the network puts its scanner (world, m; None when
    its scan is not posed in the anchor's cluster), whether it was used, and why not."""

    control: Control
    adjusted: np.ndarray | None
    used: bool
    reason: str = ""

    @property
    def residual(self) -> np.ndarray | None:
        """Adjusted minus given (x, y, z; m), None without an adjusted position."""
        return None if self.adjusted is None else self.adjusted - self.control.xyz


class WorldFrame(StrEnum):
    """What the world frame is; the value is what summary.json holds."""

    LEVELLED = "levelled"  # the anchor's frame tipped level about its ground point
    GEOREFERENCED = "the anchor's own (georeferenced)"  # kept as it is
    CONTROL = "control"  # the coordinates of two or more control stations
    CONTROL_HEADING = "control, heading from the anchor"  # one station: the anchor's heading

    @property
    def from_control(self) -> bool:
        return self in (WorldFrame.CONTROL, WorldFrame.CONTROL_HEADING)


@dataclass(frozen=True)
class Datum:
    """How the anchor's cluster sits in the world: ``T_world_node`` of each of its nodes (the
    scans' reduced frames), their 6x6 covariances when the control adjustment gave new ones,
    what the frame is, the stations and the combined vertical's standard deviation (deg)."""

    poses: dict[int, np.ndarray]
    covariances: dict[int, np.ndarray]
    frame: WorldFrame
    controls: tuple[ControlFit, ...]
    vertical_sigma_deg: float
    problem: str = ""  # why stations that could be used did not make the world ('' if none)


@dataclass(frozen=True)
class Cluster:
    """What the datum needs of the anchor's cluster: each node's ``T_anchor_node`` (the
    anchor's scan frame from the node's reduced frame), its reduction point (scan frame, m),
    its vertical (unit, scan axes) and how it was found."""

    poses: dict[int, np.ndarray]
    reductions: dict[int, np.ndarray]
    ups: dict[int, np.ndarray]
    sources: dict[int, str]
    anchor: int = 0


def combined_vertical(cluster: Cluster) -> tuple[np.ndarray, float]:
    """The vertical in the anchor's frame: every scan's, carried by its pose, averaged with
    weights 1/sigma^2; and its standard deviation (deg)."""
    total, weight = np.zeros(3), 0.0
    for v, T in cluster.poses.items():
        if v in cluster.ups:
            w = 1.0 / VERTICAL_SIGMA_DEG.get(cluster.sources.get(v, "given"), 1.0) ** 2
            total += w * (T[:3, :3] @ cluster.ups[v])
            weight += w
    if weight == 0.0:
        return np.array([0.0, 0.0, 1.0]), VERTICAL_SIGMA_DEG["given"]
    return total / np.linalg.norm(total), float(1.0 / np.sqrt(weight))


def _levelled(up: np.ndarray) -> np.ndarray:
    """4x4 rotation turning ``up`` onto +z without a turn about z."""
    return rotation4(levelling_rotation(-up[0] / up[2], -up[1] / up[2]))


def _scanner(T_world_node: np.ndarray, reduction: np.ndarray) -> np.ndarray:
    """Where a scan's scanner (its frame's origin) is in the world."""
    return T_world_node[:3, :3] @ -reduction + T_world_node[:3, 3]


def datum(
    cluster: Cluster,
    controls: Sequence[Control],
    solver: Solver,
    kept: Sequence[int],
    grid_scale: float = 1.0,
) -> Datum:
    """The world frame of the anchor's cluster (see the module docstring). ``solver``: the
    network's, for the control adjustment; ``kept``: the edges it keeps in the cluster;
    ``grid_scale``: the control's grid distance over ground distance (a map projection's)."""
    if grid_scale == 1.0 or not controls:
        return _datum(cluster, controls, solver, kept)
    centre = np.mean([c.xyz for c in controls], axis=0)
    K = np.array([grid_scale, grid_scale, 1.0])
    ground = [replace(c, xyz=centre + (c.xyz - centre) / K) for c in controls]
    world = _datum(cluster, ground, solver, kept)
    return _on_grid(world, cluster, controls, centre, K)


def _on_grid(
    world: Datum, cluster: Cluster, controls: Sequence[Control], centre: np.ndarray, K: np.ndarray
) -> Datum:
    """The world of ground coordinates about ``centre`` put on the control's grid: each
    scanner moved to where the grid has it (x, y scaled by ``K`` about ``centre``), its
    orientation kept; the stations as given."""
    given = {c.scan: c for c in controls}
    if not world.frame.from_control:
        fits = tuple(replace(f, control=given[f.control.scan]) for f in world.controls)
        return replace(world, controls=fits)
    poses = {}
    for v, T in world.poses.items():
        red = cluster.reductions[v]
        moved = T.copy()
        moved[:3, 3] = centre + K * (_scanner(T, red) - centre) + T[:3, :3] @ red
        poses[v] = moved
    fits = tuple(
        replace(
            f,
            control=given[f.control.scan],
            adjusted=None if f.adjusted is None else centre + K * (f.adjusted - centre),
        )
        for f in world.controls
    )
    return replace(world, poses=poses, controls=fits)


def _datum(
    cluster: Cluster, controls: Sequence[Control], solver: Solver, kept: Sequence[int]
) -> Datum:
    """:func:`datum` at ground scale."""
    up, sigma = combined_vertical(cluster)
    ground = cluster.reductions[cluster.anchor]
    georeferenced = np.linalg.norm(ground) > GEOREFERENCED_M
    W = np.eye(4) if georeferenced else translation(ground) @ _levelled(up) @ translation(-ground)
    levelled = {v: W @ T for v, T in cluster.poses.items()}
    frame = WorldFrame.GEOREFERENCED if georeferenced else WorldFrame.LEVELLED
    usable = [c for c in controls if c.scan in cluster.poses]
    fits = [ControlFit(c, None, False, OUTSIDE) for c in controls if c.scan not in cluster.poses]
    if len(usable) >= 2:
        adjusted, problem, why = _controlled(cluster, levelled, usable, solver, kept)
        if adjusted is not None:
            poses, covariances, used = adjusted
            fits += [_fit(c, poses, cluster, c.scan in used) for c in usable]
            return Datum(poses, covariances, WorldFrame.CONTROL, tuple(fits), sigma)
        fits += [ControlFit(c, None, False, why[c.scan]) for c in usable]
        return Datum(levelled, {}, frame, tuple(fits), sigma, problem)
    if len(usable) == 1:
        c = usable[0]
        shift = translation(c.xyz - _scanner(levelled[c.scan], cluster.reductions[c.scan]))
        poses = {v: shift @ T for v, T in levelled.items()}
        fits.append(_fit(c, poses, cluster, True, "one station: position only"))
        return Datum(poses, {}, WorldFrame.CONTROL_HEADING, tuple(fits), sigma)
    return Datum(levelled, {}, frame, tuple(fits), sigma)


Adjusted = tuple[dict[int, np.ndarray], dict[int, np.ndarray], set[int]]


def _controlled(
    cluster: Cluster,
    levelled: dict[int, np.ndarray],
    stations: Sequence[Control],
    solver: Solver,
    kept: Sequence[int],
) -> tuple[Adjusted | None, str, dict[int, str]]:
    """The cluster adjusted with its stations, from the largest group of them that agrees
    (:mod:`ndt_cli.pipeline.consensus`); or None, why the stations cannot place it and, per
    station (by scan), why it is not used."""
    p = np.array([_scanner(levelled[c.scan], cluster.reductions[c.scan]) for c in stations])
    q = np.array([c.xyz for c in stations])
    s_xy = np.array([c.sigma_xy for c in stations])
    s_z = np.array([c.sigma_z for c in stations])
    group = largest_group(p, q, s_xy, s_z)
    unplaced = _why_unplaced(group, [c.name for c in stations], p, q, s_xy, s_z)
    if unplaced is not None:
        problem, why = unplaced
        return None, problem, dict.fromkeys((c.scan for c in stations), why)
    members = [stations[k] for k in group.members]
    others = [c for k, c in enumerate(stations) if k not in group.members]
    adjusted = _with_control(cluster, levelled, members, others, solver, kept)
    if adjusted is None:
        why = "the two stations left disagree beyond their standard deviations"
        return None, f"{why}: which is wrong cannot be told", {c.scan: why for c in stations}
    return adjusted, "", {}


def _why_unplaced(
    group: Group,
    names: Sequence[str],
    p: np.ndarray,
    q: np.ndarray,
    s_xy: np.ndarray,
    s_z: np.ndarray,
) -> tuple[str, str] | None:
    """Why the largest ``group`` of the stations ``names`` cannot place the network (arguments
    of :func:`~ndt_cli.pipeline.consensus.largest_group`), and what each station is told; None
    when it can: most stations agree, and no group as large places it elsewhere."""
    n, k = len(names), len(group.members)
    cause = likely_cause(p, q, s_xy, s_z, k) if k < n else ""
    if cause:
        return (
            f"{k} of the {n} stations agree with the network as given, {cause}",
            "the stations fit the network only if changed",
        )
    if group.rivals:
        a, b = (", ".join(names[i] for i in g) for g in (group.members, group.rivals))
        return (
            f"the stations form groups that place the network differently, {k} against "
            f"{len(group.rivals)} ({a} | {b}): which is right cannot be told",
            f"in one of two groups, {k} against {len(group.rivals)}: which is right cannot be told",
        )
    if k < 2:
        return _no_two_agree(p, q), "agrees with no other station"
    if 2 * k <= n:
        agree = ", ".join(names[i] for i in group.members)
        return (
            f"only {k} of the {n} stations agree with one placement of the network ({agree}): "
            "not a majority, which are right cannot be told",
            "the stations that agree are not the majority",
        )
    return None


def _no_two_agree(p: np.ndarray, q: np.ndarray) -> str:
    """Why no two stations agree with the network: of two, their distances."""
    if len(p) == 2:
        dq, dp = np.linalg.norm(q[1] - q[0]), np.linalg.norm(p[1] - p[0])
        return (
            f"the two stations are {dq:.2f} m apart, their scanners {dp:.2f} m: which is wrong "
            "cannot be told"
        )
    return f"no two of the {len(p)} stations agree with the network"


def _fit(
    c: Control, poses: dict[int, np.ndarray], cluster: Cluster, used: bool, reason: str = ""
) -> ControlFit:
    where = _scanner(poses[c.scan], cluster.reductions[c.scan])
    if not used and not reason:
        r = (where - c.xyz) / c.sigmas
        reason = f"rejected: misfit chi2 {float(r @ r):.4g} > {CHI2_3_999:.2f}"
    return ControlFit(c, where, used, reason)


def _heading_fit(
    levelled: dict[int, np.ndarray], stations: Sequence[Control], cluster: Cluster
) -> np.ndarray:
    """4x4 turn about z and shift taking the levelled anchor frame onto the control's
    coordinates at the stations (weighted least squares: the frame is level already, so two
    stations in a line are enough)."""
    p = np.array([_scanner(levelled[c.scan], cluster.reductions[c.scan]) for c in stations])
    q = np.array([c.xyz for c in stations])
    w = np.array([1.0 / c.sigma_xy**2 for c in stations])
    pm, qm = w @ p / w.sum(), w @ q / w.sum()
    a, b = (p - pm)[:, :2], (q - qm)[:, :2]
    cross = (w * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])).sum()
    dot = (w * (a * b).sum(axis=1)).sum()
    yaw = np.arctan2(cross, dot)
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0, 0, 1]])
    return translation(qm) @ rotation4(R) @ translation(-pm)


def _vertical_prior(g: object, v: int, T: np.ndarray, up: np.ndarray, sigma_deg: float) -> object:
    """A prior on node ``v``'s tilt alone: its vertical ``up`` (body axes) points up in the
    world within ``sigma_deg``; its heading and position are left free."""
    world_up = T[:3, :3] @ up
    Q = levelling_rotation(-world_up[0] / world_up[2], -world_up[1] / world_up[2])
    mean = T.copy()
    mean[:3, :3] = Q @ T[:3, :3]
    basis = np.linalg.svd(np.eye(3) - np.outer(up, up))[0][:, :2]  # the two tilt axes
    R = np.zeros((6, 6))
    R[:2, :3] = basis.T / np.radians(sigma_deg)
    return g.PriorFactorPose3(v, g.Pose3(mean), g.noiseModel.Gaussian.SqrtInformation(R))


def _solve_controlled(
    cluster: Cluster,
    start: dict[int, np.ndarray],
    stations: Sequence[Control],
    solver: Solver,
    kept: Sequence[int],
) -> tuple[dict[int, np.ndarray], object, object]:
    """Levenberg-Marquardt on the kept links, a position prior per station (on its node's
    frame origin: the station less its reduction point turned by the current pose) and a tilt
    prior per scan; the poses (local world), the graph and the values."""
    g = solver.g
    graph, values = g.NonlinearFactorGraph(), g.Values()
    for k in kept:
        graph.add(solver.factors[k])
    huber = g.noiseModel.mEstimator.Huber.Create(float(np.sqrt(CHI2_3_999)))
    for c in stations:
        T = start[c.scan]
        origin = c.xyz + T[:3, :3] @ cluster.reductions[c.scan]
        noise = g.noiseModel.Robust.Create(huber, g.noiseModel.Diagonal.Sigmas(c.sigmas))
        graph.add(g.GPSFactor(c.scan, origin, noise))
    for v, T in start.items():
        values.insert(v, g.Pose3(T))
        if v in cluster.ups:
            sig = VERTICAL_SIGMA_DEG.get(cluster.sources.get(v, "given"), 1.0)
            graph.add(_vertical_prior(g, v, T, cluster.ups[v], sig))
    params = g.LevenbergMarquardtParams()
    params.setMaxIterations(solver.max_iterations)
    values = g.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    return {v: values.atPose3(v).matrix() for v in start}, graph, values


def _chi2(c: Control, poses: dict[int, np.ndarray], cluster: Cluster) -> float:
    """A station's misfit: its residual over its sigmas, squared (chi-square, 3 DOF)."""
    r = (_scanner(poses[c.scan], cluster.reductions[c.scan]) - c.xyz) / c.sigmas
    return float(r @ r)


def _with_control(
    cluster: Cluster,
    levelled: dict[int, np.ndarray],
    group: Sequence[Control],
    others: Sequence[Control],
    solver: Solver,
    kept: Sequence[int],
) -> Adjusted | None:
    """The anchor's cluster adjusted with its stations (see the module docstring), from the
    ``group`` that agrees: the worst station above the chi-square bound left out, one at a
    time, and each of the ``others`` within it taken in. The poses and covariances in the
    control's coordinates and the scans of the stations used; None when two stations are
    left and they disagree."""
    origin = np.round(np.mean([c.xyz for c in group], axis=0))
    local = {c.scan: replace(c, xyz=c.xyz - origin) for c in (*group, *others)}
    A = _heading_fit(levelled, [local[c.scan] for c in group], cluster)
    start = {v: A @ T for v, T in levelled.items()}
    used, dropped = [c.scan for c in group], set()
    while True:
        active = [local[s] for s in used]
        poses, graph, values = _solve_controlled(cluster, start, active, solver, kept)
        poses, graph, values = _solve_controlled(cluster, poses, active, solver, kept)
        start = poses
        misfits = {s: _chi2(c, poses, cluster) for s, c in local.items()}
        worst = max(used, key=misfits.__getitem__)
        if misfits[worst] > CHI2_3_999:
            if len(used) <= 2:
                return None
            used.remove(worst)
            dropped.add(worst)
            continue
        back = [s for s in local if s not in used and s not in dropped and misfits[s] <= CHI2_3_999]
        if not back:
            break
        used += back
    covariances = marginal_covariances(solver.g, graph, values, poses)
    shift = translation(origin)
    return {v: shift @ T for v, T in poses.items()}, covariances, set(used)


def not_georeferenced(
    datum: Datum | None, stations: Sequence[Station], names: Sequence[str]
) -> str:
    """Why the world is not the control's coordinates as a control file of ``stations`` asks
    ('' when it is, or without control): fewer than two of its stations in use (fewer than
    one, for a file of one station). ``names``: the campaign's scans, as the outputs name them."""
    if not stations:
        return ""
    need = min(2, len(stations))
    fits = datum.controls if datum is not None else ()
    used = sum(f.used for f in fits)
    if used >= need:
        return ""
    why = [datum.problem] if datum is not None and datum.problem else []
    if datum is None:
        why.append("the anchor has no link yet")
    outside = [f.control.name for f in fits if f.reason == OUTSIDE]
    if outside:
        why.append(f"{len(outside)} on scans no link ties to the anchor ({', '.join(outside)})")
    why += [f"line {s.line}: {problem}" for s, problem in unmatched(stations, names)]
    return f"{used} of {len(stations)} control station(s) in use, {need} needed: " + "; ".join(why)


def log_unused_controls(datum: Datum | None) -> None:
    """A warning per control station the adjustment did not use, with its misfit."""
    for fit in () if datum is None else datum.controls:
        if not fit.used:
            r = fit.residual
            misfit = (
                ""
                if r is None
                else " (adjusted - given: {:+.1f} {:+.1f} {:+.1f} cm)".format(*(100 * r))
            )
            log.warning("control station %s not used: %s%s", fit.control.name, fit.reason, misfit)
