"""``report.html`` of a run: the registration report a client reads, filled from the results.

One self-contained file (:mod:`ndt_cli.report.html`). Here: a pair's report (its verdict, the
two scans, the link with its fit and strength, the configuration) and the header every report
shares; a campaign's is :mod:`ndt_cli.report.html_chain`.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

import numpy as np

from ndt_cli.report.html import HtmlReport, LinkRow, ScanRow, Verdict, render_html

if TYPE_CHECKING:
    from ndt_cli.ndt.result import RegistrationResult


def _version() -> str:
    from ndt_cli import __version__

    return f"ndt-cli {__version__}"


def finite(v: float) -> float | None:
    """``v``, or None (no value) when it is not finite."""
    return float(v) if np.isfinite(v) else None


def register_report(result: RegistrationResult, config_yaml: str, command: str = "") -> str:
    """The HTML report of an ``ndt-register`` run (the target's frame is the world);
    ``command``: the command line that ran it ('' for a library call: not shown)."""
    from ndt_cli.report.network_numbers import link_strength

    T = result.T_target_source
    reason = "; ".join(result.warnings)
    target, source = result.labels
    scans = (
        ScanRow(target, "anchor", 0.0, 0.0, 0.0, 0.0),
        ScanRow(source, result.status.value, *T[:3, 3], result.yaw_deg, reason=reason),
    )
    link = LinkRow(
        kind="pair",
        target=target,
        source=source,
        status=result.status.value,
        score_per_point=result.score_per_point,
        overlap=result.overlap,
        ambiguity=result.ambiguity,
        icp_rms_cm=finite(100 * result.icp_rms),
        warnings=result.warnings,
        strength_mm=link_strength(result).as_mm(),
    )
    verdict = Verdict(result.ok, "" if result.ok else f"{result.status.value}")
    summary = (("status", result.status.value), ("run time", f"{result.runtime_s:.1f} s"))
    return render(
        command,
        verdict=verdict,
        summary=summary,
        scans=scans,
        links=(link,),
        config_yaml=config_yaml,
    )


def render(command: str, **content: Any) -> str:
    """The page of a run: ``content`` (verdict, summary, tables, ...) under the header every
    report shares (the command, the time in UTC, the version)."""
    created = datetime.now(UTC).replace(microsecond=0)
    report = HtmlReport(
        title="Registration report",
        command=command,
        created=created,
        version=_version(),
        **content,
    )
    return render_html(report)
