"""Deterministic terrestrial-laser-scanner simulator of street scenes, city districts, building
interiors and forest plots (tests, samples, benchmarks).

Frames: the **world frame** (right-handed, z up, ground z = 0, the street along x) and each
**scanner frame**; ``T_world_scan`` maps scanner points into the world. The same seed always
gives bit-identical output.
"""

from ndt_cli.sim.campaigns import (
    Survey,
    block_loop,
    junction,
    route,
    shuffled,
    two_sites,
    write_route,
    write_survey,
)
from ndt_cli.sim.district import DistrictWorld, scan_district
from ndt_cli.sim.forest import ForestWorld, scan_forest
from ndt_cli.sim.ground import Ground
from ndt_cli.sim.indoor import FloorWorld, floor_scene, scan_floor
from ndt_cli.sim.scanner import make_sequence, scanner_pose, simulate_scan
from ndt_cli.sim.scene import Scene, make_street
from ndt_cli.sim.worlds import StreetWorld, passers_by, scan_street

__all__ = [
    "DistrictWorld",
    "FloorWorld",
    "ForestWorld",
    "Ground",
    "Scene",
    "StreetWorld",
    "Survey",
    "block_loop",
    "floor_scene",
    "junction",
    "make_sequence",
    "make_street",
    "passers_by",
    "route",
    "scan_district",
    "scan_floor",
    "scan_forest",
    "scan_street",
    "scanner_pose",
    "shuffled",
    "simulate_scan",
    "two_sites",
    "write_route",
    "write_survey",
]
