"""Top view of a campaign: every posed scan's slice points in the world frame, the scanner
positions marked by status, and every link coloured by its residual after the adjustment.

Needs matplotlib (extra ``[plot]``); without it, one notice is logged and no picture is made.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ndt_cli.pipeline.chain import ChainResult
from ndt_cli.report.figures import png_bytes, pyplot

_MARKERS = {"ok": ("^", "black"), "suspect": ("s", "darkorange")}


def _points(ax: Any, result: ChainResult, colours: Any) -> None:
    for k, scan in enumerate(result.solution.scans):
        T, pts = scan.T_world_scan, result.previews.get(k)
        if T is None:
            continue
        if pts is not None:
            w = pts @ T[:3, :3].T + T[:3, 3]
            # markers of one line, not a scatter: the same dots, drawn in a fraction of the time
            ax.plot(
                w[:, 0], w[:, 1], ".", ms=1.6, mew=0, color=colours(k % 10), label=result.names[k]
            )
        marker, colour = _MARKERS.get(scan.status.value, ("x", "red"))
        ax.plot(T[0, 3], T[1, 3], marker, color=colour, ms=8)
        label = str(k) if scan.status.value == "ok" else f"{k} {scan.status.value}"
        ax.annotate(label, (T[0, 3], T[1, 3]), textcoords="offset points", xytext=(4, 4))


def _links(ax: Any, result: ChainResult, plt: Any) -> Any:
    """Draw the links; returns the colour mapping of the residuals (for a colour bar)."""
    sol, poses = result.solution, result.poses
    res = [
        f.residual.translation_m * 100
        for f in sol.links
        if f.residual is not None and f.state.value != "rejected"
    ]
    top = max(1.0, float(np.percentile(res, 95))) if res else 1.0
    cmap = plt.get_cmap("viridis")
    for link, fit in zip(result.links, sol.links, strict=True):
        a, b = poses[link.target], poses[link.source]
        if a is None or b is None:
            continue
        xy = ([a[0, 3], b[0, 3]], [a[1, 3], b[1, 3]])
        if fit.state.value == "rejected" or (not link.ok and fit.state.value == "unused"):
            ax.plot(*xy, "--", color="red", lw=1.2)
        elif fit.residual is None:
            ax.plot(*xy, "-", color="green" if link.ok else "grey", lw=1.5)
        else:
            ax.plot(*xy, "-", color=cmap(min(fit.residual.translation_m * 100 / top, 1.0)), lw=2)
    return plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(0, top)) if res else None


_MAX_IN = (11.0, 9.0)  # inches: the largest plot area (width, height)
_MIN_IN = (6.0, 4.0)  # inches: room for the title and the legend
_MARGIN_IN = (0.9, 0.7, 0.3, 0.55)  # inches: left, bottom, right, top (one title line)
_BAR_IN = 1.4  # inches right of the plot area for the colour bar and its label


def _layout(fig: Any, ax: Any, bar: bool, title_lines: int) -> Any:
    """Size the figure to the data's aspect with fixed margins (in inches) instead of cropping
    the saved image to what is drawn, which would draw the scans' points twice. Returns the
    colour bar's axes (None without ``bar``)."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)  # data height over width
    w = max(min(_MAX_IN[0], _MAX_IN[1] / aspect), _MIN_IN[0])
    h = max(min(_MAX_IN[1], w * aspect), _MIN_IN[1])
    left, bottom, right, top = _MARGIN_IN
    top += 0.25 * (title_lines - 1)
    right += _BAR_IN if bar else 0.0
    fw, fh = left + w + right, bottom + h + top
    fig.set_size_inches(fw, fh)
    ax.set_position([left / fw, bottom / fh, w / fw, h / fh])
    ax.set_aspect("equal", adjustable="datalim")  # the limits widen to fill the area
    if not bar:
        return None
    return fig.add_axes([(left + w + 0.25) / fw, (bottom + 0.2 * h) / fh, 0.2 / fw, 0.6 * h / fh])


def topview_png(result: ChainResult) -> bytes | None:
    """``topview.png``, or None without matplotlib."""
    plt = pyplot()
    if plt is None:
        return None
    fig = plt.figure(dpi=120)
    ax = fig.add_axes([0.0, 0.0, 1.0, 1.0])
    _points(ax, result, plt.get_cmap("tab10"))
    mapping = _links(ax, result, plt)
    not_ok = [
        result.names[k] for k, s in enumerate(result.solution.scans) if s.status.value != "ok"
    ]
    bar = _layout(fig, ax, mapping is not None, 2 if not_ok else 1)
    if mapping is not None:
        fig.colorbar(mapping, cax=bar, label="link residual after adjustment (cm)")
    ax.set_xlabel("x world (m)")
    ax.set_ylabel("y world (m)")
    ax.set_title(
        "Scans (slice points) and links (red dashed: rejected or failed)"
        + (f"\nnot ok: {', '.join(not_ok)}" if not_ok else "")
    )
    if result.previews:
        ax.legend(markerscale=6, fontsize="small", loc="best")
    return png_bytes(fig, tight=False)
