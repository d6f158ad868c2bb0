"""What the world frame of a campaign's poses is, for every output that says so: a line for
poses.txt, the console and the report (with the grid scale applied, and why the campaign is
not georeferenced when control was given and could not place it), the record of summary.json
with the control stations' given and adjusted coordinates, and field mode's words for its
first scan and its last lines."""

from __future__ import annotations

from typing import Any

from ndt_cli.io.crs import crs_name
from ndt_cli.io.matrices import quote_name
from ndt_cli.pipeline.control import Station, unmatched
from ndt_cli.pipeline.datum import ControlFit, WorldFrame
from ndt_cli.pipeline.result import ChainResult


def _fit_row(fit: ControlFit) -> dict[str, Any]:
    c, r = fit.control, fit.residual
    return {
        "scan": c.name,
        "given": c.xyz.tolist(),
        "sigma_xy": c.sigma_xy,
        "sigma_z": c.sigma_z,
        "adjusted": None if fit.adjusted is None else fit.adjusted.tolist(),
        "residual_cm": None if r is None else [round(100 * v, 2) for v in r],
        "used": fit.used,
        "reason": fit.reason,
    }


def _unmatched_row(s: Station, why: str) -> dict[str, Any]:
    return {
        "scan": s.name,
        "given": s.xyz.tolist(),
        "sigma_xy": s.sigma_xy,
        "sigma_z": s.sigma_z,
        "adjusted": None,
        "residual_cm": None,
        "used": False,
        "reason": f"line {s.line}: {why}",
    }


def world_summary(result: ChainResult) -> dict[str, Any]:
    """What the world frame is (:mod:`ndt_cli.pipeline.datum`); per control station, the given
    and adjusted coordinates of its scanner and their difference (cm); whether the campaign is
    georeferenced as its control asked (None without control) and why not."""
    datum = result.solution.datum
    rows = [_fit_row(f) for f in datum.controls] if datum is not None else []
    rows += [_unmatched_row(s, why) for s, why in unmatched(result.stations, result.names)]
    problem = result.not_georeferenced
    georeferenced = {
        "georeferenced": not problem if result.stations else None,
        "not_georeferenced": problem or None,
    }
    if datum is None:
        frame = f"the anchor's own: {result.names[result.anchor]}"
        return {"frame": frame, "crs": result.crs or None, "controls": rows, **georeferenced}
    return {
        "frame": datum.frame,
        "anchor": result.names[result.anchor],
        "crs": result.crs or None,
        "grid_scale": result.grid_scale,
        "vertical_sigma_deg": datum.vertical_sigma_deg,
        "controls": rows,
        **georeferenced,
    }


def _frame_words(result: ChainResult) -> str:
    """What the world frame is, in words."""
    anchor = quote_name(result.names[result.anchor])
    datum = result.solution.datum
    where = crs_name(result.crs) if result.crs else "the control's coordinates"
    if datum is None:
        return f"frame of {anchor}"
    if datum.frame is WorldFrame.CONTROL:
        used = sum(f.used for f in datum.controls)
        return f"{where}, from {used} control station(s); z the vertical"
    if datum.frame is WorldFrame.CONTROL_HEADING:
        return f"{where} at one station, heading of {anchor}"
    if datum.frame is WorldFrame.LEVELLED:
        return f"frame of {anchor} tipped level about its ground point (z up)"
    return f"frame of {anchor} (georeferenced: kept as it is)"


def world_line(result: ChainResult) -> str:
    """One line saying what the world frame of the poses is: with the grid scale applied, and
    why the campaign is not georeferenced when its control could not place it."""
    line = f"world frame = {_frame_words(result)}"
    if result.grid_scale != 1.0:
        ppm = (result.grid_scale - 1.0) * 1e6
        line += f"; grid scale {result.grid_scale:.6f} applied ({ppm:+.0f} ppm)"
    problem = result.not_georeferenced
    return f"{line}; NOT GEOREFERENCED: {problem}" if problem else line


def first_scan_role(result: ChainResult) -> str:
    """What the first scan of a campaign is to its world frame, as field mode says it."""
    n = len(result.stations)
    if not n:
        return "it defines the world frame"
    where = crs_name(result.crs) if result.crs else "the control's coordinates"
    wait = "its station is in" if n == 1 else f"2 of its {n} stations are in"
    return f"the world frame will be {where}, once {wait}"


def closing_lines(result: ChainResult) -> list[str]:
    """What field mode says of the world as it stops, when control was given: the world line,
    and each control station whose scan never came."""
    if not result.stations:
        return []
    lines = [world_line(result)]
    for s, why in unmatched(result.stations, result.names):
        lines.append(f"control station {s.name} (line {s.line}) not used: {why}")
    return lines
