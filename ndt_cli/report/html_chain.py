"""``report.html`` of a campaign (``ndt-chain``, ``ndt-watch``): the verdict and what it rests
on, the network's figures, the control stations, the plan, the scans with their status, pose
and uncertainty, the links with their registration, state and strength, the link inspector,
the registrations tried and left out, and the notes that say what the statuses mean."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ndt_cli.core.transforms import yaw_of
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.solution import LinkFit, ScanPose
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.report.html import ControlRow, Figure, LinkRow, ScanRow, Verdict
from ndt_cli.report.html_cards import link_cards
from ndt_cli.report.html_report import finite, render
from ndt_cli.report.network_numbers import NetworkNumbers, link_strength, network_numbers
from ndt_cli.report.reasons import network_note
from ndt_cli.report.verdict import judge
from ndt_cli.report.world import world_line, world_summary

STATE_WORDS = {
    EdgeState.CONFIRMED: "confirmed",
    EdgeState.USED: "not checked",
    EdgeState.REJECTED: "rejected",
    EdgeState.UNUSED: "not used",
}
"""A link's state in the network as the report and the console word it: a kept link that no
cycle checks reads "not checked", never like a confirmed one."""


def _scan_row(name: str, scan: ScanPose, anchor: bool) -> ScanRow:
    T, sigma = scan.T_world_scan, scan.sigma
    pose = (None,) * 4 if T is None else (*T[:3, 3], float(np.degrees(yaw_of(T))))
    sd = (None,) * 4 if sigma is None else (*(100 * sigma[:3]), sigma[3])
    status = "anchor" if anchor and scan.status is NodeStatus.OK else scan.status.value
    reason = scan.reason
    if scan.status is NodeStatus.OK and scan.cluster:
        reason = f"cluster {scan.cluster}: no kept link ties it to the anchor (its own frame)"
    return ScanRow(name, status, *pose, *sd, reason=reason)


def link_row(names: Sequence[str], link: Link, state: str, fit: LinkFit | None) -> LinkRow:
    """A link's row: ``state`` as the report words it; the residual of a link a cycle checks
    or that was rejected (``fit``), none for the others."""
    r = link.result
    res = fit.residual if fit and fit.state in (EdgeState.CONFIRMED, EdgeState.REJECTED) else None
    note = network_note(link, fit)
    warnings = tuple(w for w in (link.reason, note) if w)
    return LinkRow(
        kind=link.kind.value,
        target=names[link.target],
        source=names[link.source],
        status=link.status.value,
        state=state,
        score_per_point=None if r is None else r.score_per_point,
        overlap=None if r is None else r.overlap,
        ambiguity=None if r is None else r.ambiguity,
        icp_rms_cm=None if r is None else finite(100 * r.icp_rms),
        residual_deg=None if res is None else res.rotation_deg,
        residual_cm=None if res is None else 100 * res.translation_m,
        warnings=warnings,
        strength_mm=None if r is None else link_strength(r).as_mm(),
        figure=f"link-{link.index}" if r is not None else "",
        network=note,
    )


def _network(n: NetworkNumbers, adjusted: bool) -> tuple[tuple[str, str], ...]:
    """The network's figures, as (label, value) pairs."""
    failed = n.tried - n.registered
    checked = (
        f"max {n.max_cm:.2f} cm, {n.max_deg:.4f}°; RMS {n.rms_cm:.2f} cm, {n.rms_deg:.4f}°"
        if n.max_cm is not None
        else "none: no link lies on a cycle"
    )
    sigma0 = (
        f"{n.sigma0:.2f} (redundancy {n.redundancy})"
        if n.sigma0 is not None
        else "none: no redundancy"
    )
    return (
        ("registrations tried", f"{n.tried}: {n.registered} registered, {failed} failed"),
        ("links in the network", f"{n.in_network}; {n.left_out} left out"),
        ("kept", f"{n.kept}: {n.confirmed} confirmed by a cycle, {n.not_checked} not checked"),
        ("rejected, not used", f"{n.rejected} rejected, {n.not_used} not used"),
        ("residuals of the checked links", checked),
        ("a-posteriori σ (unit weight)", sigma0 if adjusted else "not adjusted"),
    )


