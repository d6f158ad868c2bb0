"""A scanner set up on a tripod at a standpoint of a simulated campaign: its pose (any heading,
tilted or level, its centre at a height above the ground) and its scan.

Frames and units as in :mod:`ndt_cli.sim.scanner`: metres, world z up, ``T_world_scan`` maps
scanner points into the world. Every draw comes from the generator passed in, in a fixed order
(tilt, height, heading; then the scan's noise seed), so that a campaign stays deterministic in
its seed.
"""

from __future__ import annotations

import numpy as np

from ndt_cli.sim.scanner import scanner_pose, simulate_scan
from ndt_cli.sim.scene import Scene


def tripod_pose(
    scene: Scene,
    xy: np.ndarray,
    rng: np.random.Generator,
    tilt_deg: float,
    heights: tuple[float, float],
) -> np.ndarray:
    """``T_world_scan`` of a scanner over world ``xy`` (m): roll and pitch uniform in
    +-``tilt_deg`` degrees (none when 0), its centre ``heights`` m (uniform) above the ground,
    any heading."""
    roll, pitch = rng.uniform(-tilt_deg, tilt_deg, 2) if tilt_deg > 0 else (0.0, 0.0)
    height = float(scene.ground_z(xy[0], xy[1])) + rng.uniform(*heights)
    return scanner_pose(xy[0], xy[1], rng.uniform(-180.0, 180.0), height, roll, pitch)


def tripod_scan(
    seen: Scene,
    T_world_scan: np.ndarray,
    rng: np.random.Generator,
    k: int,
    rays: tuple[int, int],
    range_noise: float,
) -> np.ndarray:
    """The ``k``-th scan of a campaign: what the scanner at ``T_world_scan`` sees of ``seen``
    with ``rays`` (azimuths x elevations) and ``range_noise`` (m), (N, 3) in its frame."""
    return simulate_scan(
        seen,
        T_world_scan,
        n_azimuth=rays[0],
        n_elevation=rays[1],
        range_noise=range_noise,
        seed=int(rng.integers(0, 2**31 - 1)) + k,
    )
