"""E57, the exchange format of terrestrial scanners (optional: ``pip install 'ndt-cli[e57]'``).

One E57 file may hold many scans. A single scan is named ``FILE.e57#K`` (K from 0); a plain
``FILE.e57`` means its only scan. Points are read in each scan's own frame (cartesian, or
spherical converted to cartesian); a pose stored in the scan's header is not applied (it is
reported, never used for registration).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.errors import InputError, one_line
from ndt_cli.io.blocks import Block
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
    with scan_header(spec) as header:
        return int(header.point_count)


def _coordinates(fields: list[str], spec: str | Path) -> tuple[tuple[str, ...], str]:
    """The scan's coordinate fields (cartesian when it has them, as pye57 chooses) and the name
    of their invalid-state field."""
    if all(f in fields for f in _CARTESIAN):
        return _CARTESIAN, "cartesianInvalidState"
    if all(f in fields for f in _SPHERICAL):
        return _SPHERICAL, "sphericalInvalidState"
    raise InputError("the scan has neither cartesian nor spherical coordinates", spec)


def _spherical(arrays: dict[str, np.ndarray], n: int) -> np.ndarray:
    """(n,3) float64 x, y, z of the first ``n`` buffered spherical records."""
    r, az, el = (arrays[name][:n] for name in _SPHERICAL)  # as pye57 converts them
    return np.column_stack(
        [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]
    )


def _single(header: Any) -> bool:
    """Whether the scan stores x, y and z as single-precision floats: read as float32, they are
    exact in half the memory (and libE57 converts them a third faster)."""
    from pye57 import libe57

    proto = libe57.StructureNode(header.points.prototype())
    for name in _CARTESIAN:
        node = proto.get(name)
        if node.type() != libe57.NodeType.E57_FLOAT:
            return False
        if libe57.FloatNode(node).precision() != libe57.FloatPrecision.E57_SINGLE:
            return False
    return True


def _buffers(e57: Any, arrays: dict[str, np.ndarray], cap: int) -> Any:
    """libE57 buffers of ``arrays``: one per field, or the columns of an (cap,3) array."""
    from pye57 import libe57

    buffers = libe57.VectorSourceDestBuffer()
    for name, arr in arrays.items():
        if arr.ndim == 1:
            buffers.append(libe57.SourceDestBuffer(e57.image_file, name, arr, cap, True, True))
            continue
        k, flat = _CARTESIAN.index(name), arr.reshape(-1)  # x, y, z of a row side by side
        stride = 3 * arr.itemsize
        buffers.append(
            libe57.SourceDestBuffer(e57.image_file, name, flat[k:], cap, True, True, stride)
        )
    return buffers


def _chunks(e57: Any, k: int, spec: str | Path, chunk_size: int) -> Iterator[Block]:
    """The valid points of scan ``k`` of the open file, ``chunk_size`` records at a time."""
    header = e57.get_header(k)
    fields = list(header.point_fields)
    names, state = _coordinates(fields, spec)
    cap = int(min(chunk_size, max(1, header.point_count)))
    if names == _CARTESIAN:
        rows = np.empty((cap, 3), np.float32 if _single(header) else np.float64)
        arrays = dict.fromkeys(names, rows)
    else:
        arrays = {name: np.empty(cap, np.float64) for name in names}
    states = np.empty(cap, np.int8) if state in fields else None
    reader = header.points.reader(
        _buffers(e57, {**arrays, **({} if states is None else {state: states})}, cap)
    )
    try:
        while n := reader.read():
            xyz = rows[:n].copy() if names == _CARTESIAN else _spherical(arrays, n)
            yield Block(xyz if states is None else xyz[states[:n] == 0])
    finally:
        reader.close()


def iter_blocks(spec: str | Path, chunk_size: int = CHUNK) -> Iterator[Block]:
    """The points of one scan as blocks of ``chunk_size`` records through libE57's buffers, in
    the scan's own frame (header pose not applied), invalid records left out (the points
    pye57's ``read_scan`` gives), so memory stays bounded by the chunk. Coordinates stored as
    single-precision floats stay float32 (exact), the others are float64."""
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


def iter_xyz(spec: str | Path, chunk_size: int = CHUNK) -> Iterator[np.ndarray]:
    """The points of :func:`iter_blocks` as (m,3) float64 chunks."""
    for block in iter_blocks(spec, chunk_size):
        yield block.xyz()


def read_xyz(spec: str | Path) -> np.ndarray:
    """(N,3) float64 points of one scan, in the scan's own frame (header pose not applied)."""
    parts = list(iter_xyz(spec))
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


@contextmanager
def scan_header(spec: str | Path) -> Iterator[Any]:
    """The pye57 header of the scan ``spec`` names, its file open while the block runs."""
    path, index = split_spec(spec)
    e57 = open_file(path)
    try:
        yield e57.get_header(which_scan(path, index, int(e57.scan_count), str(spec)))
    finally:
        e57.close()


def header_pose(spec: str | Path) -> np.ndarray | None:
    """The 4x4 pose stored in a scan's header (scan frame to file frame), or None."""
    with scan_header(spec) as header:
        if not header.has_pose():
            return None
        T = np.eye(4)
        T[:3, :3] = np.asarray(header.rotation_matrix, dtype=np.float64)
        T[:3, 3] = np.asarray(header.translation, dtype=np.float64)
        return T


def acquisition_start(spec: str | Path) -> float | None:
    """The scan header's ``acquisitionStart`` (GPS seconds), or None when it has none."""
    with scan_header(spec) as header:
        try:
            return float(header.acquisitionStart_dateTimeValue)
        except Exception:  # libE57 raises when the optional element is missing
            return None


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
