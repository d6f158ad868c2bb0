"""The registered point cloud of a result folder: which scans, from which files, in which pose.

An ``ndt-chain`` folder names its scans' files in ``summary.json`` and their status and
``T_world_scan`` in ``poses.csv``; an ``ndt-register`` folder names both files in
``result.json`` (the target's frame is the world). ``config_used.yaml`` says how each file's
coordinates become the scanner frame (``input.scale``, ``input.axes``). Only ``ok`` scans are
exported, ``suspect`` ones too when asked; ``unposed`` ones never.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ndt_cli.config import load
from ndt_cli.errors import InputError, read_user_text
from ndt_cli.io.export import ExportScan


@dataclass(frozen=True)
class ResultScan:
    """A scan of a result: its name, file, status, T_world_scan (None when unposed), reason."""

    name: str
    file: Path
    status: str
    T_world_scan: np.ndarray | None
    reason: str = ""


def _file(path: str) -> Path:
    """A scan file as the result names it (relative names: from the current folder)."""
    p = Path(path)
    return p if p.is_absolute() else Path.cwd() / p


def _chain_scans(folder: Path) -> tuple[list[ResultScan], int]:
    summary = json.loads(read_user_text(folder / "summary.json", "summary"))
    files = summary.get("scan_files") or summary["scans"]
    rows = list(csv.DictReader(read_user_text(folder / "poses.csv", "poses").splitlines()))
    if len(rows) != len(files):
        raise InputError("poses.csv and summary.json list different scans", folder)
    anchor = int(summary.get("anchor", 0))
    scans = []
    for row, f in zip(rows, files, strict=True):
        has = row["has_pose"] == "true"
        T = np.array([float(row[f"m{r}{c}"]) for r in range(4) for c in range(4)]).reshape(4, 4)
        status = row.get("status") or ("ok" if has else "unposed")
        reason = row.get("reason", "")
        if row.get("cluster") not in (None, "", "0"):  # posed in its own cluster's frame
            status, reason = "other cluster", f"cluster {row['cluster']}: not tied to the anchor"
        scans.append(ResultScan(row["file"], _file(f), status, T if has else None, reason))
    return scans, anchor


def _pair_scans(folder: Path) -> tuple[list[ResultScan], int]:
    data = json.loads(read_user_text(folder / "result.json", "result"))
    T = np.array(data["T_target_source"], dtype=float)
    files = [data.get("target_file") or data["target"], data.get("source_file") or data["source"]]
    status = "ok" if data["status"] == "ok" else "suspect"
    reason = "; ".join(data.get("warnings", []))
    return [
        ResultScan(Path(files[0]).name, _file(files[0]), "ok", np.eye(4)),
        ResultScan(Path(files[1]).name, _file(files[1]), status, T, reason),
    ], 0


def result_scans(folder: Path) -> tuple[list[ResultScan], int]:
    """The scans of an ``ndt-chain`` or ``ndt-register`` result folder, and the anchor's index
    (the scan whose frame is the world, and whose CRS the exports carry)."""
    if (folder / "summary.json").exists():
        return _chain_scans(folder)
    if (folder / "result.json").exists():
        return _pair_scans(folder)
    raise InputError("not an ndt-chain or ndt-register result folder", folder)


def select(
    scans: list[ResultScan], names: list[str] | None, include_suspect: bool
) -> tuple[list[int], list[str]]:
    """Indices of the scans to export, and one line per scan left out (why)."""
    wanted = set(range(len(scans)))
    if names:
        lookup = {s.name: k for k, s in enumerate(scans)} | {str(k): k for k in range(len(scans))}
        unknown = [n for n in names if n not in lookup]
        if unknown:
            raise InputError(f"--scans names no scan of the result: {', '.join(unknown)}")
        wanted = {lookup[n] for n in names}
    keep, left = [], []
    allowed = ("ok", "suspect") if include_suspect else ("ok",)
    for k in sorted(wanted):
        s = scans[k]
        if s.T_world_scan is not None and s.status in allowed:
            keep.append(k)
        else:
            hint = " (--include-suspect exports it)" if s.status == "suspect" else ""
            left.append(f"{s.name}: {s.status}{': ' + s.reason if s.reason else ''}{hint}")
    return keep, left


def export_scans(
    folder: Path, keep: list[int], scans: list[ResultScan], anchor: int
) -> list[ExportScan]:
    """The scans to export with their poses and the input transform of the run's config; the
    anchor (or, when it is left out, the first exported scan) gives the CRS."""
    cfg = load(folder / "config_used.yaml") if (folder / "config_used.yaml").exists() else None
    scale = 1.0 if cfg is None else cfg.input.scale
    axes = "x,y,z" if cfg is None else cfg.input.axes
    crs = anchor if anchor in keep else keep[0]
    return [
        ExportScan.from_pose(
            scans[k].file,
            scans[k].name,
            k,
            scans[k].T_world_scan,
            scale=scale,
            axes=axes,
            anchor=(k == crs),
        )
        for k in keep
    ]
