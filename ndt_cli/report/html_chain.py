"""``report.html`` of a campaign (``ndt-chain``, ``ndt-watch``): the verdict, the scans with
their status, pose and uncertainty, the links with their registration and their state in the
network, the top view and the notes that say what the statuses mean."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable

import numpy as np

from ndt_cli.core.transforms import yaw_of
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.solution import LinkFit, ScanPose
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.report.html import Figure, LinkRow, ScanRow, Verdict
from ndt_cli.report.html_report import finite, render
from ndt_cli.report.world import world_line, world_summary


def _scan_row(name: str, scan: ScanPose, anchor: bool) -> ScanRow:
    T, sigma = scan.T_world_scan, scan.sigma
    pose = (None,) * 4 if T is None else (*T[:3, 3], float(np.degrees(yaw_of(T))))
    sd = (None,) * 4 if sigma is None else (*(100 * sigma[:3]), sigma[3])
    status = "anchor" if anchor and scan.status is NodeStatus.OK else scan.status.value
    return ScanRow(name, status, *pose, *sd, reason=scan.reason)


def _link_row(result: ChainResult, link: Link, fit: LinkFit) -> LinkRow:
    r, res = link.result, fit.residual
    warnings = (link.reason,) if link.reason else ()
    if fit.state is EdgeState.REJECTED and fit.reason:
        warnings += (f"network: {fit.reason}",)
    return LinkRow(
        kind=link.kind.value,
        target=result.names[link.target],
        source=result.names[link.source],
        status=link.status.value,
        state=fit.state.value,
        score_per_point=None if r is None else r.score_per_point,
        overlap=None if r is None else r.overlap,
        ambiguity=None if r is None else r.ambiguity,
        icp_rms_cm=None if r is None else finite(100 * r.icp_rms),
        residual_deg=None if res is None else res.rotation_deg,
        residual_cm=None if res is None else 100 * res.translation_m,
        warnings=warnings,
    )


def chain_report(
    result: ChainResult, config_yaml: str, runtime_s: float, topview: bytes, command: str = ""
) -> str:
    """The HTML report of a campaign, with its top view (PNG bytes); ``command``: the command
    line that ran it ('' for a library call: not shown)."""
    sol = result.solution
    not_ok = [result.names[k] for k, s in enumerate(sol.scans) if s.status is not NodeStatus.OK]
    why = [f"{len(not_ok)} scan(s) not ok: {', '.join(not_ok)}"] if not_ok else []
    if result.not_georeferenced:
        why.append(f"not georeferenced: {result.not_georeferenced}")
    verdict = Verdict(result.ok, "; ".join(why))
    states = [f.state.value for f in sol.links]
    solved = "adjusted; " if sol.adjusted else "chained, not adjusted; "
    summary = (
        ("scans", f"{len(sol.scans) - len(not_ok)} of {len(sol.scans)} ok"),
        ("world frame", world_line(result).removeprefix("world frame = ")),
        *_control_rows(result),
        ("links", f"{len(result.links)}: " + _counts(k.kind.value for k in result.links)),
        ("network", solved + _counts(states)),
        ("link radius", "none" if np.isnan(result.radius) else f"{result.radius:.1f} m"),
        ("run time", f"{runtime_s:.1f} s"),
    )
    return render(
        command,
        verdict=verdict,
        summary=summary,
        scans=tuple(
            _scan_row(n, s, k == result.anchor)
            for k, (n, s) in enumerate(zip(result.names, sol.scans, strict=True))
        ),
        links=tuple(_link_row(result, k, f) for k, f in zip(result.links, sol.links, strict=True)),
        figures=(Figure(topview, _TOPVIEW),),
        config_yaml=config_yaml,
        notes=_NOTES,
    )


def _control_rows(result: ChainResult) -> tuple[tuple[str, str], ...]:
    """A summary row per control station: its given coordinates, the adjusted minus the given
    (cm: east, north, height) and whether the adjustment used it."""
    rows = []
    for r in world_summary(result)["controls"]:
        given = " ".join(f"{v:.3f}" for v in r["given"])
        res = r["residual_cm"]
        misfit = "" if res is None else "; adjusted - given " + " ".join(f"{v:+.1f}" for v in res)
        used = "used" if r["used"] else f"not used: {r['reason']}"
        rows.append((f"control {r['scan']}", f"{given} m{misfit}{' cm' if misfit else ''}; {used}"))
    return tuple(rows)


def _counts(values: Iterable[str]) -> str:
    """``"3 confirmed, 1 used"``: how often each value comes, in the order first seen."""
    return ", ".join(f"{n} {k}" for k, n in Counter(values).items())


_TOPVIEW = (
    "Top view of the registered scans (slice points) in the world frame; scanner positions "
    "marked, links coloured by their residual after the adjustment (red dashed: rejected or "
    "failed)."
)

_NOTES = (
    "Status of a scan: ok = connected to the anchor through accepted links (the pose is "
    "adjusted over every redundant link); suspect = reached only through links that neither "
    "passed their own quality gate nor were confirmed by the others; unposed = no usable link. "
    "Only ok scans belong in the deliverables.",
    "State of a link: confirmed = checked against the other links (a cycle) and consistent; "
    "used = accepted but not checkable (no cycle passes through it); rejected = inconsistent "
    "with the others (its residual exceeds what the links' uncertainties allow, chi-square "
    "p = 0.999); unused = not part of the adjustment.",
)
