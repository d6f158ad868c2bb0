"""Writing results: transform text, CSV report, JSON, the config used, and the console summary.

Every file is written atomically (temporary file, then rename): a failed run leaves the
previous results untouched and never a half-written file.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli import atomic
from ndt_cli.config import Config, dump
from ndt_cli.result import RegistrationResult
from ndt_cli.transforms import format_matrix

REPORT_COLUMNS = (
    "target",
    "source",
    "tx",
    "ty",
    "tz",
    "yaw_deg",
    "score",
    "score_per_point",
    "overlap",
    "ambiguity",
    "overlap_3d",
    "icp_rms",
    "icp_inliers",
    "hessian_eigenvalues",
    "icp_hessian_eigenvalues",
    "degenerate",
    "points_per_slice",
    "iterations_per_level",
    "converged",
    "status",
    "warnings",
    "runtime_s",
)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def to_json(data: dict[str, Any]) -> str:
    """Pretty JSON text (numpy values converted)."""
    return json.dumps(data, indent=2, default=_json_default) + "\n"


def report_row(result: RegistrationResult) -> dict[str, Any]:
    """One CSV row of a registration (metres, degrees)."""
    tx, ty, tz = result.translation
    return {
        "target": result.target,
        "source": result.source,
        "tx": f"{tx:.6f}",
        "ty": f"{ty:.6f}",
        "tz": f"{tz:.6f}",
        "yaw_deg": f"{result.yaw_deg:.6f}",
        "score": f"{result.score:.4f}",
        "score_per_point": f"{result.score_per_point:.6f}",
        "overlap": f"{result.overlap:.4f}",
        "ambiguity": f"{result.ambiguity:.4f}",
        "overlap_3d": f"{result.overlap_3d:.4f}",
        "icp_rms": f"{result.icp_rms:.5f}",
        "icp_inliers": str(result.icp_inliers),
        "hessian_eigenvalues": ";".join(f"{v:.6g}" for v in result.hessian_eigenvalues),
        "icp_hessian_eigenvalues": ";".join(f"{v:.6g}" for v in result.icp_hessian_eigenvalues),
        "degenerate": result.degenerate,
        "points_per_slice": ";".join(str(n) for n in result.points_per_slice),
        "iterations_per_level": ";".join(str(level.iterations) for level in result.levels),
        "converged": str(result.converged).lower(),
        "status": result.status,
        "warnings": " | ".join(result.warnings),
        "runtime_s": f"{result.runtime_s:.3f}",
    }


def csv_text(rows: list[dict[str, Any]], columns: tuple[str, ...]) -> str:
    """CSV text with a header line."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def write_register_outputs(
    out_dir: str | Path, result: RegistrationResult, cfg: Config
) -> list[Path]:
    """Write T_target_source.txt, report.csv, result.json and config_used.yaml into ``out_dir``."""
    out = Path(out_dir)
    files = {
        "T_target_source.txt": format_matrix(result.T_target_source),
        "report.csv": csv_text([report_row(result)], REPORT_COLUMNS),
        "result.json": to_json(result.to_dict()),
        "config_used.yaml": dump(cfg),
    }
    for name, text in files.items():
        atomic.write_text(out / name, text)
    return [out / name for name in files]


def print_summary(result: RegistrationResult, console: Any) -> None:
    """A rich table of the result and its levels."""
    from rich.table import Table

    tx, ty, tz = result.translation
    head = Table(title=f"{result.source} -> {result.target}", show_header=False)
    head.add_row("status", result.status)
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
