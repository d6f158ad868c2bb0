"""Control files as surveyors write them, for the sample street: its ground truth turned and
moved onto UTM zone 32N (EPSG:25832) and put on that projection's grid, as a GNSS receiver on
each scanner would give it."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ndt_cli.io.matrices import read_pose_list

SAMPLE = Path(__file__).resolve().parents[1] / "sample_data"
EPSG = 25832
EARTH_RADIUS_M = 6_371_000.0


def utm_truth(yaw_deg: float = 30.0) -> dict[str, np.ndarray]:
    """True ``T_crs_scan`` of each sample scan in EPSG:25832: the truth turned ``yaw_deg``
    about the vertical, moved to (500000, 5400000, 100) m, each scanner put on the grid
    (distances from the street's centre times pyproj's point scale and R / (R + h))."""
    from pyproj import CRS, Proj, Transformer

    G = np.eye(4)
    yaw = np.radians(yaw_deg)
    G[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
    G[:3, 3] = [500_000.0, 5_400_000.0, 100.0]
    truth = {n: G @ T for n, T in read_pose_list(SAMPLE / "poses_T_world_scan.txt").items()}
    crs = CRS.from_epsg(EPSG)
    c = np.mean([T[:3, 3] for T in truth.values()], axis=0)
    lon, lat = Transformer.from_crs(crs, crs.geodetic_crs, always_xy=True).transform(c[0], c[1])
    point = float(np.sqrt(Proj(crs).get_factors(lon, lat).areal_scale))
    scale = point * EARTH_RADIUS_M / (EARTH_RADIUS_M + c[2])
    for T in truth.values():
        T[:2, 3] = c[:2] + scale * (T[:2, 3] - c[:2])
    return truth


def grid_scale_at_street() -> float:
    """The grid scale :func:`utm_truth` applies (grid over ground distance)."""
    truth = utm_truth()
    a, b = truth["scan_00.laz"], truth["scan_04.laz"]
    ground = read_pose_list(SAMPLE / "poses_T_world_scan.txt")
    return float(
        np.linalg.norm(b[:2, 3] - a[:2, 3])
        / np.linalg.norm(ground["scan_04.laz"][:2, 3] - ground["scan_00.laz"][:2, 3])
    )


def control_csv(
    truth: dict[str, np.ndarray],
    scans: Iterable[str],
    swap: tuple[str, str] | None = None,
    columns: tuple[int, int, int] = (0, 1, 2),
) -> str:
    """A control file of the scanners of ``scans`` (4 decimals, blank sigmas: RTK), with a
    header; ``swap``: two stations whose point numbers were swapped; ``columns``: the order
    the coordinates are written in ((1, 0, 2): northing first)."""
    other = dict([swap, swap[::-1]]) if swap else {}
    rows = ["scan,x,y,z,sigma_xy,sigma_z"]
    for name in scans:
        xyz = truth[other.get(name, name)][:3, 3][list(columns)]
        rows.append(f"{name},{xyz[0]:.4f},{xyz[1]:.4f},{xyz[2]:.4f},,")
    return "\n".join(rows) + "\n"
