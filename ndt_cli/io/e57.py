"""E57, the exchange format of terrestrial scanners (optional: ``pip install 'ndt-cli[e57]'``).

One E57 file may hold many scans. A single scan is named ``FILE.e57#K`` (K from 0); a plain
``FILE.e57`` means its only scan. Points are read in each scan's own frame (cartesian, or
spherical converted to cartesian); a pose stored in the scan's header is not applied (it is
reported, never used for registration).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.errors import InputError, one_line
from ndt_cli.io.multiscan import split_spec, which_scan


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


def check_scan(spec: str | Path) -> None:
    """Raise unless the file opens as E57 and holds the scan that ``spec`` names."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        which_scan(path, index, int(e57.scan_count), str(spec))
    finally:
        e57.close()


def read_xyz(spec: str | Path) -> np.ndarray:
    """(N,3) float64 points of one scan, in the scan's own frame (header pose not applied)."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        k = which_scan(path, index, int(e57.scan_count), str(spec))
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
        k = which_scan(path, index, int(e57.scan_count), str(spec))
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
