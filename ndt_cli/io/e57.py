"""E57, the exchange format of terrestrial scanners (optional: ``pip install 'ndt-cli[e57]'``).

One E57 file may hold many scans. A single scan is named ``FILE.e57#K`` (K from 0); a plain
``FILE.e57`` means its only scan. Points are read in each scan's own frame (cartesian, or
spherical converted to cartesian); a pose stored in the scan's header is not applied (it is
reported, never used for registration).
"""

from __future__ import annotations

from collections.abc import Iterator
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


_CARTESIAN = ("cartesianX", "cartesianY", "cartesianZ")
_SPHERICAL = ("sphericalRange", "sphericalAzimuth", "sphericalElevation")
CHUNK = 4_000_000  # records read at a time by read_xyz


def record_count(spec: str | Path) -> int:
    """Point records of the scan ``spec`` names (its header's count, invalid records too)."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        k = which_scan(path, index, int(e57.scan_count), str(spec))
        return int(e57.get_header(k).point_count)
    finally:
        e57.close()


def _coordinates(fields: list[str], spec: str | Path) -> tuple[tuple[str, ...], str]:
    """The scan's coordinate fields (cartesian when it has them, as pye57 chooses) and the name
    of their invalid-state field."""
    if all(f in fields for f in _CARTESIAN):
        return _CARTESIAN, "cartesianInvalidState"
    if all(f in fields for f in _SPHERICAL):
        return _SPHERICAL, "sphericalInvalidState"
    raise InputError("the scan has neither cartesian nor spherical coordinates", spec)


def _cartesian(arrays: dict[str, np.ndarray], names: tuple[str, ...], n: int) -> np.ndarray:
    """(n,3) float64 x, y, z of the first ``n`` buffered records (spherical ones converted)."""
    a, b, c = (arrays[name][:n] for name in names)
    if names == _CARTESIAN:
        out = np.empty((n, 3))
        out[:, 0], out[:, 1], out[:, 2] = a, b, c
        return out
    r, az, el = a, b, c  # as pye57 converts them
    return np.column_stack(
        [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]
    )


def _chunks(e57: Any, k: int, spec: str | Path, chunk_size: int) -> Iterator[np.ndarray]:
    """The valid points of scan ``k`` of the open file, ``chunk_size`` records at a time."""
    from pye57 import libe57

    header = e57.get_header(k)
    fields = list(header.point_fields)
    names, state = _coordinates(fields, spec)
    cap = int(min(chunk_size, max(1, header.point_count)))
    arrays = {name: np.empty(cap, np.float64) for name in names}
    if state in fields:
        arrays[state] = np.empty(cap, np.int8)
    buffers = libe57.VectorSourceDestBuffer()
    for name, arr in arrays.items():
        buffers.append(libe57.SourceDestBuffer(e57.image_file, name, arr, cap, True, True))
    reader = header.points.reader(buffers)
    try:
        while n := reader.read():
            xyz = _cartesian(arrays, names, n)
            yield xyz if state not in arrays else xyz[arrays[state][:n] == 0]
    finally:
        reader.close()


def iter_xyz(spec: str | Path, chunk_size: int = CHUNK) -> Iterator[np.ndarray]:
    """(m,3) float64 points of one scan, ``chunk_size`` records at a time through libE57's
    buffers, in the scan's own frame (header pose not applied), invalid records left out (the
    points pye57's ``read_scan`` gives), so memory stays bounded by the chunk."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        k = which_scan(path, index, int(e57.scan_count), str(spec))
        yield from _chunks(e57, k, spec, chunk_size)
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"cannot read E57 scan: {one_line(exc)}", spec) from None
    finally:
        e57.close()


def read_xyz(spec: str | Path) -> np.ndarray:
    """(N,3) float64 points of one scan, in the scan's own frame (header pose not applied)."""
    parts = list(iter_xyz(spec))
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


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
