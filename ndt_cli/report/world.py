"""What the world frame of a campaign's poses is, for every output that says so: a line for
poses.txt, the console and the report, and the record of summary.json with the control
stations' given and adjusted coordinates."""

from __future__ import annotations

from typing import Any

from ndt_cli.io.crs import crs_name
from ndt_cli.io.matrices import quote_name
from ndt_cli.pipeline.datum import WorldFrame
from ndt_cli.pipeline.result import ChainResult


def world_summary(result: ChainResult) -> dict[str, Any]:
    """What the world frame is (:mod:`ndt_cli.pipeline.datum`) and, per control station,
    the given and adjusted coordinates of its scanner and their difference (cm)."""
    datum = result.solution.datum
    if datum is None:
        return {"frame": f"the anchor's own: {result.names[result.anchor]}", "controls": []}
    rows = []
    for fit in datum.controls:
        c, r = fit.control, fit.residual
        rows.append(
            {
                "scan": c.name,
                "given": c.xyz.tolist(),
                "sigma_xy": c.sigma_xy,
                "sigma_z": c.sigma_z,
                "adjusted": None if fit.adjusted is None else fit.adjusted.tolist(),
                "residual_cm": None if r is None else [round(100 * v, 2) for v in r],
                "used": fit.used,
                "reason": fit.reason,
            }
        )
    return {
        "frame": datum.frame,
        "anchor": result.names[result.anchor],
        "crs": result.crs or None,
        "grid_scale": result.grid_scale,
        "vertical_sigma_deg": datum.vertical_sigma_deg,
        "controls": rows,
    }


def world_line(result: ChainResult) -> str:
    """One line saying what the world frame of the poses is."""
    anchor = quote_name(result.names[result.anchor])
    datum = result.solution.datum
    if datum is None:
        return f"world frame = frame of {anchor}"
    if datum.frame is WorldFrame.CONTROL:
        used = sum(f.used for f in datum.controls)
        where = crs_name(result.crs) if result.crs else "the control's coordinates"
        return f"world frame = {where}, from {used} control station(s); z the vertical"
    if datum.frame is WorldFrame.CONTROL_HEADING:
        return f"world frame = the control's coordinates at one station, heading of {anchor}"
    if datum.frame is WorldFrame.LEVELLED:
        return f"world frame = frame of {anchor} tipped level about its ground point (z up)"
    return f"world frame = frame of {anchor} (georeferenced: kept as it is)"