def _controls(result: ChainResult) -> tuple[tuple[ControlRow, ...], str]:
    """The control table's rows and what it rests on (the world frame, the grid scale)."""
    rows = []
    for r in world_summary(result)["controls"]:
        res, adj = r["residual_cm"], r["adjusted"]
        state = "used" if r["used"] else ("rejected" if "rejected" in r["reason"] else "not used")
        rows.append(
            ControlRow(
                station=r["scan"],
                given=tuple(r["given"]),
                adjusted=None if adj is None else tuple(adj),
                residual_cm=None if res is None else tuple(res),
                sigma_xy_cm=100 * r["sigma_xy"],
                sigma_z_cm=100 * r["sigma_z"],
                state=state,
                reason=r["reason"],
            )
        )
    scale, line = result.grid_scale, world_line(result)
    note = (
        f"{line[:1].upper()}{line[1:]}. Grid scale applied at the scanners: {scale:.8f} "
        "(grid distance / ground distance" + ("; 1: none)." if scale == 1.0 else ").")
    )
    return tuple(rows), note


def _left_out(result: ChainResult) -> tuple[str, ...]:
    """Per scan not ok: why, and every registration tried for it."""
    every = [*result.links, *(t.link for t in result.tried)]
    out = []
    for k, (name, s) in enumerate(zip(result.names, result.solution.scans, strict=True)):
        if s.anchored:
            continue
        mine = [x for x in every if k in (x.target, x.source)]
        tried = "; ".join(
            f"{result.names[x.target]} <- {result.names[x.source]}: {x.status.value}"
            + (f" ({x.reason})" if x.reason else "")
            for x in mine
        )
        why = s.reason or f"ok in cluster {s.cluster}, not tied to the anchor"
        out.append(
            f"{name} ({s.status.value}): {why}. Registrations tried for it: {tried or 'none'}"
        )
    return tuple(out)


def chain_report(
    result: ChainResult, config_yaml: str, runtime_s: float, topview: bytes, command: str = ""
) -> str:
    """The HTML report of a campaign, with its top view (PNG bytes); ``command``: the command
    line that ran it ('' for a library call: not shown)."""
    sol = result.solution
    verdict = judge(result)
    n_ok = sum(s.anchored for s in sol.scans)
    summary = (
        ("scans", f"{n_ok} of {len(sol.scans)} ok in the anchor's frame"),
        ("world frame", world_line(result).removeprefix("world frame = ")),
        ("link radius", "none" if np.isnan(result.radius) else f"{result.radius:.1f} m"),
        ("run time", f"{runtime_s:.1f} s"),
    )
    links = tuple(
        link_row(result.names, k, STATE_WORDS[f.state], f)
        for k, f in zip(result.links, sol.links, strict=True)
    )
    tried = tuple(link_row(result.names, t.link, t.why.value, None) for t in result.tried)
    controls, note = _controls(result)
    return render(
        command,
        verdict=Verdict(result.ok, verdict.headline, verdict.remarks, verdict.level),
        summary=summary,
        network=_network(network_numbers(result), sol.adjusted),
        controls=controls,
        control_note=note if controls else "",
        scans=tuple(
            _scan_row(n, s, k == result.anchor)
            for k, (n, s) in enumerate(zip(result.names, sol.scans, strict=True))
        ),
        links=links,
        figures=(Figure(topview, _TOPVIEW),),
        cards=link_cards(result, links, tried),
        tried=tried,
        tried_note=_left_out(result),
        config_yaml=config_yaml,
        notes=_NOTES,
    )


_TOPVIEW = (
    "Plan of the registered scans (slice points) in the world frame: scanners (triangles: ok), "
    "control stations (diamonds, at their given coordinates), links by their state (solid: "
    "checked by a cycle, coloured by its residual; dashed blue: not checked; dashed red: "
    "rejected; grey: not used). The axes count metres from the origin their labels state."
)

_NOTES = (
    "Status of a scan: ok = tied to the anchor by kept links, its pose adjusted over every "
    "redundant link and pinned down (σ at most 0.2 m and 0.2°); suspect = reached only through "
    "links that neither passed their own quality gate nor were confirmed by the others, or "
    "free along some direction; unposed = no usable link. Only ok scans belong in the "
    "deliverables.",
    "State of a link: confirmed = on a cycle of links that agree within their uncertainties "
    "(chi-square, p = 0.999); not checked = kept on its own quality gate's word, no cycle "
    "passes through it (a second link to its scans would check it), or, where its gate "
    "doubted it, on the network's (its reason says why); rejected = disagrees with "
    "the others; not used = neither checkable nor passed by its gate. Registrations tried and "
    "left out are listed apart.",
)
