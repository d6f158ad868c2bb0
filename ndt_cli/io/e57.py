"""E57, the exchange format of terrestrial scanners (optional: ``pip install 'ndt-cli[e57]'``).

One E57 file may hold many scans. A single scan is named ``FILE.e57#K`` (K from 0); a plain
``FILE.e57`` means its only scan. Points are read in each scan's own frame (cartesian, or
spherical converted to cartesian); a pose stored in the scan's header is not applied (it is
reported, never used for registration).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.errors import InputError, one_line

_SPEC = re.compile(r"^(?P<file>.+\.e57)#(?P<index>\d+)$", re.IGNORECASE)


def split_spec(spec: str | Path) -> tuple[Path, int | None]:
    """``'a.e57#3'`` -> (Path('a.e57'), 3); anything else -> (Path(spec), None)."""
    m = _SPEC.match(str(spec))
    return (Path(m["file"]), int(m["index"])) if m else (Path(spec), None)


def open_file(path: Path) -> Any:
    """The E57 file opened with pye57; an InputError naming it when it cannot be."""
    try:
        import pye57
    except ImportError:
        raise InputError("reading E57 needs pye57: pip install 'ndt-cli[e57]'", path) from None
    try:
        return pye57.E57(str(path))
    except Exception as exc:  # libE57 errors are plain exceptions
        raise InputError(f"not a valid E57 file: {one_line(exc)}", path) from None


def scan_count(path: str | Path) -> int:
    """Number of scans in an E57 file."""
    e57 = open_file(Path(path))
    try:
        return int(e57.scan_count)
    finally:
        e57.close()


def expand(paths: list[Path]) -> list[Path]:
    """Each multi-scan E57 file becomes ``FILE.e57#0``, ``#1``, ... in order; others unchanged."""
    out: list[Path] = []
    for p in paths:
        n = 1
        if p.suffix.lower() == ".e57" and split_spec(p)[1] is None and p.is_file():
            try:
                n = scan_count(p)
            except InputError:
                n = 1  # left as it is: reading it fails later and is reported for its link
        out.extend(Path(f"{p}#{k}") for k in range(n)) if n > 1 else out.append(p)
    return out


def header_poses(paths: list[Path]) -> dict[int, np.ndarray]:
    """Header poses of the E57 scans among ``paths`` (by position); unreadable ones are skipped."""
    poses = {}
    for k, p in enumerate(paths):
        if split_spec(p)[0].suffix.lower() == ".e57":
            try:
                T = header_pose(p)
            except InputError:
                continue
            if T is not None:
                poses[k] = T
    return poses


def scan_index(path: Path, index: int | None, count: int, spec: str) -> int:
    """The index of the scan ``spec`` names among the ``count`` scans of ``path``."""
    if count == 0:
        raise InputError("the E57 file holds no scan", spec)
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


def check_scan(spec: str | Path) -> None:
    """Raise unless the file opens as E57 and holds the scan that ``spec`` names."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        scan_index(path, index, int(e57.scan_count), str(spec))
    finally:
        e57.close()


def read_xyz(spec: str | Path) -> np.ndarray:
    """(N,3) float64 points of one scan, in the scan's own frame (header pose not applied)."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        k = scan_index(path, index, int(e57.scan_count), str(spec))
        data = e57.read_scan(k, transform=False, ignore_missing_fields=True)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"cannot read E57 scan: {one_line(exc)}", spec) from None
    finally:
        e57.close()
    if "cartesianX" in data:
        return np.column_stack([data["cartesianX"], data["cartesianY"], data["cartesianZ"]])
    if "sphericalRange" in data:
        r, az, el = data["sphericalRange"], data["sphericalAzimuth"], data["sphericalElevation"]
        return np.column_stack(
            [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]
        ).astype(np.float64)
    raise InputError("the scan has neither cartesian nor spherical coordinates", spec)


def header_pose(spec: str | Path) -> np.ndarray | None:
    """The 4x4 pose stored in a scan's header (scan frame to file frame), or None."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        k = scan_index(path, index, int(e57.scan_count), str(spec))
        header = e57.get_header(k)
        if not header.has_pose():
            return None
        T = np.eye(4)
        T[:3, :3] = np.asarray(header.rotation_matrix, dtype=np.float64)
        T[:3, 3] = np.asarray(header.translation, dtype=np.float64)
        return T
    finally:
        e57.close()


def write(path: str | Path, scans: list[np.ndarray], poses: list[np.ndarray | None]) -> None:
    """Write scans (each (N,3) in its own frame) with optional header poses (tests and tools)."""
    import pye57

    from ndt_cli.core.transforms import rotation_to_quaternion
    from ndt_cli.io.atomic import atomic_path

    with atomic_path(path) as tmp:
        tmp.unlink()  # libE57 creates the file itself
        e57 = pye57.E57(str(tmp), mode="w")
        try:
            for pts, T in zip(scans, poses, strict=True):
                data = {f"cartesian{a}": pts[:, k].copy() for k, a in enumerate("XYZ")}
                if T is None:
                    e57.write_scan_raw(data)
                else:
                    rotation = rotation_to_quaternion(T[:3, :3])
                    e57.write_scan_raw(data, rotation=rotation, translation=T[:3, 3].copy())
        finally:
            e57.close()
