"""Outputs of a chain: pairs.csv, poses.csv, poses.txt, one T_<target>_<source>.txt per link,
config_used.yaml, summary.json and (with matplotlib) topview.png. All written atomically."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli import atomic
from ndt_cli.chain import ChainResult, Link
from ndt_cli.config import Config, dump
from ndt_cli.report import csv_text, to_json
from ndt_cli.transforms import format_matrix, yaw_of

log = logging.getLogger(__name__)

PAIR_COLUMNS = (
    "link", "target", "source", "tx", "ty", "tz", "yaw_deg", "score", "score_per_point",
    "overlap", "ambiguity", "overlap_3d", "icp_rms", "icp_inliers", "degenerate", "iterations",
    "converged", "runtime_s", "status", "reason",
)  # fmt: skip
POSE_COLUMNS = (
    "scan", "file", "has_pose", "x", "y", "z", "yaw_deg",
    *(f"m{r}{c}" for r in range(4) for c in range(4)),
)  # fmt: skip


def _num(v: float, digits: int = 6) -> str:
    return "" if not np.isfinite(v) else f"{v:.{digits}f}"


def pair_row(link: Link, scans: tuple[Path, ...]) -> dict[str, Any]:
    T = link.T_target_source
    t = T[:3, 3] if T is not None else np.full(3, np.nan)
    return {
        "link": link.index,
        "target": scans[link.target].name,
        "source": scans[link.source].name,
        "tx": _num(t[0]),
        "ty": _num(t[1]),
        "tz": _num(t[2]),
        "yaw_deg": _num(np.degrees(yaw_of(T))) if T is not None else "",
        "score": _num(link.score, 4),
        "score_per_point": _num(link.score_per_point),
        "overlap": _num(link.overlap, 4),
        "ambiguity": _num(link.ambiguity, 4),
        "overlap_3d": _num(link.overlap_3d, 4),
        "icp_rms": _num(link.icp_rms, 5),
        "icp_inliers": link.icp_inliers,
        "degenerate": link.degenerate,
        "iterations": link.iterations,
        "converged": str(link.converged).lower(),
        "runtime_s": f"{link.runtime_s:.3f}",
        "status": link.status,
        "reason": link.reason,
    }


def pose_row(k: int, path: Path, T: np.ndarray | None) -> dict[str, Any]:
    row: dict[str, Any] = {"scan": k, "file": path.name, "has_pose": str(T is not None).lower()}
    M = T if T is not None else np.full((4, 4), np.nan)
    row.update(x=_num(M[0, 3]), y=_num(M[1, 3]), z=_num(M[2, 3]))
    row["yaw_deg"] = _num(np.degrees(yaw_of(M))) if T is not None else ""
    row.update(
        {f"m{r}{c}": ("" if T is None else f"{M[r, c]:.17g}") for r in range(4) for c in range(4)}
    )
    return row


def link_file_name(link: Link, scans: tuple[Path, ...]) -> str:
    return f"T_{scans[link.target].stem}_{scans[link.source].stem}.txt"


def summary(result: ChainResult, runtime_s: float) -> dict[str, Any]:
    statuses = [link.status for link in result.links]
    return {
        "scans": [str(p) for p in result.scans],
        "anchor": result.anchor,
        "links": len(result.links),
        "ok": statuses.count("ok"),
        "suspect": statuses.count("suspect"),
        "degenerate": statuses.count("degenerate"),
        "failed": len(statuses) - sum(statuses.count(s) for s in ("ok", "suspect", "degenerate")),
        "unreadable": {result.scans[i].name: r for i, r in result.unreadable.items()},
        "scans_without_pose": [
            result.scans[i].name for i, T in enumerate(result.poses) if T is None
        ],
        "all_ok": result.ok,
        "reused": len(result.reused),
        "runtime_s": runtime_s,
    }


def write_chain_outputs(out: Path, result: ChainResult, cfg: Config, runtime_s: float) -> None:
    """Write every chain output file into ``out``."""
    scans = result.scans
    atomic.write_text(
        out / "pairs.csv", csv_text([pair_row(k, scans) for k in result.links], PAIR_COLUMNS)
    )
    atomic.write_text(
        out / "poses.csv",
        csv_text(
            [pose_row(k, p, T) for k, (p, T) in enumerate(zip(scans, result.poses, strict=True))],
            POSE_COLUMNS,
        ),
    )
    lines = [
        "# T_world_scan per scan: file name, then 16 numbers of the 4x4, row-major (metres)",
        f"# world frame = frame of {scans[result.anchor].name}; scans without a pose omitted",
    ]
    lines += [
        f"{p.name} " + " ".join(f"{v:.17g}" for v in T.ravel())
        for p, T in zip(scans, result.poses, strict=True)
        if T is not None
    ]
    atomic.write_text(out / "poses.txt", "\n".join(lines) + "\n")
    for link in result.links:
        if link.T_target_source is not None:
            atomic.write_text(
                out / link_file_name(link, scans), format_matrix(link.T_target_source)
            )
    from ndt_cli.e57 import header_poses

    stored = header_poses(list(scans))
    if stored:  # reported only: registration never uses them
        lines = [
            "# Poses stored in the E57 scan headers (ignored for registration): scan, then",
            "# the 16 numbers of the 4x4 (scan frame to the E57 file frame), row-major",
        ]
        lines += [f"{scans[k].name} " + " ".join(f"{v:.17g}" for v in T.ravel())
                  for k, T in stored.items()]  # fmt: skip
        atomic.write_text(out / "e57_header_poses.txt", "\n".join(lines) + "\n")
    atomic.write_text(out / "config_used.yaml", dump(cfg))
    atomic.write_text(out / "summary.json", to_json(summary(result, runtime_s)))


def write_topview(out: Path, result: ChainResult, cfg: Config) -> Path | None:
    """Top view of every scan's slice points in the world frame, standpoints and links.

    Needs matplotlib (extra ``[plot]``); without it, logs one notice and returns None.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log.warning(
            "matplotlib is not installed (pip install 'ndt-cli[plot]'): topview.png skipped"
        )
        return None
    from ndt_cli.chain import preview
    from ndt_cli.prepare import load_and_prepare

    fig, ax = plt.subplots(figsize=(10, 8), dpi=120)
    colours = plt.get_cmap("tab10")
    for k, T in enumerate(result.poses):
        if T is None:
            continue
        pts = result.previews.get(k)
        if pts is None:
            pts = preview(load_and_prepare(result.scans[k], cfg))
        w = pts @ T[:3, :3].T + T[:3, 3]
        ax.scatter(w[:, 0], w[:, 1], s=0.3, color=colours(k % 10), label=result.scans[k].name)
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
    path = out / "topview.png"
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)
    return path


def print_chain_summary(result: ChainResult, console: Any) -> None:
    """A rich table with one row per link."""
    from rich.table import Table

    table = Table(
        "link",
        "target",
        "source",
        "tx (m)",
        "ty (m)",
        "yaw (deg)",
        "score/pt",
        "overlap",
        "status",
        title="ndt-chain",
    )
    for link in result.links:
        row = pair_row(link, result.scans)
        table.add_row(
            str(link.index),
            row["target"],
            row["source"],
            row["tx"][:9],
            row["ty"][:9],
            row["yaw_deg"][:9],
            row["score_per_point"][:6],
            row["overlap"][:5],
            link.status if not link.reason else f"{link.status}: {link.reason}",
        )
    console.print(table)
