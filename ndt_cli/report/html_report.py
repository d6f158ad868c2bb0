"""``report.html`` of a run: the registration report a client reads, filled from the results.

One self-contained file (:mod:`ndt_cli.report.html`): summary and verdict, a table of scans
(status, pose, uncertainty), a table of links (kind, status, fit, residual after the
adjustment, warnings), the top view and the configuration used.
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Iterable
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

import numpy as np

from ndt_cli.core.transforms import yaw_of
from ndt_cli.report.html import Figure, HtmlReport, LinkRow, ScanRow, Verdict, render_html

if TYPE_CHECKING:  # a pair's report does not load the network's modules
    from ndt_cli.ndt.result import RegistrationResult
    from ndt_cli.pipeline.links import Link
    from ndt_cli.pipeline.result import ChainResult
    from ndt_cli.pipeline.solution import LinkFit, ScanPose


def _command() -> str:
    return shlex.join([sys.argv[0].rsplit("/", 1)[-1], *sys.argv[1:]])


def _version() -> str:
    from ndt_cli import __version__

    return f"ndt-cli {__version__}"


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _scan_row(name: str, scan: ScanPose, anchor: bool) -> ScanRow:
    T, sigma = scan.T_world_scan, scan.sigma
    pose = (None,) * 4 if T is None else (*T[:3, 3], float(np.degrees(yaw_of(T))))
    sd = (None,) * 4 if sigma is None else (*(100 * sigma[:3]), sigma[3])
    status = "anchor" if anchor and scan.status.value == "ok" else scan.status.value
    return ScanRow(name, status, *pose, *sd, reason=scan.reason)


def _link_row(result: ChainResult, link: Link, fit: LinkFit) -> LinkRow:
    r, res = link.result, fit.residual
    warnings = (link.reason,) if link.reason else ()
    if fit.state.value == "rejected" and fit.reason:
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
        icp_rms_cm=None if r is None else _finite(100 * r.icp_rms),
        residual_deg=None if res is None else res.rotation_deg,
        residual_cm=None if res is None else 100 * res.translation_m,
        warnings=warnings,
    )


def _world_line(result: ChainResult) -> str:
    from ndt_cli.report.chain_outputs import world_line

    return world_line(result)


def chain_report(result: ChainResult, config_yaml: str, runtime_s: float, topview: bytes) -> str:
    """The HTML report of an ``ndt-chain`` run, with its top view (PNG bytes)."""
    sol = result.solution
    not_ok = [result.names[k] for k, s in enumerate(sol.scans) if s.status.value != "ok"]
    verdict = Verdict(
        result.ok, "" if result.ok else f"{len(not_ok)} scan(s) not ok: {', '.join(not_ok)}"
    )
    states = [f.state.value for f in sol.links]
    solved = "adjusted; " if sol.adjusted else "chained, not adjusted; "
    summary = (
        ("scans", f"{len(sol.scans) - len(not_ok)} of {len(sol.scans)} ok"),
        ("world frame", _world_line(result).removeprefix("world frame = ")),
        *_control_rows(result),
        ("links", f"{len(result.links)}: " + _counts(k.kind.value for k in result.links)),
        ("network", solved + _counts(states)),
        ("link radius", "none" if np.isnan(result.radius) else f"{result.radius:.1f} m"),
        ("run time", f"{runtime_s:.1f} s"),
    )
    return _render(
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
    from ndt_cli.report.chain_outputs import world_summary

    rows = []
    for r in world_summary(result)["controls"]:
        given = " ".join(f"{v:.3f}" for v in r["given"])
        res = r["residual_cm"]
        misfit = "" if res is None else "; adjusted - given " + " ".join(f"{v:+.1f}" for v in res)
        used = "used" if r["used"] else f"not used: {r['reason']}"
        rows.append((f"control {r['scan']}", f"{given} m{misfit} cm; {used}"))
    return tuple(rows)


def register_report(result: RegistrationResult, config_yaml: str) -> str:
    """The HTML report of an ``ndt-register`` run (the target's frame is the world)."""
    T = result.T_target_source
    source_status = "ok" if result.ok else result.status.value
    reason = "; ".join(result.warnings)
    target, source = result.labels
    scans = (
        ScanRow(target, "anchor", 0.0, 0.0, 0.0, 0.0),
        ScanRow(source, source_status, *T[:3, 3], result.yaw_deg, reason=reason),
    )
    link = LinkRow(
        kind="pair",
        target=target,
        source=source,
        status=result.status.value,
        score_per_point=result.score_per_point,
        overlap=result.overlap,
        ambiguity=result.ambiguity,
        icp_rms_cm=_finite(100 * result.icp_rms),
        warnings=result.warnings,
    )
    verdict = Verdict(result.ok, "" if result.ok else f"{result.status.value}")
    summary = (("status", result.status.value), ("run time", f"{result.runtime_s:.1f} s"))
    return _render(
        verdict=verdict,
        summary=summary,
        scans=scans,
        links=(link,),
        config_yaml=config_yaml,
    )


def _counts(values: Iterable[str]) -> str:
    out: dict[str, int] = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return ", ".join(f"{n} {k}" for k, n in out.items())


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


def _render(**content: Any) -> str:
    """The page of a run: ``content`` (verdict, summary, tables, ...) under the header every
    report shares (the command, the time in UTC, the version)."""
    created = datetime.now(UTC).replace(microsecond=0)
    report = HtmlReport(
        title="Registration report",
        command=_command(),
        created=created,
        version=_version(),
        **content,
    )
    return render_html(report)
