"""Files that hold many scans (E57, PTX) as a campaign sees them: how many scans each holds,
every scan of the files given (``FILE#0``, ``FILE#1``, ...), and the poses their headers store
(reported only: registration never uses them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError
from ndt_cli.io.multiscan import MULTI_SCAN, split_spec
from ndt_cli.io.points import reader_for


def scan_count(path: Path) -> int:
    """Number of scans in an E57 or PTX file (its reader's count)."""
    return reader_for(path).scan_count(path)


def expand(paths: list[Path]) -> list[Path]:
    """Each file of many scans becomes ``FILE#0``, ``#1``, ... in order; others unchanged."""
    out: list[Path] = []
    for p in paths:
        n = 1
        if p.suffix.lower() in MULTI_SCAN and split_spec(p)[1] is None and p.is_file():
            try:
                n = scan_count(p)
            except InputError:
                n = 1  # left as it is: reading it fails later and is reported for its link
        out.extend(Path(f"{p}#{k}") for k in range(n)) if n > 1 else out.append(p)
    return out


def header_pose(spec: Path) -> np.ndarray | None:
    """The 4x4 pose a scan's header stores (scan frame to the file's frame), or None."""
    return reader_for(split_spec(spec)[0]).header_pose(spec)


def header_poses(paths: list[Path]) -> dict[int, np.ndarray]:
    """Header poses of the E57 and PTX scans among ``paths`` (by position); unreadable ones and
    identities (a PTX that stores none) are skipped."""
    poses = {}
    for k, p in enumerate(paths):
        if split_spec(p)[0].suffix.lower() not in MULTI_SCAN:
            continue
        try:
            T = header_pose(p)
        except InputError:
            continue
        if T is not None and not np.array_equal(T, np.eye(4)):
            poses[k] = T
    return poses
