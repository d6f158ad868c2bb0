"""Files that hold many scans (E57, PTX): ``FILE#K`` names scan K (from 0) of such a file, a
plain ``FILE`` its only scan. Here: splitting such names, finding the scan K a name means,
listing every scan of the files of a campaign, and the poses their headers store (reported
only: registration never uses them)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError

MULTI_SCAN = (".e57", ".ptx")
_SPEC = re.compile(r"^(?P<file>.+\.(e57|ptx))#(?P<index>\d+)$", re.IGNORECASE)


def split_spec(spec: str | Path) -> tuple[Path, int | None]:
    """``'a.e57#3'`` -> (Path('a.e57'), 3); anything else -> (Path(spec), None)."""
    m = _SPEC.match(str(spec))
    return (Path(m["file"]), int(m["index"])) if m else (Path(spec), None)


def which_scan(path: Path, index: int | None, count: int, spec: str) -> int:
    """The index of the scan ``spec`` names among the ``count`` scans of ``path``."""
    if count == 0:
        raise InputError(f"the {path.suffix.lstrip('.').upper()} file holds no scan", spec)
    if index is None:
        if count > 1:
            raise InputError(
                f"holds {count} scans: name one as {path.name}#K (K = 0..{count - 1}) "
                "or register them all with ndt-chain",
                spec,
            )
        return 0
    if index >= count:
        raise InputError(f"no scan #{index} (the file holds {count})", spec)
    return index


def scan_count(path: Path) -> int:
    """Number of scans in an E57 or PTX file."""
    if path.suffix.lower() == ".ptx":
        from ndt_cli.io import ptx

        return ptx.scan_count(path)
    from ndt_cli.io import e57

    return e57.scan_count(path)


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
    if split_spec(spec)[0].suffix.lower() == ".ptx":
        from ndt_cli.io import ptx

        return ptx.header_pose(spec)
    from ndt_cli.io import e57

    return e57.header_pose(spec)


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
