"""Summaries printed on the terminal (rich tables)."""

from __future__ import annotations

from typing import Any

from ndt_cli.ndt.result import RegistrationResult
from ndt_cli.pipeline.chain import ChainResult
from ndt_cli.report.tables import pair_row


def print_summary(result: RegistrationResult, console: Any) -> None:
    """A rich table of a registration and its levels."""
    from rich.table import Table

    tx, ty, tz = result.translation
    head = Table(title=f"{result.source} -> {result.target}", show_header=False)
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


def print_chain_summary(result: ChainResult, console: Any) -> None:
    """A rich table with one row per link."""
    from rich.table import Table

    columns = ("link", "target", "source", "tx (m)", "ty (m)", "yaw (deg)", "score/pt", "overlap")
    table = Table(*columns, "status", title="ndt-chain")
    for link in result.links:
        row = pair_row(link, result.names)
        table.add_row(
            str(link.index),
            row["target"],
            row["source"],
            row["tx"][:9],
            row["ty"][:9],
            row["yaw_deg"][:9],
            row["score_per_point"][:6],
            row["overlap"][:5],
            link.status.value if not link.reason else f"{link.status.value}: {link.reason}",
        )
    console.print(table)


def print_evaluation(ev: Any, console: Any) -> None:
    """Per-link errors, success rates and the end-of-chain drift of an evaluation."""
    from rich.table import Table

    table = Table(
        "target", "source", "rotation error (deg)", "translation error (cm)", title="ndt-eval"
    )
    for row in ev.links:
        table.add_row(
            row["target"],
            row["source"],
            f"{row['rotation_error_deg']:.4f}",
            f"{100 * row['translation_error_m']:.2f}",
        )
    console.print(table)
    for s in ev.success:
        console.print(
            f"success at {s['max_rotation_deg']:g} deg / {100 * s['max_translation_m']:g} cm: "
            f"{100 * s['success_rate']:.0f} %"
        )
    if ev.drift:
        d = ev.drift
        console.print(
            f"end-of-chain drift ({d['to']} in the frame of {d['from']}): "
            f"{d['rotation_error_deg']:.4f} deg, {100 * d['translation_error_m']:.2f} cm"
        )
