"""Outputs of ``ndt-chain``: pairs.csv, poses.csv, poses.txt, one T_<target>_<source>.txt per
link, config_used.yaml, summary.json, topview.png and (E57 input) e57_header_poses.txt, published
together (:func:`ndt_cli.io.outdir.publish`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.io.matrices import format_matrix, format_pose_line
from ndt_cli.io.outdir import publish
from ndt_cli.io.serialize import csv_text, to_json
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.chain import ChainResult
from ndt_cli.pipeline.scans import link_file_name
from ndt_cli.report.tables import PAIR_COLUMNS, POSE_COLUMNS, pair_row, pose_row
from ndt_cli.report.topview import topview_png


def summary(result: ChainResult, runtime_s: float) -> dict[str, Any]:
    """The run in numbers: links per status, unreadable scans, scans without a pose."""
    statuses = [link.status for link in result.links]
    good = (Status.OK, Status.SUSPECT, Status.DEGENERATE)
    return {
        "scans": [str(p) for p in result.scans],
        "anchor": result.anchor,
        "links": len(result.links),
        "ok": statuses.count(Status.OK),
        "suspect": statuses.count(Status.SUSPECT),
        "degenerate": statuses.count(Status.DEGENERATE),
        "failed": len(statuses) - sum(statuses.count(s) for s in good),
        "unreadable": {result.names[i]: r for i, r in result.unreadable.items()},
        "scans_without_pose": [result.names[i] for i, T in enumerate(result.poses) if T is None],
        "all_ok": result.ok,
        "reused": len(result.reused),
        "runtime_s": runtime_s,
    }


def poses_text(result: ChainResult) -> str:
    """``poses.txt``: a comment header, then name and T_world_scan of every posed scan."""
    lines = [
        "# T_world_scan per scan: file name, then 16 numbers of the 4x4, row-major (metres)",
        f"# world frame = frame of {result.names[result.anchor]}; scans without a pose omitted",
    ]
    lines += [
        format_pose_line(name, T)
        for name, T in zip(result.names, result.poses, strict=True)
        if T is not None
    ]
    return "\n".join(lines) + "\n"


def _header_poses_text(result: ChainResult) -> str | None:
    """The poses stored in E57 scan headers (reported only: registration never uses them)."""
    from ndt_cli.io.e57 import header_poses

    stored = header_poses(list(result.scans))
    if not stored:
        return None
    lines = [
        "# Poses stored in the E57 scan headers (ignored for registration): scan, then",
        "# the 16 numbers of the 4x4 (scan frame to the E57 file frame), row-major",
    ]
    lines += [format_pose_line(result.names[k], T) for k, T in stored.items()]
    return "\n".join(lines) + "\n"


def chain_files(result: ChainResult, cfg: Config, runtime_s: float) -> dict[str, str]:
    """Every text output of a chain, by file name."""
    names = result.names
    files = {
        "pairs.csv": csv_text([pair_row(k, names) for k in result.links], PAIR_COLUMNS),
        "poses.csv": csv_text(
            [pose_row(k, n, T) for k, (n, T) in enumerate(zip(names, result.poses, strict=True))],
            POSE_COLUMNS,
        ),
        "poses.txt": poses_text(result),
    }
    for link in result.links:
        if link.T_target_source is not None:
            name = link_file_name(names[link.target], names[link.source])
            files[name] = format_matrix(link.T_target_source)
    header = _header_poses_text(result)
    if header is not None:
        files["e57_header_poses.txt"] = header
    files["config_used.yaml"] = dump(cfg)
    files["summary.json"] = to_json(summary(result, runtime_s))
    return files


def write_chain_outputs(out: Path, result: ChainResult, cfg: Config, runtime_s: float) -> None:
    """Publish every chain output (and the top view, with matplotlib) as the content of
    ``out``, all together; the links of the run are kept for ``--resume``."""
    files: dict[str, str | bytes] = dict(chain_files(result, cfg, runtime_s))
    png = topview_png(result)
    if png is not None:
        files["topview.png"] = png
    publish(Path(out), files)
