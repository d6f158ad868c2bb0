"""Writing (N,3) point arrays in the formats the readers understand (tests, tools, samples).

Every file is written atomically (temporary file, then rename).
"""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import plyfile

from ndt_cli.core.arrays import column_bounds
from ndt_cli.errors import OutputError
from ndt_cli.io.atomic import atomic_path

LAS_SCALE = 0.001
"""Coordinate resolution of written LAS/LAZ files, metres."""

WRITE_SUFFIXES: tuple[str, ...] = (".ply", ".las", ".laz", ".pcd", ".xyz", ".txt", ".csv")


def _write_ply(path: Path, points: np.ndarray) -> None:
    vertex = np.empty(len(points), dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    vertex["x"], vertex["y"], vertex["z"] = points.T
    element = plyfile.PlyElement.describe(vertex, "vertex")
    plyfile.PlyData([element], text=False, byte_order="<").write(str(path))


def _las_offsets(points: np.ndarray, target: Path) -> np.ndarray:
    """Whole-metre offsets at the data minimum; checks that LAS integers can hold the points."""
    if not np.isfinite(points).all():
        raise OutputError("LAS/LAZ cannot store NaN or infinite coordinates", target)
    if len(points) == 0:
        return np.zeros(3)
    low, high = column_bounds(points)
    offsets = np.floor(low)
    if (high - offsets).max() / LAS_SCALE >= 2**31 - 1:
        raise OutputError(f"extent too large for LAS at {LAS_SCALE} m resolution", target)
    return offsets


def _write_las(
    path: Path, points: np.ndarray, offsets: np.ndarray, compress: bool, gps_time: np.ndarray | None
) -> None:
    header = laspy.LasHeader(point_format=0 if gps_time is None else 1, version="1.2")
    header.scales = np.full(3, LAS_SCALE)
    header.offsets = offsets
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    if gps_time is not None:
        las.gps_time = np.asarray(gps_time, dtype=np.float64)
    las.write(str(path), do_compress=compress)


def _write_pcd(path: Path, points: np.ndarray) -> None:
    import pypcd4  # here: only PCD needs it, and it is slow to import

    cloud = pypcd4.PointCloud.from_points(points, ("x", "y", "z"), (np.float64,) * 3)
    cloud.save(path, encoding=pypcd4.Encoding.BINARY)


def _write_text(path: Path, points: np.ndarray, sep: str) -> None:
    """Shortest round-trip repr of each float64: full precision, no spurious digits."""
    with path.open("w", encoding="utf-8", newline="\n") as fh:
        if sep == ",":
            fh.write("x,y,z\n")
        for start in range(0, len(points), 100_000):
            block = points[start : start + 100_000].tolist()
            fh.write("".join(f"{x!r}{sep}{y!r}{sep}{z!r}\n" for x, y, z in block))


def write(path: str | Path, points: np.ndarray, gps_time: np.ndarray | None = None) -> None:
    """Write (N,3) points (metres, any frame) atomically; the format follows the extension.

    .ply: binary little endian float64; .las/.laz: 1 mm scale, offsets from the data minimum,
    point format 0, or 1 with ``gps_time`` ((N,) seconds, when each point was measured);
    .pcd: binary float64; .xyz/.txt: space separated, .csv: comma separated with an x,y,z
    header, full float64 precision. Raises :class:`OutputError` if the file cannot be written.
    """
    target = Path(path)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be an (N,3) array, got shape {pts.shape}")
    suffix = target.suffix.lower()
    if suffix not in WRITE_SUFFIXES:
        raise OutputError(
            f"cannot write {suffix or '(no extension)'!r}; writable: {' '.join(WRITE_SUFFIXES)}",
            target,
        )
    if gps_time is not None and (suffix not in (".las", ".laz") or len(gps_time) != len(pts)):
        raise ValueError("times are written to LAS/LAZ only, one per point")
    offsets = _las_offsets(pts, target) if suffix in (".las", ".laz") else None
    with atomic_path(target) as tmp:
        if suffix == ".ply":
            _write_ply(tmp, pts)
        elif offsets is not None:
            _write_las(tmp, pts, offsets, suffix == ".laz", gps_time)
        elif suffix == ".pcd":
            _write_pcd(tmp, pts)
        else:
            _write_text(tmp, pts, "," if suffix == ".csv" else " ")
