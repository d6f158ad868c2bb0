"""Top view of a campaign (``topview.png``): every posed scan's slice points in the world frame,
the scanner positions marked by status, and every link coloured by its residual after the
adjustment (:mod:`ndt_cli.report.planview` draws it)."""

from __future__ import annotations

import numpy as np

from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.solution import LinkFit
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.report.planview import Edge, EdgeStyle, Scan, Scene, render


def _edge(link: Link, fit: LinkFit, a: np.ndarray, b: np.ndarray) -> Edge:
    if fit.state is EdgeState.REJECTED or (not link.ok and fit.state is EdgeState.UNUSED):
        return Edge(a, b, EdgeStyle.REJECTED)
    if fit.residual is None:
        return Edge(a, b, EdgeStyle.OK if link.ok else EdgeStyle.FAILED)
    return Edge(a, b, EdgeStyle.RESIDUAL, fit.residual.translation_m * 100)


def scene_of(result: ChainResult) -> Scene:
    """The scans, links and title of a chain's result."""
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
    title = ("Scans (slice points) and links (red dashed: rejected or failed)",)
    return Scene(
        tuple(scans),
        tuple(edges),
        top,
        title + ((f"not ok: {', '.join(not_ok)}",) if not_ok else ()),
    )


def topview_png(result: ChainResult) -> bytes:
    """``topview.png`` of a chain's result."""
    return render(scene_of(result))
