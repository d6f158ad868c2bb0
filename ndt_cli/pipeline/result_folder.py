"""A result folder read back for the export: which scans, from which files, in which pose.

An ``ndt-chain`` folder names its scans' files in ``summary.json`` and their status and
``T_world_scan`` in ``poses.csv``; an ``ndt-register`` folder names both files in
``result.json`` (the target's frame is the world). ``config_used.yaml`` says how each file's
coordinates become the scanner frame (``input.scale``, ``input.axes``). Only ``ok`` scans are
exported, ``suspect`` ones too when asked; ``unposed`` ones (and a pair's ``degenerate``,
``not_converged`` or ``no_overlap`` source) never.

A result is trusted only as its run wrote it: every file read here must match the SHA-256 its
manifest records, the files must agree with each other (the rows of poses.csv name the scans
of summary.json in order), every pose must be a rigid transform, and every scan file must
still be the one registered (the SHA-256 the result records). Anything else is an
:class:`~ndt_cli.errors.InputError` naming the file and the problem.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from enum import Enum
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ndt_cli.config import load
from ndt_cli.config.schema import Config
from ndt_cli.errors import InputError
from ndt_cli.io.crs import wkt_records
from ndt_cli.io.export_inputs import ExportScan
from ndt_cli.io.matrices import rigid_problem
from ndt_cli.io.outdir import check_unchanged
from ndt_cli.io.records import RawVlr
from ndt_cli.io.serialize import read_json_object, read_table
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.datum import WorldFrame
from ndt_cli.pipeline.scans import file_hash, scan_names
from ndt_cli.pipeline.verify import NodeStatus

log = logging.getLogger(__name__)

_E = TypeVar("_E", bound=Enum)
PAIR_STATUSES = tuple(s for s in Status if s is not Status.FAILED)  # what result.json may say
MATRIX = tuple(f"m{r}{c}" for r in range(4) for c in range(4))
POSE_TOLERANCE = 1e-6  # largest deviation of R R^T from the identity in a written pose


_OK = {NodeStatus.OK, Status.OK}
_SUSPECT = {NodeStatus.SUSPECT, Status.SUSPECT}


@dataclass(frozen=True)
class ResultScan:
    """A scan of a result: its name, file, status (a chain's :class:`NodeStatus`; a pair's
    :class:`Status` of its registration), T_world_scan (None when unposed), reason, the
    cluster it is posed in (0: the anchor's; another's poses are in the frame of that
    cluster's first scan), and the SHA-256 of
    its file when registered (None when it could not be read then; ``hash_recorded``: whether
    the result records it at all: older results do not)."""

    name: str
    file: Path
    status: NodeStatus | Status
    T_world_scan: np.ndarray | None
    reason: str = ""
    cluster: int = 0
    sha256: str | None = None
    hash_recorded: bool = False

    def exportable(self, include_suspect: bool, cluster: int = 0) -> bool:
        """Posed in the frame of ``cluster``, ok (or suspect, when ``include_suspect``)."""
        allowed = _OK | _SUSPECT if include_suspect else _OK
        posed = self.T_world_scan is not None and self.cluster == cluster
        return posed and self.status in allowed

    def why_left_out(self, include_suspect: bool, cluster: int) -> str:
        """Why an export of ``cluster`` leaves this scan out (one line)."""
        if self.T_world_scan is not None and self.cluster != cluster:
            return f"{self.name}: in cluster {self.cluster}, not {cluster} (--cluster)"
        hint = ""
        if self.status in _SUSPECT and not include_suspect:
            hint = " (--include-suspect exports it)"
        return f"{self.name}: {self.status.value}{': ' + self.reason if self.reason else ''}{hint}"


def _file(path: str) -> Path:
    """A scan file as the result names it (relative names: from the current folder)."""
    p = Path(path)
    return p if p.is_absolute() else Path.cwd() / p


def _filled(v: Any) -> bool:
    return isinstance(v, str) and bool(v)


def _list(value: Any, n: int | None, what: str, where: Path, item: Callable[[Any], bool]) -> list:
    """``value`` as a list of ``n`` items (any length when None) that pass ``item``."""
    ok = isinstance(value, list) and all(item(v) for v in value)
    if not ok or (n is not None and len(value) != n):
        count = "" if n is None else f" of {n}"
        raise InputError(f"{what!r} is not a list{count} file names or hashes", where)
    return value


def _strings(value: Any, n: int | None, what: str, where: Path) -> list[str]:
    """``value`` as a list of ``n`` non-empty strings (any length when None)."""
    return _list(value, n, what, where, _filled)


def _hashes(value: Any, n: int, where: Path) -> list[str | None]:
    """summary.json's ``scan_sha256``: a SHA-256 per scan (None: its file could not be read)."""
    return _list(value, n, "scan_sha256", where, lambda v: v is None or _filled(v))


def _pose(row: dict[str, str], where: str, path: Path) -> np.ndarray:
    """The rigid 4x4 of a poses.csv row."""
    try:
        T = np.array([float(row[m]) for m in MATRIX]).reshape(4, 4)
    except ValueError:
        raise InputError(f"{where}: a matrix cell is not a number", path) from None
    problem = rigid_problem(T, POSE_TOLERANCE)
    if problem:
        raise InputError(f"{where}: T_world_scan: {problem}", path)
    return T


def _is_tail(name: str, file: str) -> bool:
    """Whether the scan name is the end of its file's path (``north/scan.laz``). The name is
    as a CSV file holds it: a file name that is not valid UTF-8 is written escaped there."""
    file = file.encode("utf-8", "backslashreplace").decode("utf-8")
    tails = (file, file.replace("\\", "/"))  # a Windows path's folders too
    return file == name or any(t.endswith("/" + name) for t in tails)


def _chain_row(row: dict[str, str], k: int, file: str, path: Path) -> ResultScan:
    """Scan ``k`` of a chain from its row of poses.csv, checked against summary.json."""
    where = f"row {k + 2} ({row['file']})"
    if row["scan"] != str(k) or not _is_tail(row["file"], file):
        raise InputError(f"{where} does not name scan {k} of summary.json ({file})", path)
    if row["has_pose"] not in ("true", "false"):
        raise InputError(f"{where}: has_pose is {row['has_pose']!r}, not true or false", path)
    has = row["has_pose"] == "true"
    text = row.get("status") or (NodeStatus.OK if has else NodeStatus.UNPOSED).value
    status = _member(NodeStatus, text)
    if status is None or (status is NodeStatus.UNPOSED) == has:
        raise InputError(f"{where}: status {text!r} with has_pose {row['has_pose']}", path)
    T = _pose(row, where, path) if has else None
    reason = row.get("reason") or ""
    text = row.get("cluster") or "0"  # blank: unposed, or a result without clusters
    if not (text.isascii() and text.isdigit()):
        raise InputError(f"{where}: cluster {text!r} is not a cluster number", path)
    return ResultScan(row["file"], _file(file), status, T, reason, cluster=int(text))


def _member(kind: type[_E], value: object) -> _E | None:
    """The member of the enum ``kind`` whose value ``value`` (read from a file) is; None when
    there is none."""
    try:
        return kind(value)
    except (ValueError, TypeError):
        return None


def _chain_scans(folder: Path) -> tuple[list[ResultScan], int]:
    check_unchanged(folder, ("summary.json", "poses.csv", "poses.txt"))
    summary = read_json_object(folder / "summary.json", "summary")
    where = folder / "summary.json"
    files = _strings(summary.get("scan_files") or summary.get("scans"), None, "scan_files", where)
    recorded = summary.get("scan_sha256")
    hashes = [None] * len(files) if recorded is None else _hashes(recorded, len(files), where)
    anchor = summary.get("anchor", 0)
    if type(anchor) is not int or not 0 <= anchor < len(files):
        raise InputError(f"anchor {anchor!r} is not a scan index", where)
    path = folder / "poses.csv"
    rows = read_table(path, "poses", ("scan", "file", "has_pose", *MATRIX))
    if len(rows) != len(files):
        raise InputError("poses.csv and summary.json list different scans", folder)
    scans = [
        _chain_row(row, k, f, path) for k, (row, f) in enumerate(zip(rows, files, strict=True))
    ]
    if len({s.name for s in scans}) != len(scans):
        raise InputError("two rows name the same scan", path)
    with_hashes = [
        replace(s, sha256=h, hash_recorded=recorded is not None)
        for s, h in zip(scans, hashes, strict=True)
    ]
    return with_hashes, anchor


def _pair_scans(folder: Path) -> tuple[list[ResultScan], int]:
    check_unchanged(folder, ("result.json",))
    path = folder / "result.json"
    data = read_json_object(path, "result")
    ends = [
        data.get("target_file") or data.get("target"),
        data.get("source_file") or data.get("source"),
    ]
    if None in ends:
        raise InputError("registered from arrays: no scan files to export", path)
    files = _strings(ends, 2, "target and source", path)
    text = data.get("status")
    status = _member(Status, text)
    if status not in PAIR_STATUSES:
        raise InputError(f"status {text!r} is not one of {', '.join(PAIR_STATUSES)}", path)
    try:
        T = np.array(data.get("T_target_source"), dtype=float)
    except (TypeError, ValueError):
        raise InputError("T_target_source is not a 4x4 matrix of numbers", path) from None
    problem = rigid_problem(T, POSE_TOLERANCE)
    if problem:
        raise InputError(f"T_target_source: {problem}", path)
    warnings = data.get("warnings") or []
    reason = "; ".join(map(str, warnings)) if isinstance(warnings, list) else str(warnings)
    names = scan_names([Path(f) for f in files])
    return [
        ResultScan(names[0], _file(files[0]), Status.OK, np.eye(4), **_hash_of(data, "target")),
        ResultScan(names[1], _file(files[1]), status, T, reason, **_hash_of(data, "source")),
    ], 0


def _hash_of(data: dict[str, Any], end: str) -> dict[str, Any]:
    """The SHA-256 a pair's ``result.json`` records for the file of its ``end`` (None when the
    file could not be read), and whether it records one at all (as :class:`ResultScan`'s
    fields)."""
    key = f"{end}_sha256"
    value = data.get(key)
    return {"sha256": None if value is None else str(value), "hash_recorded": key in data}


def result_scans(folder: Path) -> tuple[list[ResultScan], int]:
    """The scans of an ``ndt-chain`` or ``ndt-register`` result folder, and the anchor's index
    (the scan whose frame is the world, and whose CRS the exports carry), checked (see the
    module docstring)."""
    if (folder / "summary.json").exists():
        return _chain_scans(folder)
    if (folder / "result.json").exists():
        return _pair_scans(folder)
    raise InputError("not an ndt-chain or ndt-register result folder", folder)


def result_crs(folder: Path) -> tuple[RawVlr, ...] | None:
    """The CRS records an export of the result carries: the WKT of ``--crs`` when the chain was
    georeferenced with it (two or more stations); none when control coordinates made the world
    without a named system, or with one station only (its heading is the anchor's, not the
    system's): the anchor's records would not describe it; else None (the anchor's, copied)."""
    path = folder / "summary.json"
    if not path.exists():
        return None
    world = read_json_object(path, "summary").get("world")
    if isinstance(world, dict) and world.get("georeferenced") is False:
        raise InputError(
            f"not georeferenced: {world.get('not_georeferenced')}; correct the control and "
            "run ndt-chain again",
            path,
        )
    frame = _member(WorldFrame, world.get("frame")) if isinstance(world, dict) else None
    if frame is None or not frame.from_control:
        return None
    wkt = world.get("crs")
    if not wkt or frame is not WorldFrame.CONTROL:
        why = (
            "in the CRS of --crs at one station only, its heading the anchor's"
            if wkt
            else "the control's coordinates, of no named CRS"
        )
        log.warning("%s: the world is %s: no CRS written", folder, why)
        return ()
    if not isinstance(wkt, str):
        raise InputError("summary.json: world.crs is not a WKT text", path)
    return wkt_records(wkt)


def result_config(folder: Path) -> Config:
    """The config the result was made with (``config_used.yaml``, checked unchanged)."""
    path = folder / "config_used.yaml"
    if not path.is_file():
        raise InputError(
            "no config_used.yaml: how the scan files' coordinates become the scanner frame "
            "(input.scale, input.axes) is unknown",
            folder,
        )
    check_unchanged(folder, ("config_used.yaml",))
    return load(path)


def select(
    scans: list[ResultScan], names: list[str] | None, include_suspect: bool, cluster: int = 0
) -> tuple[list[int], list[str]]:
    """Indices of the scans of ``cluster`` to export, and one line per scan left out (why)."""
    clusters = {s.cluster for s in scans if s.T_world_scan is not None}
    if cluster != 0 and cluster not in clusters:
        have = ", ".join(str(c) for c in sorted(clusters)) or "none"
        raise InputError(f"--cluster {cluster}: the result has no such cluster (it has {have})")
    wanted = set(range(len(scans)))
    if names is not None:
        if not any(names):
            raise InputError("--scans is empty: name the scans to export, or leave it out")
        lookup = {s.name: k for k, s in enumerate(scans)} | {str(k): k for k in range(len(scans))}
        unknown = [n for n in names if n not in lookup]
        if unknown:
            raise InputError(f"--scans names no scan of the result: {', '.join(unknown)}")
        wanted = {lookup[n] for n in names}
    keep, left = [], []
    for k in sorted(wanted):
        s = scans[k]
        if s.exportable(include_suspect, cluster):
            keep.append(k)
        else:
            left.append(s.why_left_out(include_suspect, cluster))
    return keep, left


def check_scan_files(scans: list[ResultScan], keep: list[int]) -> None:
    """Raise unless every kept scan's file is the one registered (its SHA-256); a result that
    records no hash (made by an older ndt-cli) is exported with a warning."""
    for k in keep:
        scan = scans[k]
        if not scan.hash_recorded:
            log.warning("%s: the result records no SHA-256 of this file: not checked", scan.file)
            continue
        if file_hash(scan.file) != scan.sha256:
            raise InputError(
                "not the file that was registered (its SHA-256 differs from the result's): "
                "register it again",
                scan.file,
            )


def export_scans(
    keep: list[int], scans: list[ResultScan], anchor: int, cfg: Config
) -> list[ExportScan]:
    """The scans to export with their poses and the input transform of the run's config
    (:func:`result_config`); the anchor (or, when it is left out or another cluster is
    exported, the first exported scan) gives the CRS."""
    crs = anchor if anchor in keep else keep[0]
    return [
        ExportScan.from_pose(
            scans[k].file,
            scans[k].name,
            k,
            scans[k].T_world_scan,
            scale=cfg.input.scale,
            axes=cfg.input.axes,
            anchor=(k == crs),
        )
        for k in keep
    ]
