"""Accuracy of ndt-register / ndt-chain results against reference poses.

Ground truth is either a pose list (``name`` + 16 numbers of T_world_scan per line) or a pair
list (``target source`` + 16 numbers of T_target_source per line). Errors are rotation angles
(degrees) and translations (metres) of differences of transforms:

- per link, of its ``T_target_source``; the success rates judge the links the network kept
  (confirmed or used; every link of a result without a network), the others are listed;
- per scan, of its pose relative to the anchor's, ``inv(T_world_anchor) @ T_world_scan``, so
  that a result in any world frame (levelled, georeferenced) compares with a reference in any
  other; a scan of the reference that the result does not give as ok in the anchor's frame
  (unposed, suspect, another cluster) fails, and the reference's scans the result lacks are
  named.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import InputError
from ndt_cli.io.matrices import named_rows, read_matrix, read_pose_list, rigid_problem
from ndt_cli.io.names import old_link_file_name
from ndt_cli.io.outdir import check_unchanged
from ndt_cli.io.serialize import read_json_object, read_table
from ndt_cli.pipeline.scans import scan_names

DEFAULT_THRESHOLDS = ((2.0, 0.10), (0.1, 0.02))  # (degrees, metres)


KEPT = ("confirmed", "used")  # the network states of the links a result rests on


@dataclass(frozen=True)
class Evaluation:
    """Per-link errors (with the network's verdict on each link, when there is one) and their
    success rates per threshold (of the judged links), the end-of-chain drift of the adjusted
    and of the chained poses; per scan of the reference in the result its status and error
    relative to ``anchor`` (the result's anchor, or the first scan both give a pose when the
    reference lacks it; None when there is no such scan) and their success rates, errors None
    when the scan has no ok pose in the anchor's frame; the reference's scans the result lacks
    (``missing``)."""

    links: list[dict[str, Any]]
    success: list[dict[str, Any]]
    drift: dict[str, Any] | None
    drift_chained: dict[str, Any] | None = None
    scans: list[dict[str, Any]] = field(default_factory=list)
    scan_success: list[dict[str, Any]] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    anchor: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "links": self.links,
            "success": self.success,
            "drift": self.drift,
            "drift_chained": self.drift_chained,
            "anchor": self.anchor,
            "scans": self.scans,
            "scan_success": self.scan_success,
            "missing": self.missing,
        }


def read_reference(
    path: str | Path,
) -> tuple[dict[str, np.ndarray], dict[tuple[str, str], np.ndarray]]:
    """(poses by scan name, relative transforms by (target, source)) from a reference file;
    every matrix must be a rigid transform."""
    p = Path(path)
    poses: dict[str, np.ndarray] = {}
    pairs: dict[tuple[str, str], np.ndarray] = {}
    for n, fields in named_rows(p, "reference"):
        try:
            if len(fields) not in (17, 18):
                raise ValueError
            T = np.array(fields[len(fields) - 16 :], dtype=float).reshape(4, 4)
        except ValueError:
            raise InputError(
                f"line {n}: expected 'name' or 'target source', then 16 numbers", p
            ) from None
        problem = rigid_problem(T)
        if problem:
            raise InputError(f"line {n}: {problem}", p)
        if len(fields) == 17:
            poses[fields[0]] = T
        else:
            pairs[(fields[0], fields[1])] = T
    return poses, pairs


@dataclass(frozen=True)
class _Results:
    links: list[tuple[str, str, np.ndarray, str]]  # target, source, T, network state ('' if none)
    poses: dict[str, np.ndarray]  # T_world_scan of the adjusted (or chained) ok scans
    chained: dict[str, np.ndarray]  # T_world_scan along adjacent ok links, not adjusted
    statuses: dict[str, str] = field(default_factory=dict)  # every scan's status, in order
    anchor: str | None = None  # the scan whose frame the poses are relative to


def _link_files(result_dir: Path, rows: list[dict[str, str]]) -> list[Path | None]:
    """The ``T_target_source`` file of every row of pairs.csv (None: a link without one), as
    summary.json lists them, or as results written before that list named them."""
    summary = result_dir / "summary.json"
    listed = (
        read_json_object(summary, "summary").get("transform_files") if summary.exists() else None
    )
    if listed is None:
        files = [result_dir / old_link_file_name(r["target"], r["source"]) for r in rows]
        return [f if f.is_file() else None for f in files]
    ok = isinstance(listed, list) and all(isinstance(n, str) for n in listed)
    if not ok or len(listed) != len(rows):
        raise InputError("'transform_files' does not list one file per link of pairs.csv", summary)
    for name in listed:
        if name and (Path(name).name != name or name in (".", "..")):
            raise InputError(f"{name!r} is not a file name", summary)
    return [result_dir / n if n else None for n in listed]


def _read_results(result_dir: Path) -> _Results:
    """Links and poses of an ndt-chain or ndt-register folder."""
    pairs_csv = result_dir / "pairs.csv"
    if pairs_csv.exists():
        check_unchanged(result_dir, ("pairs.csv", "poses.txt", "poses_chain.txt", "summary.json"))
        rows = read_table(pairs_csv, "pairs", ("target", "source"))
        links = []
        for row, f in zip(rows, _link_files(result_dir, rows), strict=True):
            if f is not None:
                check_unchanged(result_dir, (f.name,))
                state = row.get("network") or ""
                links.append((row["target"], row["source"], read_matrix(f), state))
        poses = _poses(result_dir / "poses.txt")
        statuses = _statuses(result_dir, poses)
        anchor = _anchor(result_dir, list(statuses))
        return _Results(links, poses, _poses(result_dir / "poses_chain.txt"), statuses, anchor)
    single = result_dir / "T_target_source.txt"
    if single.exists():
        check_unchanged(result_dir, ("T_target_source.txt", "result.json"))
        meta = read_json_object(result_dir / "result.json", "result")
        ends = [meta.get("target"), meta.get("source")]
        if not all(isinstance(e, str) and e for e in ends):
            raise InputError("no 'target' and 'source' scan names", result_dir / "result.json")
        names = scan_names([Path(e) for e in ends])
        return _Results([(names[0], names[1], read_matrix(single), "")], {}, {})
    raise InputError(
        "no ndt-chain (pairs.csv) or ndt-register (T_target_source.txt) results", result_dir
    )


def _poses(path: Path) -> dict[str, np.ndarray]:
    return read_pose_list(path) if path.exists() else {}


def _statuses(result_dir: Path, poses: dict[str, np.ndarray]) -> dict[str, str]:
    """Every scan's status (poses.csv; a result without it: the scans of poses.txt, ok)."""
    table = result_dir / "poses.csv"
    if not table.exists():
        return dict.fromkeys(poses, "ok")
    check_unchanged(result_dir, ("poses.csv",))
    rows = read_table(table, "poses", ("file", "status"))
    out = {}
    for r in rows:
        status, cluster = r["status"] or "unposed", r.get("cluster") or "0"
        out[r["file"]] = f"{status} in cluster {cluster}" if cluster != "0" else status
    return out


def _anchor(result_dir: Path, names: list[str]) -> str | None:
    """The anchor's name: summary.json's ``anchor`` index into the scans (the first scan of a
    result without it)."""
    summary = result_dir / "summary.json"
    index = read_json_object(summary, "summary").get("anchor", 0) if summary.exists() else 0
    if not isinstance(index, int) or not 0 <= index < max(len(names), 1):
        raise InputError("'anchor' is not the index of a scan", summary)
    return names[index] if names else None


def _drift(est: dict[str, np.ndarray], ref: dict[str, np.ndarray]) -> dict[str, Any] | None:
    """Error of the last scan in the frame of the first (both named in the reference)."""
    named = [n for n in est if n in ref]
    if len(named) < 2:
        return None
    first, last = named[0], named[-1]
    T_ref = np.linalg.inv(ref[first]) @ ref[last]
    T_est = np.linalg.inv(est[first]) @ est[last]
    rot, trans = transform_errors(T_est, T_ref)
    return {"from": first, "to": last, "rotation_error_deg": rot, "translation_error_m": trans}


Thresholds = tuple[tuple[float, float], ...]


def _rates(rows: list[dict[str, Any]], thresholds: Thresholds) -> list[dict[str, Any]]:
    """Per threshold, the share of rows within it (a row without errors fails)."""
    out = []
    for r, t in thresholds:
        ok = [
            x["rotation_error_deg"] is not None
            and x["rotation_error_deg"] <= r
            and x["translation_error_m"] <= t
            for x in rows
        ]
        rate = float(np.mean(ok)) if ok else None
        out.append({"max_rotation_deg": r, "max_translation_m": t, "success_rate": rate})
    return out


def _link_rows(results: _Results, ref_poses: dict, ref_pairs: dict) -> list[dict[str, Any]]:
    """The error of every link the reference covers, with its network state."""
    rows = []
    for target, source, T, state in results.links:
        if (target, source) in ref_pairs:
            T_ref = ref_pairs[(target, source)]
        elif target in ref_poses and source in ref_poses:
            T_ref = np.linalg.inv(ref_poses[target]) @ ref_poses[source]
        else:
            continue
        rot, trans = transform_errors(T, T_ref)
        row = {"target": target, "source": source, "rotation_error_deg": rot}
        row["translation_error_m"] = trans
        if state:
            row["network"] = state
        rows.append(row)
    return rows


def _base(results: _Results, ref: dict[str, np.ndarray]) -> str | None:
    """The scan the poses are compared relative to: the anchor, or (the reference lacks it)
    the first scan both give a pose; None when they share none."""
    est = results.poses
    if results.anchor in ref and results.anchor in est:
        return results.anchor
    return next((n for n in results.statuses if n in ref and n in est), None)


def _scan_rows(results: _Results, ref: dict[str, np.ndarray], base: str | None) -> list:
    """Per scan of both: its status and its pose error relative to ``base`` (None: no ok pose
    in the anchor's frame)."""
    est = results.poses
    rows = []
    for name, status in results.statuses.items():
        if name not in ref:
            continue
        row: dict[str, Any] = {"scan": name, "status": status}
        row["rotation_error_deg"] = row["translation_error_m"] = None
        if base is not None and name in est:
            T_est = np.linalg.inv(est[base]) @ est[name]
            T_ref = np.linalg.inv(ref[base]) @ ref[name]
            rot, trans = transform_errors(T_est, T_ref)
            row["rotation_error_deg"], row["translation_error_m"] = rot, trans
        rows.append(row)
    return rows


def compare_with_reference(
    result_dir: str | Path, reference: str | Path, thresholds: Thresholds = DEFAULT_THRESHOLDS
) -> Evaluation:
    """Compare every link and every scan of ``result_dir`` with ``reference`` (see the module
    docstring)."""
    results = _read_results(Path(result_dir))
    ref_poses, ref_pairs = read_reference(reference)
    rows = _link_rows(results, ref_poses, ref_pairs)
    base = _base(results, ref_poses)
    scans = _scan_rows(results, ref_poses, base)
    if not rows and not scans:
        raise InputError(
            "no link or scan of the results has a reference pose (check the scan names)",
            reference,
        )
    judged = [x for x in rows if x.get("network", KEPT[0]) in KEPT]
    drift, chained = _drift(results.poses, ref_poses), _drift(results.chained, ref_poses)
    named = set(results.statuses) | {n for t, s, _, _ in results.links for n in (t, s)}
    return Evaluation(
        rows,
        _rates(judged, thresholds),
        drift,
        chained if results.chained else None,
        scans,
        _rates(scans, thresholds) if scans else [],
        sorted(n for n in ref_poses if n not in named),
        base,
    )
