"""Summaries printed on the terminal (rich tables): a registration, a campaign
(:mod:`ndt_cli.report.console_chain`), an evaluation."""

from __future__ import annotations

from typing import Any

from ndt_cli.ndt.result import RegistrationResult
from ndt_cli.report.console_chain import print_chain_summary

__all__ = ["print_chain_summary", "print_evaluation", "print_summary"]


def print_summary(result: RegistrationResult, console: Any) -> None:
    """A rich table of a registration and its levels."""
    from rich.table import Table

    tx, ty, tz = result.translation
    target, source = result.labels
    head = Table(title=f"{source} -> {target}", show_header=False)
    head.add_row("status", result.status.value)
    head.add_row("translation (m)", f"{tx:.4f}  {ty:.4f}  {tz:.4f}")
    head.add_row("yaw (deg)", f"{result.yaw_deg:.4f}")
    head.add_row("score / point", f"{result.score_per_point:.4f}")
    head.add_row("overlap", f"{result.overlap:.3f}")
    head.add_row("second candidate / best", f"{result.ambiguity:.3f}")
    if result.icp_hessian is not None:
        head.add_row("ICP inlier RMS (m)", f"{result.icp_rms:.4f} ({result.icp_inliers} inliers)")
        head.add_row("3D overlap", f"{result.overlap_3d:.3f}")
    if result.degenerate:
        head.add_row("degenerate", result.degenerate)
    head.add_row("runtime (s)", f"{result.runtime_s:.2f}")
    for warning in result.warnings:
        head.add_row("warning", warning)
    console.print(head)
    levels = Table("cell (m)", "starts", "iterations", "score", "score/point", "time (s)")
    for lv in result.levels:
        levels.add_row(
            f"{lv.cell_size:g}",
            str(lv.starts),
            str(lv.iterations),
            f"{lv.score:.1f}",
            f"{lv.score_per_point:.4f}",
            f"{lv.time_s:.2f}",
        )
    console.print(levels)


def _rates(label: str, success: list, n: int, console: Any) -> None:
    """One line per threshold: the share within it, of ``n``."""
    for s in success:
        if s["success_rate"] is None:
            continue
        within = round(s["success_rate"] * n)
        console.print(
            f"{label} within {s['max_rotation_deg']:g} deg / {100 * s['max_translation_m']:g} cm: "
            f"{100 * s['success_rate']:.0f} % ({within} of {n})",
            soft_wrap=False,
            markup=False,
        )


_WORDS = {"used": "not checked", "unused": "not used"}  # the network states, as the report says


def _deg_cm(row: dict) -> tuple[str, str]:
    rot, trans = row["rotation_error_deg"], row["translation_error_m"]
    if rot is None:
        return "", ""
    return f"{rot:.4f}", f"{100 * trans:.2f}"


def print_evaluation(ev: Any, console: Any) -> None:
    """Per-link and per-scan errors, their success rates, the scans the result lacks and the
    end-of-chain drift of an evaluation (errors in degrees and centimetres)."""
    from ndt_cli.analysis.accuracy import KEPT
    from ndt_cli.report.console_fit import Col, print_fitted, styled

    links = ev.links
    errors = [_deg_cm(r) for r in links]
    cols = [Col("target <- source", [f"{r['target']} <- {r['source']}" for r in links])]
    if any("network" in r for r in links):
        words = [_WORDS.get(r.get("network", ""), r.get("network", "")) for r in links]
        cols.append(Col("network", [styled(w) for w in words]))
    cols += [
        Col("rotation\nerror (deg)", [e[0] for e in errors], justify="right"),
        Col("translation\nerror (cm)", [e[1] for e in errors], justify="right"),
    ]
    if links:
        print_fitted(console, [cols], "ndt-eval: links")
    judged = [r for r in links if r.get("network", KEPT[0]) in KEPT]
    _rates("kept links", ev.success, len(judged), console)
    if len(judged) < len(links):
        left = len(links) - len(judged)
        console.print(f"{left} link(s) not kept by the network: not judged", soft_wrap=False)
    if ev.scans:
        errors = [_deg_cm(r) for r in ev.scans]
        scans = [
            Col("scan", [r["scan"] for r in ev.scans]),
            Col("status", [styled(r["status"]) for r in ev.scans]),
            Col("rotation\nerror (deg)", [e[0] for e in errors], justify="right"),
            Col("translation\nerror (cm)", [e[1] for e in errors], justify="right"),
        ]
        print_fitted(console, [scans], f"ndt-eval: scans, relative to {ev.anchor}")
        _rates("scans ok and", ev.scan_success, len(ev.scans), console)
    if ev.missing:
        console.print(
            f"the result lacks {len(ev.missing)} scan(s) of the reference: {', '.join(ev.missing)}",
            soft_wrap=False,
            markup=False,
        )
    for label, d in (("end-of-chain drift", ev.drift), ("chained, not adjusted", ev.drift_chained)):
        if d:
            console.print(
                f"{label} ({d['to']} in the frame of {d['from']}): "
                f"{d['rotation_error_deg']:.4f} deg, {100 * d['translation_error_m']:.2f} cm",
                soft_wrap=False,
                markup=False,
            )
