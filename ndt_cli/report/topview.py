"""Top view of a chain: every scan's slice points in the world frame, standpoints and links.

Needs matplotlib (extra ``[plot]``); without it, one notice is logged and no picture is made.
"""

from __future__ import annotations

from ndt_cli.pipeline.chain import ChainResult
from ndt_cli.report.figures import png_bytes, pyplot


def topview_png(result: ChainResult) -> bytes | None:
    """``topview.png``: slice points of every posed scan (from the pipeline's previews),
    standpoints, and links (green ok, red not ok); None without matplotlib."""
    plt = pyplot()
    if plt is None:
        return None
    fig, ax = plt.subplots(figsize=(10, 8), dpi=120)
    colours = plt.get_cmap("tab10")
    for k, T in enumerate(result.poses):
        if T is None:
            continue
        pts = result.previews.get(k)
        if pts is not None:
            w = pts @ T[:3, :3].T + T[:3, 3]
            ax.scatter(w[:, 0], w[:, 1], s=0.3, color=colours(k % 10), label=result.names[k])
        ax.plot(T[0, 3], T[1, 3], "k^", ms=7)
        ax.annotate(str(k), (T[0, 3], T[1, 3]), textcoords="offset points", xytext=(4, 4))
    for link in result.links:
        a, b = result.poses[link.target], result.poses[link.source]
        if a is not None and b is not None:
            style = "g-" if link.ok else "r--"
            ax.plot([a[0, 3], b[0, 3]], [a[1, 3], b[1, 3]], style, lw=1.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x world (m)")
    ax.set_ylabel("y world (m)")
    ax.set_title("Chained scans (slice points), standpoints and links (green ok, red not ok)")
    ax.legend(markerscale=20, fontsize="small", loc="best")
    return png_bytes(fig)
