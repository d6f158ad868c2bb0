"""PNG plots of the analyses (matplotlib, optional extra ``[plot]``). Axes carry their units."""

from __future__ import annotations

from typing import Any

import numpy as np

from ndt_cli.report.figures import png_bytes
from ndt_cli.report.figures import pyplot as _pyplot


def rotation_plot(rows: list[dict[str, Any]], cell: float) -> bytes | None:
    plt = _pyplot()
    if plt is None:
        return None
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for k in sorted({r["slices"] for r in rows}):
        mine = [r for r in rows if r["slices"] == k]
        ax.plot(
            [r["rotation_deg"] for r in mine],
            [r["score_per_point"] for r in mine],
            label=f"{k} slice{'s' if k > 1 else ''}",
        )
    ax.set_xlabel("rotation of the source about its centre (deg)")
    ax.set_ylabel("NDT score per source point")
    ax.set_title(f"Score while rotating the aligned source, {cell:g} m cells")
    ax.legend()
    ax.grid(alpha=0.3)
    return png_bytes(fig, dpi=110)


def translation_plot(rows: list[dict[str, Any]], cell: float) -> bytes | None:
    plt = _pyplot()
    if plt is None:
        return None
    ks = sorted({r["slices"] for r in rows})
    fig, axes = plt.subplots(1, len(ks), figsize=(3.2 * len(ks), 3.6), squeeze=False)
    for ax, k in zip(axes[0], ks, strict=True):
        mine = [r for r in rows if r["slices"] == k]
        xs = np.unique([r["dx_m"] for r in mine])
        ys = np.unique([r["dy_m"] for r in mine])
        z = np.array([r["score_per_point"] for r in mine]).reshape(len(xs), len(ys))
        im = ax.imshow(z.T, origin="lower", extent=(xs[0], xs[-1], ys[0], ys[-1]), aspect="auto")
        ax.set_title(f"{k} slice{'s' if k > 1 else ''}")
        ax.set_xlabel("shift x (m)")
        ax.set_ylabel("shift y (m)")
    fig.colorbar(im, ax=axes[0].tolist(), label="score per source point")
    fig.suptitle(f"Score while shifting the aligned source, {cell:g} m cells")
    return png_bytes(fig, dpi=110)


def basin_plot(rows: list[dict[str, Any]], rates: list[dict[str, Any]]) -> bytes | None:
    plt = _pyplot()
    if plt is None:
        return None
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    for variant in dict.fromkeys(r["variant"] for r in rows):
        mine = [r for r in rows if r["variant"] == variant]
        a.scatter(
            [r["start_distance_m"] for r in mine],
            [max(r["final_error_m"], 1e-4) for r in mine],
            s=8,
            label=variant,
        )
        rr = [r for r in rates if r["variant"] == variant]
        b.plot(
            [0.5 * (r["start_distance_from_m"] + r["start_distance_to_m"]) for r in rr],
            [r["success_rate"] for r in rr],
            marker="o",
            label=variant,
        )
    a.set_yscale("log")
    a.set_xlabel("start offset (m)")
    a.set_ylabel("final translation error (m)")
    a.set_title("Where each start ends")
    b.set_xlabel("start offset (m)")
    b.set_ylabel("success rate")
    b.set_ylim(-0.05, 1.05)
    b.set_title("Success per start distance")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    return png_bytes(fig, dpi=110)


def optimizer_plot(rows: list[dict[str, Any]]) -> bytes | None:
    plt = _pyplot()
    if plt is None:
        return None
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    panels = [
        ("score", "NDT score"),
        ("tx_m", "tx (m)"),
        ("ty_m", "ty (m)"),
        ("yaw_deg", "yaw (deg)"),
    ]
    for ax, (key, label) in zip(axes.ravel(), panels, strict=True):
        for method in dict.fromkeys(r["method"] for r in rows):
            mine = [r for r in rows if r["method"] == method]
            ax.plot([r["iteration"] for r in mine], [r[key] for r in mine], label=method)
        ax.set_xlabel("iteration (all cell sizes)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0, 0].legend()
    fig.suptitle("Optimiser traces through their cell schedules")
    return png_bytes(fig, dpi=110)
