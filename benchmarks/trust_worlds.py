"""The trust sweep's worlds beside the streets (``benchmarks/trust_sweep.py``): building
interiors, forests and city districts, each case a simulated campaign with its ground truth.

- Interiors (:class:`~ndt_cli.sim.indoor.FloorWorld`): office floors of three layouts (rooms
  on both sides of a corridor, on one side, an open-plan hall beside a corridor), corridors
  2-3 m wide, ceilings 2.7-3.3 m, 10-60 % of the doors closed, furniture sparse to crowded,
  pilasters or none, standpoints 5-12 m apart along the corridor and in rooms seen through
  their doorways. Hostile: a corridor with every door closed and no columns, the same turned
  by 180 degrees (only the anchor can be known).
- Forests (:class:`~ndt_cli.sim.forest.ForestWorld`): plots on slopes of 0-15 % in varied
  directions, 250-700 stems a hectare of 0.1-0.8 m, some leaning, shrubs and fallen logs;
  scanned on a 3 x 3 grid or along a line, 10-20 m apart, scanners tilted up to 1 degree.
- Districts (:class:`~ndt_cli.sim.district.DistrictWorld`): 2 x 2 blocks walked round their
  ring and through the middle street (loops closing), grades, people and traffic.
- Shuffled routes (:class:`ShuffledRoute`): one long straight street of sparse scans 16 m
  apart, given in a random order (files merged from two scanners, a renumbering): every scan
  is placed by coarse matches, none by the campaign order; an 18 m street of constant width
  fits itself shifted by a few blocks.

Every scan of a clean case should come out ok and right.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.trust_cases import Case, cached
from ndt_cli import sim
from ndt_cli.sim.district import DistrictWorld, scan_district
from ndt_cli.sim.forest import ForestWorld, scan_forest
from ndt_cli.sim.indoor import FloorWorld, scan_floor

QUICK_RAYS = (1000, 120)  # azimuths x elevations of the reduced tier: about 0.1 M points


def floors(quick: bool) -> list[FloorWorld]:
    """Office floors: at least 8 (2 in the reduced tier), the first ones clean."""
    F = FloorWorld
    if quick:
        return [
            F(seed=51, length=30.0, corridor_width=2.4, closed=0.3, rays=QUICK_RAYS),
            F(seed=52, layout="open", length=30.0, ceiling=2.8, closed=0.2, rays=QUICK_RAYS),
        ]
    return [
        F(seed=1),
        F(seed=2, corridor_width=2.0, ceiling=2.7, closed=0.6, furniture=2.0, spacing=(5, 8)),
        F(seed=3, layout="single", corridor_width=2.8, ceiling=3.3, closed=0.1, furniture=0.3),
        F(seed=4, layout="open", corridor_width=3.0, ceiling=3.2, closed=0.4, furniture=1.5),
        F(seed=5, corridor_width=2.2, ceiling=2.8, closed=0.5, furniture=0.5, columns=False),
        F(seed=6, layout="single", ceiling=2.9, closed=0.2, furniture=2.0, room_scans=3),
        F(seed=7, layout="open", corridor_width=2.0, ceiling=2.7, closed=0.1, furniture=0.3),
        F(seed=8, length=60.0, corridor_width=3.0, ceiling=3.3, spacing=(8, 12), room_scans=3),
        F(seed=9, corridor_width=2.6, ceiling=3.1, furniture=1.2, tilt_deg=0.8, spacing=(5, 9)),
        *held_out_floors(),
    ]


def held_out_floors() -> list[FloorWorld]:
    """Five floors added after the indoor rules were set, measured once: what the rules do
    on layouts they were not chosen on."""
    F = FloorWorld
    return [
        F(seed=21, length=50.0, corridor_width=2.3, closed=0.35, furniture=0.8, spacing=(6, 10)),
        F(seed=22, layout="open", corridor_width=2.5, ceiling=2.9, closed=0.3),
        F(
            seed=23,
            layout="single",
            corridor_width=2.2,
            ceiling=3.1,
            closed=0.4,
            furniture=1.8,
            tilt_deg=0.6,
            room_scans=3,
        ),
        F(seed=24, corridor_width=2.8, ceiling=2.75, closed=0.15, furniture=2.5, spacing=(5, 7)),
        F(
            seed=25,
            layout="open",
            length=56.0,
            corridor_width=2.1,
            ceiling=3.3,
            closed=0.5,
            furniture=0.5,
            spacing=(7, 11),
        ),
    ]


def corridor_floor() -> FloorWorld:
    """Every door closed, no pilasters, no furniture to see, one window at each end: the
    corridor looks the same turned by 180 degrees (the closed leaves, 5-9 cm behind the
    wall's face, are the only clue)."""
    return FloorWorld(seed=10, closed=1.0, columns=False, furniture=0.0, room_scans=0)


def forests(quick: bool) -> list[ForestWorld]:
    """Forest plots: at least 4 (1 in the reduced tier)."""
    W = ForestWorld
    if quick:
        return [W(seed=61, slope=0.1, slope_deg=250.0, shape=(1, 4), rays=QUICK_RAYS)]
    return [
        W(seed=1, slope=0.085, slope_deg=40.0),
        W(seed=2, slope=0.15, slope_deg=200.0, stems=600, leaning=0.4, lean_deg=6.0, shape=(1, 6)),
        W(seed=3, slope=0.0, stems=250, diameter=(0.2, 0.8), shrubs=100, logs=80, tilt_deg=0.0),
        W(seed=4, slope=0.12, slope_deg=300.0, stems=700, diameter=(0.1, 0.4), spacing=(10, 14)),
        W(seed=5, slope=0.05, slope_deg=90.0, stems=300, shape=(1, 5), spacing=(15, 20)),
    ]


def districts(quick: bool) -> list[DistrictWorld]:
    """City districts: at least 2 of about 36 scans (one smaller in the reduced tier)."""
    D = DistrictWorld
    if quick:
        return [
            D(
                seed=71,
                blocks=(1, 2),
                pitch=(60.0, 56.0),
                spacing=22.0,
                spur=25.0,
                heading_deg=15.0,
                grade=0.04,
                people=10,
            )
        ]
    return [
        D(seed=1, heading_deg=25.0, grade=0.03, cross_fall=0.01, tilt_deg=0.5, trees=True),
        D(seed=2, heading_deg=-60.0, grade=-0.05, curve=0.0002, people=20, traffic=2),
        D(seed=3, pitch=(52.0, 64.0), grade=0.02, tilt_deg=1.0, people=10, spacing=18.0),
    ]


@dataclass(frozen=True)
class ShuffledRoute:
    """``sim.route`` of ``n_scans`` (``seed``), shuffled by ``sim.shuffled`` (``order``)."""

    seed: int
    n_scans: int
    order: int
    rays: tuple[int, int] = (1500, 200)

    def describe(self) -> str:
        return f"route of {self.n_scans} scans, seed {self.seed}, shuffled ({self.order})"


def scan_shuffled_route(world: ShuffledRoute) -> tuple[object, list, list[np.ndarray]]:
    route = sim.route(seed=world.seed, n_scans=world.n_scans, rays=world.rays)
    mixed = sim.shuffled(route, seed=world.order)
    return mixed.scene, list(mixed.scans), list(mixed.poses)


def routes(quick: bool) -> list[ShuffledRoute]:
    """Shuffled routes: 16 scans (the reduced tier), then 32, 64, 96 and 128 (the
    benchmark's route)."""
    first = [ShuffledRoute(3, 16, 2)]
    more = [ShuffledRoute(7, 32, 3), ShuffledRoute(5, 64, 1), ShuffledRoute(9, 96, 2)]
    return first if quick else [*first, *more, ShuffledRoute(5, 128, 1)]


def _clean(name: str, files: list, truth: list) -> Case:
    return Case(name, files, truth, [True] * len(files))


def interior_cases(quick: bool) -> list[Case]:
    """The floors, then the hostile corridor (full tier)."""
    modules = ("ground", "scene", "scanner", "indoor")
    out = [_clean(w.describe(), *cached(w, scan_floor, modules, "f")) for w in floors(quick)]
    if not quick:
        w = corridor_floor()
        files, truth = cached(w, scan_floor, modules, "f")
        expected = [k == 0 for k in range(len(files))]
        out.append(Case(f"{w.describe()}: closed corridor", files, truth, expected))
    return out


def forest_cases(quick: bool) -> list[Case]:
    modules = ("ground", "scene", "scanner", "forest")
    return [_clean(w.describe(), *cached(w, scan_forest, modules, "w")) for w in forests(quick)]


def district_cases(quick: bool) -> list[Case]:
    modules = ("ground", "scene", "scanner", "worlds", "campaigns", "district")
    return [_clean(w.describe(), *cached(w, scan_district, modules, "d")) for w in districts(quick)]


def route_cases(quick: bool) -> list[Case]:
    modules = ("ground", "scene", "scanner", "campaigns")
    return [
        _clean(w.describe(), *cached(w, scan_shuffled_route, modules, "r")) for w in routes(quick)
    ]
