"""Summaries printed on the terminal (rich tables)."""

from __future__ import annotations

from typing import Any

from ndt_cli.ndt.result import RegistrationResult
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.report.tables import pair_row


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


def print_chain_summary(result: ChainResult, console: Any) -> None:
    """A rich table with one row per link, and one per scan that is not ok."""
    from rich.table import Table

    columns = ("link", "kind", "target", "source", "tx (m)", "ty (m)", "yaw (deg)", "score/pt")
    table = Table(*columns, "status", "network", "residual (cm)", title="ndt-chain links")
    sol = result.solution
    for link, fit in zip(result.links, sol.links, strict=True):
        row = pair_row(link, result.names, fit)
        status = link.status.value if not link.reason else f"{link.status.value}: {link.reason}"
        table.add_row(
            str(link.index),
            link.kind.value,
            row["target"],
            row["source"],
            row["tx"][:9],
            row["ty"][:9],
            row["yaw_deg"][:9],
            row["score_per_point"][:6],
            status,
            row["network"] + (f": {fit.reason}" if fit.state is EdgeState.REJECTED else ""),
            row["residual_cm"],
        )
    console.print(table)
    bad = [(k, s) for k, s in enumerate(sol.scans) if s.status is not NodeStatus.OK]
    if bad:
        scans = Table("scan", "status", "reason", title="scans that are not ok")
        for k, s in bad:
            scans.add_row(result.names[k], s.status.value, s.reason)
        console.print(scans)
    _print_controls(result, console)
    n_ok = len(sol.scans) - len(bad)
    georeferenced = "; NOT GEOREFERENCED (see above)" if result.not_georeferenced else ""
    adjusted = " (adjusted)" if sol.adjusted else ""
    console.print(f"{n_ok} of {len(sol.scans)} scans ok{adjusted}{georeferenced}")


def _print_controls(result: Any, console: Any) -> None:
    """The control stations: given and adjusted coordinates, residual (cm), used or not."""
    from rich.table import Table

    from ndt_cli.report.world import world_line, world_summary

    rows = world_summary(result)["controls"]
    if rows:
        table = Table("scan", "given x y z (m)", "residual E N h (cm)", "used", title="control")
        for r in rows:
            res = r["residual_cm"]
            table.add_row(
                r["scan"],
                " ".join(f"{v:.3f}" for v in r["given"]),
                "" if res is None else " ".join(f"{v:+.1f}" for v in res),
                "yes" if r["used"] else f"no: {r['reason']}",
            )
        console.print(table)
    console.print(world_line(result), soft_wrap=False)  # long: wrapped at words


def print_evaluation(ev: Any, console: Any) -> None:
    """Per-link errors, success rates and the end-of-chain drift of an evaluation."""
    from rich.table import Table

    network = any("network" in row for row in ev.links)
    columns = ["target", "source", "rotation error (deg)", "translation error (cm)"]
    table = Table(*columns, *(["network"] if network else []), title="ndt-eval")
    for row in ev.links:
        cells = [row["target"], row["source"], f"{row['rotation_error_deg']:.4f}"]
        cells.append(f"{100 * row['translation_error_m']:.2f}")
        table.add_row(*cells, *([row.get("network", "")] if network else []))
    console.print(table)
    for s in ev.success:
        console.print(
            f"success at {s['max_rotation_deg']:g} deg / {100 * s['max_translation_m']:g} cm: "
            f"{100 * s['success_rate']:.0f} %"
        )
    for label, d in (("end-of-chain drift", ev.drift), ("chained, not adjusted", ev.drift_chained)):
        if d:
            console.print(
                f"{label} ({d['to']} in the frame of {d['from']}): "
                f"{d['rotation_error_deg']:.4f} deg, {100 * d['translation_error_m']:.2f} cm"
            )
