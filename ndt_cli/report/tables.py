"""The CSV tables of results: one definition per column, shared by every file that has it.

``report.csv`` (ndt-register) and ``pairs.csv`` (ndt-chain) show the same metrics of a
registration with the same formatting; an empty cell is a value that does not exist (no ICP,
a failed link). Lengths are metres, angles degrees.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ndt_cli.core.transforms import yaw_of
from ndt_cli.ndt.result import RegistrationResult


def num(v: float, digits: int = 6) -> str:
    """A number with ``digits`` decimals; '' when it is NaN or infinite."""
    return "" if not np.isfinite(v) else f"{v:.{digits}f}"


def _joined(values: Any, fmt: str = "{:.6g}") -> str:
    return ";".join(fmt.format(v) for v in values)


# metric columns of a registration result, in the order the tables show them
METRICS: dict[str, Callable[[RegistrationResult], str]] = {
    "tx": lambda r: num(r.translation[0]),
    "ty": lambda r: num(r.translation[1]),
    "tz": lambda r: num(r.translation[2]),
    "yaw_deg": lambda r: num(r.yaw_deg),
    "score": lambda r: num(r.score, 4),
    "score_per_point": lambda r: num(r.score_per_point),
    "overlap": lambda r: num(r.overlap, 4),
    "ambiguity": lambda r: num(r.ambiguity, 4),
    "overlap_3d": lambda r: num(r.overlap_3d, 4),
    "icp_rms": lambda r: num(r.icp_rms, 5),
    "icp_inliers": lambda r: str(r.icp_inliers),
    "free_space": lambda r: num(r.free_space, 4),
    "tilt_target_deg": lambda r: num(_tilt(r.level_target), 4),
    "tilt_source_deg": lambda r: num(_tilt(r.level_source), 4),
    "hessian_eigenvalues": lambda r: _joined(r.hessian_eigenvalues),
    "icp_hessian_eigenvalues": lambda r: _joined(r.icp_hessian_eigenvalues),
    "degenerate": lambda r: r.degenerate,
    "points_per_slice": lambda r: _joined(r.points_per_slice, "{}"),
    "iterations_per_level": lambda r: _joined((lv.iterations for lv in r.levels), "{}"),
    "iterations": lambda r: str(r.iterations),
    "converged": lambda r: str(r.converged).lower(),
    "status": lambda r: r.status.value,
    "warnings": lambda r: " | ".join(r.warnings),
    "notes": lambda r: " | ".join(r.notes),
    "runtime_s": lambda r: f"{r.runtime_s:.3f}",
}


def _tilt(level: np.ndarray) -> float:
    """Angle (degrees) between a scan's z axis and the vertical it was levelled to."""
    return float(np.degrees(np.arccos(np.clip(level[2, 2], -1.0, 1.0))))


# what a link without a result (failed) shows in the metric columns
_FAILED = {"icp_inliers": "0", "iterations": "0", "converged": "false", "runtime_s": "0.000"}


def _names(*lines: str) -> tuple[str, ...]:
    """Column names written as words."""
    return tuple(word for line in lines for word in line.split())


_POSE_AND_FIT = (
    "tx ty tz yaw_deg score score_per_point overlap ambiguity overlap_3d icp_rms icp_inliers "
    "free_space tilt_target_deg tilt_source_deg"
)
REPORT_COLUMNS = _names(
    "target source",
    _POSE_AND_FIT,
    "hessian_eigenvalues icp_hessian_eigenvalues degenerate points_per_slice",
    "iterations_per_level converged status warnings notes runtime_s",
)
PAIR_COLUMNS = _names(
    "link target source",
    _POSE_AND_FIT,
    "degenerate iterations converged runtime_s status reason notes",
    "kind network residual_deg residual_cm network_reason",
)
POSE_COLUMNS = _names(
    "scan file has_pose x y z yaw_deg",
    *(f"m{r}{c}" for r in range(4) for c in range(4)),
    "status cluster sigma_x_cm sigma_y_cm sigma_z_cm sigma_yaw_deg tilt_deg reason",
)


def metrics(result: RegistrationResult | None, columns: tuple[str, ...]) -> dict[str, str]:
    """The metric cells of ``columns`` for a result (None: a failed link)."""
    names = [c for c in columns if c in METRICS]
    if result is None:
        return {c: _FAILED.get(c, "") for c in names}
    return {c: METRICS[c](result) for c in names}


def report_row(result: RegistrationResult) -> dict[str, Any]:
    """The row of ``report.csv`` of a registration."""
    target, source = result.labels
    return {"target": target, "source": source, **metrics(result, REPORT_COLUMNS)}


def pair_row(
    link: Any, names: tuple[str, ...], fit: Any = None, left_out: Any = None
) -> dict[str, Any]:
    """The row of ``pairs.csv`` of a campaign's link (``names``: the scans' names; ``fit``:
    what the network made of it, a :class:`~ndt_cli.pipeline.solution.LinkFit`; ``left_out``:
    for a registration tried and left out of the network, why, a
    :class:`~ndt_cli.pipeline.result.Dropped`)."""
    row = {"link": link.index, "target": names[link.target], "source": names[link.source]}
    row.update(metrics(link.result, PAIR_COLUMNS))
    row.update(status=link.status.value, reason=link.reason, kind=link.kind.value)
    residual = None if fit is None else fit.residual
    row["network"] = "" if fit is None else fit.state.value
    row["network_reason"] = "" if fit is None else fit.reason
    if left_out is not None:
        row["network"], row["network_reason"] = left_out.value, left_out.reason
    row["residual_deg"] = "" if residual is None else num(residual.rotation_deg, 4)
    row["residual_cm"] = "" if residual is None else num(100 * residual.translation_m, 2)
    return row


def pose_row(
    k: int, name: str, T: np.ndarray | None, scan: Any = None, level: np.ndarray | None = None
) -> dict[str, Any]:
    """The row of ``poses.csv`` of scan ``k``: its name, T_world_scan (empty without one) and,
    from the network (a :class:`~ndt_cli.pipeline.solution.ScanPose`), its status, 1-sigma
    uncertainty and why it is not ok; ``level``: its levelling rotation (its tilt from the
    vertical), None when no link prepared it."""
    row: dict[str, Any] = {"scan": k, "file": name, "has_pose": str(T is not None).lower()}
    M = T if T is not None else np.full((4, 4), np.nan)
    row.update(x=num(M[0, 3]), y=num(M[1, 3]), z=num(M[2, 3]))
    row["yaw_deg"] = num(np.degrees(yaw_of(M))) if T is not None else ""
    row.update(
        {f"m{r}{c}": ("" if T is None else f"{M[r, c]:.17g}") for r in range(4) for c in range(4)}
    )
    sigma = None if scan is None else scan.sigma
    row["status"] = "" if scan is None else scan.status.value
    cluster = None if scan is None else scan.cluster
    row["cluster"] = "" if cluster is None else str(cluster)
    row["tilt_deg"] = "" if level is None else num(_tilt(level), 4)
    row["reason"] = "" if scan is None else scan.reason
    for key, value, scale, digits in zip(
        ("sigma_x_cm", "sigma_y_cm", "sigma_z_cm", "sigma_yaw_deg"),
        sigma if sigma is not None else [np.nan] * 4,
        (100, 100, 100, 1),
        (2, 2, 2, 4),
        strict=True,
    ):
        row[key] = num(scale * value, digits)
    return row
