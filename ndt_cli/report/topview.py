"""Top view of a campaign (``topview.png``, the report's plan): every posed scan's slice points
in the world frame, the scanner positions marked by status, the control stations at their given
coordinates, and every link drawn by its state in the network (a checked link coloured by its
residual) (:mod:`ndt_cli.report.planview` draws it)."""

from __future__ import annotations

import numpy as np

from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.solution import LinkFit
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.report.planview import Edge, EdgeStyle, Scan, Scene, Station, origin_of, render
from ndt_cli.report.world import world_summary

_STYLES = {
    EdgeState.CONFIRMED: EdgeStyle.RESIDUAL,
    EdgeState.USED: EdgeStyle.UNCHECKED,
    EdgeState.REJECTED: EdgeStyle.REJECTED,
    EdgeState.UNUSED: EdgeStyle.UNUSED,
}


def _edge(link: Link, fit: LinkFit, a: np.ndarray, b: np.ndarray) -> Edge:
    style = _STYLES[fit.state]
    if style is EdgeStyle.RESIDUAL and fit.residual is not None:
        return Edge(a, b, style, fit.residual.translation_m * 100)
    return Edge(a, b, EdgeStyle.UNCHECKED if style is EdgeStyle.RESIDUAL else style)


def stations_of(result: ChainResult) -> tuple[Station, ...]:
    """The control stations at their given coordinates, when the world is the control's."""
    datum = result.solution.datum
    if datum is None or not datum.frame.from_control:
        return ()
    rows = world_summary(result)["controls"]
    return tuple(Station(r["scan"], np.array(r["given"][:2]), bool(r["used"])) for r in rows)


def scene_of(result: ChainResult) -> Scene:
    """The scans, links, stations and title of a chain's result."""
    scans = []
    for k, s in enumerate(result.solution.scans):
        T, pts = s.T_world_scan, result.previews.get(k)
        pos = None if T is None else T[:2, 3].copy()
        world = None if T is None or pts is None else (pts @ T[:3, :3].T + T[:3, 3])[:, :2]
        scans.append(Scan(result.names[k], k, s.status, pos, world))
    edges, res = [], []
    for link, fit in zip(result.links, result.solution.links, strict=True):
        a, b = scans[link.target].position, scans[link.source].position
        if a is not None and b is not None:
            edges.append(_edge(link, fit, a, b))
            res += [edges[-1].residual_cm] if edges[-1].style is EdgeStyle.RESIDUAL else []
    top = max(1.0, float(np.percentile(res, 95))) if res else None
    not_ok = [s.name for s in scans if s.status is not NodeStatus.OK]
    stations = stations_of(result)
    where = [s.position for s in scans if s.position is not None] + [s.xy for s in stations]
    title = ("Scans (slice points), scanners and links by their state in the network",)
    return Scene(
        tuple(scans),
        tuple(edges),
        top,
        title + ((f"not ok: {', '.join(not_ok)}",) if not_ok else ()),
        origin_of(np.array(where).reshape(-1, 2)),
        stations,
    )


def topview_png(result: ChainResult) -> bytes:
    """``topview.png`` of a chain's result."""
    return render(scene_of(result))
