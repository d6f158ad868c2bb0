"""Outputs of ``ndt-chain``: pairs.csv, poses.csv, poses.txt (and poses_cluster<K>.txt for a
network split into clusters), one T_<target>_<source>.txt per link, config_used.yaml,
summary.json, topview.png and (E57 input) e57_header_poses.txt, published together
(:func:`ndt_cli.io.outdir.publish`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.config.loading import dump
from ndt_cli.config.schema import Config
from ndt_cli.io.matrices import format_matrix, format_pose_line, quote_name
from ndt_cli.io.names import link_file_names, pose_file_names
from ndt_cli.io.outdir import publish
from ndt_cli.io.serialize import csv_text, to_json
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.scans import file_hash
from ndt_cli.pipeline.solution import ScanPose
from ndt_cli.pipeline.verify import EdgeState, NodeStatus
from ndt_cli.report.html_chain import chain_report
from ndt_cli.report.tables import PAIR_COLUMNS, POSE_COLUMNS, pair_row, pose_row
from ndt_cli.report.topview import topview_png
from ndt_cli.report.world import world_line, world_summary


def summary(result: ChainResult, runtime_s: float) -> dict[str, Any]:
    """The run in numbers: links per status and per network state, scans per status."""
    statuses = [link.status for link in result.links]
    good = (Status.OK, Status.SUSPECT, Status.DEGENERATE)
    sol = result.solution
    scans = [s.status for s in sol.scans]
    return {
        "scans": [str(p) for p in result.scans],
        "scan_files": [str(p.resolve()) for p in result.scans],
        "scan_sha256": list(result.hashes) or [file_hash(p) for p in result.scans],
        "pose_files": dict(zip(result.names, pose_file_list(result), strict=True)),
        "transform_files": link_file_list(result),
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
        "network": {
            "adjusted": sol.adjusted,
            "links_by_kind": _count(link.kind.value for link in result.links),
            "links_by_state": _count(f.state.value for f in sol.links),
            "rejected_links": [
                f"{result.names[k.target]} <- {result.names[k.source]}: {f.reason}"
                for k, f in zip(result.links, sol.links, strict=True)
                if f.state is EdgeState.REJECTED
            ],
            "left_out": _count(t.why.value for t in result.tried),
            "scans_by_status": _count(s.value for s in scans),
            "clusters": _count(str(s.cluster) for s in sol.scans if s.cluster is not None),
            "scans_not_ok": {
                result.names[k]: f"{s.status.value}: {s.reason}"
                for k, s in enumerate(sol.scans)
                if s.status is not NodeStatus.OK
            },
            "radius_m": None if np.isnan(result.radius) else result.radius,
        },
        "world": world_summary(result),
    }


def pose_records(result: ChainResult) -> list[dict[str, Any]]:
    """Every scan as ``ndt-chain --json`` gives it: name, status, cluster, ``T_world_scan``
    (4x4 rows, metres; a scan of cluster K > 0 in its cluster's frame; None when unposed),
    its 1-sigma (x, y, z in cm and yaw in degrees, world axes; None without an adjustment)
    and why it is not ok (as ``poses.csv``)."""
    out = []
    for name, s in zip(result.names, result.solution.scans, strict=True):
        sigma = None
        if s.sigma is not None:
            x, y, z, yaw = (float(v) for v in s.sigma)
            sigma = {"x_cm": 100 * x, "y_cm": 100 * y, "z_cm": 100 * z, "yaw_deg": yaw}
        T = None if s.T_world_scan is None else s.T_world_scan.tolist()
        out.append(
            {
                "scan": name,
                "status": s.status.value,
                "cluster": s.cluster,
                "T_world_scan": T,
                "sigma": sigma,
                "reason": s.reason,
            }
        )
    return out


def _count(values: Any) -> dict[str, int]:
    out: dict[str, int] = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return out


def _pose_lines(names: Any, poses: Any, what: str, world: str) -> list[str]:
    return [
        f"# {what}: file name, then 16 numbers of the 4x4, row-major (metres)",
        f"# {world}; scans without a pose omitted",
        *(format_pose_line(n, T) for n, T in zip(names, poses, strict=True) if T is not None),
    ]


def poses_text(result: ChainResult) -> str:
    """``poses.txt``: T_world_scan of every ok scan; the others as comments with the reason."""
    sol = result.solution
    ok = [s.T_world_scan if s.anchored else None for s in sol.scans]
    lines = _pose_lines(result.names, ok, "T_world_scan per scan", world_line(result))
    lines += [
        f"# {quote_name(name)}: {' '.join(_why_not(s).split())}"
        for name, s in zip(result.names, sol.scans, strict=True)
        if not s.anchored
    ]
    return "\n".join(lines) + "\n"


def _why_not(scan: ScanPose) -> str:
    """Why a scan is not in poses.txt."""
    if scan.status is NodeStatus.OK:
        k = scan.cluster
        return f"ok in cluster {k}: no link ties it to the anchor (see poses_cluster{k}.txt)"
    return f"{scan.status.value}: {scan.reason}"


def cluster_poses_files(result: ChainResult) -> dict[str, str]:
    """``poses_cluster<K>.txt`` for every cluster K > 0 with an ok scan: T_cluster_scan of its
    ok scans, in the frame of the cluster's first scan (as poses.txt for cluster 0)."""
    sol, files = result.solution, {}
    clusters = sorted({s.cluster for s in sol.scans if s.cluster and s.status is NodeStatus.OK})
    for k in clusters:
        members = [i for i, s in enumerate(sol.scans) if s.cluster == k]
        poses = [
            s.T_world_scan if s.cluster == k and s.status is NodeStatus.OK else None
            for s in sol.scans
        ]
        first = quote_name(result.names[members[0]])
        world = f"cluster {k}: world frame = frame of {first} (no link ties it to the anchor)"
        what = f"T_cluster{k}_scan per scan of cluster {k}"
        lines = _pose_lines(result.names, poses, what, world)
        files[f"poses_cluster{k}.txt"] = "\n".join(lines) + "\n"
    return files


def chained_text(result: ChainResult) -> str:
    """``poses_chain.txt``: the poses of the plain chain of adjacent ok links, not adjusted
    (to compare with the adjusted ``poses.txt``)."""
    what = "T_world_scan chained along adjacent ok links (not adjusted)"
    world = f"world frame = frame of {quote_name(result.names[result.anchor])} (not levelled)"
    lines = _pose_lines(result.names, result.solution.chained, what, world)
    return "\n".join(lines) + "\n"


def pose_file_list(result: ChainResult) -> list[str]:
    """The ``poses/T_world_<scan>.txt`` file of every scan ('' for a scan not posed in the
    anchor's frame; names: :func:`pose_file_names`)."""
    names = pose_file_names(result.names)
    anchored = [s.anchored for s in result.solution.scans]
    return [n if good else "" for n, good in zip(names, anchored, strict=True)]


def pose_files(result: ChainResult) -> dict[str, str]:
    """The pose file of every scan posed in the anchor's frame: a 4x4 that CloudCompare's
    ``-APPLY_TRANS`` and PDAL's ``filters.transformation`` read as it is."""
    names = pose_file_list(result)
    scans = result.solution.scans
    return {n: format_matrix(s.T_world_scan) for n, s in zip(names, scans, strict=True) if n}


def every_link(result: ChainResult) -> list[Link]:
    """The rows of ``pairs.csv``: the network's links, then the registrations tried and left
    out of it."""
    return [*result.links, *(t.link for t in result.tried)]


def link_file_list(result: ChainResult) -> list[str]:
    """The ``T_<target>_<source>.txt`` file of every row of ``pairs.csv`` ('' for a link
    without a transform; names: :func:`link_file_names`)."""
    links = every_link(result)
    names = link_file_names(result.names, [(k.target, k.source) for k in links])
    return [n if k.T_target_source is not None else "" for n, k in zip(names, links, strict=True)]


def _header_poses_text(result: ChainResult) -> str | None:
    """The poses stored in E57 scan headers (reported only: registration never uses them)."""
    from ndt_cli.io.multiscan_files import header_poses

    stored = header_poses(list(result.scans))
    if not stored:
        return None
    lines = [
        "# Poses stored in the E57 scan headers (ignored for registration): scan, then",
        "# the 16 numbers of the 4x4 (scan frame to the E57 file frame), row-major",
    ]
    lines += [format_pose_line(result.names[k], T) for k, T in stored.items()]
    return "\n".join(lines) + "\n"


def _levels(result: ChainResult) -> dict[int, np.ndarray]:
    """Each scan's levelling rotation, from any link that prepared it."""
    out: dict[int, np.ndarray] = {}
    for link in result.links:
        if link.result is not None:
            out[link.target] = link.result.level_target
            out[link.source] = link.result.level_source
    return out


def chain_files(result: ChainResult, cfg: Config, runtime_s: float) -> dict[str, str]:
    """Every text output of a chain, by file name."""
    names, sol, transforms = result.names, result.solution, link_file_list(result)
    pairs = [pair_row(k, names, f) for k, f in zip(result.links, sol.links, strict=True)]
    pairs += [pair_row(t.link, names, left_out=t.why) for t in result.tried]
    level = _levels(result)
    poses = [
        pose_row(k, n, s.T_world_scan, s, level.get(k))
        for k, (n, s) in enumerate(zip(names, sol.scans, strict=True))
    ]
    files = {
        "pairs.csv": csv_text(pairs, PAIR_COLUMNS),
        "poses.csv": csv_text(poses, POSE_COLUMNS),
        "poses.txt": poses_text(result),
        "poses_chain.txt": chained_text(result),
        **cluster_poses_files(result),
        **pose_files(result),
    }
    for link, name in zip(every_link(result), transforms, strict=True):
        if name:
            files[name] = format_matrix(link.T_target_source)
    header = _header_poses_text(result)
    if header is not None:
        files["e57_header_poses.txt"] = header
    files["config_used.yaml"] = dump(cfg)
    files["summary.json"] = to_json(summary(result, runtime_s))
    return files


def write_chain_outputs(
    out: Path, result: ChainResult, cfg: Config, runtime_s: float, command: str = ""
) -> None:
    """Publish every chain output and the top view as the content of ``out``, all together;
    the links of the run are kept for ``--resume``. ``command``: the command line that ran
    it, for the report ('' for a library call)."""
    text = chain_files(result, cfg, runtime_s)
    png = topview_png(result)
    report = chain_report(result, text["config_used.yaml"], runtime_s, png, command)
    files: dict[str, str | bytes] = {**text, "topview.png": png, "report.html": report}
    publish(Path(out), files)
