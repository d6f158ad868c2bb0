"""Accuracy of ndt-register / ndt-chain results against reference poses.

Ground truth is either a pose list (``name`` + 16 numbers of T_world_scan per line) or a pair
list (``target source`` + 16 numbers of T_target_source per line). Errors are those of each
link's T_target_source: rotation angle (degrees) and translation (metres) of the difference.
"""

from __future__ import annotations

from dataclasses import dataclass
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


@dataclass(frozen=True)
class Evaluation:
    """Per-link errors (with the network's verdict on each link, when there is one), success
    rates per threshold, and the end-of-chain drift of the adjusted and of the chained poses."""

    links: list[dict[str, Any]]
    success: list[dict[str, Any]]
    drift: dict[str, Any] | None
    drift_chained: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "links": self.links,
            "success": self.success,
            "drift": self.drift,
            "drift_chained": self.drift_chained,
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
        return _Results(
            links, _poses(result_dir / "poses.txt"), _poses(result_dir / "poses_chain.txt")
        )
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


def compare_with_reference(
    result_dir: str | Path, reference: str | Path, thresholds: Thresholds = DEFAULT_THRESHOLDS
) -> Evaluation:
    """Compare every link (and the chained poses) of ``result_dir`` with ``reference``."""
    results = _read_results(Path(result_dir))
    ref_poses, ref_pairs = read_reference(reference)
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
    if not rows:
        raise InputError(
            "no link of the results has a reference pose (check the scan names)", reference
        )
    success = []
    for r, t in thresholds:
        ok = [x["rotation_error_deg"] <= r and x["translation_error_m"] <= t for x in rows]
        success.append(
            {"max_rotation_deg": r, "max_translation_m": t, "success_rate": float(np.mean(ok))}
        )
    drift, chained = _drift(results.poses, ref_poses), _drift(results.chained, ref_poses)
    return Evaluation(rows, success, drift, chained if results.chained else None)
