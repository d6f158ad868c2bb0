"""The options of a campaign's network, as the commands check them
(:func:`~ndt_cli.pipeline.inputs.network_options`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ndt_cli.pipeline.control import Station
from ndt_cli.pipeline.network import PlannedLink

DEFAULT_SIGMA = (1.0, 5.0)  # m, degrees: a guess from GNSS or a placement by hand


@dataclass(frozen=True)
class NetworkOptions:
    """Which links the network holds and how it is solved: each scan's ``neighbours`` nearest
    scans within ``radius`` m (None: 2.2 times the median distance between nearest scans; one
    neighbour: the classic chain in the order given), whether it is ``adjust``-ed, and the
    user's ``pairs`` (campaign indices)."""

    neighbours: int = 4
    adjust: bool = True
    radius: float | None = None
    pairs: tuple[PlannedLink, ...] = ()
    stations: tuple[Station, ...] = ()  # of known coordinates (the world: theirs); a station
    # counts once its scan is in the campaign (field mode: the control file is read first)
    crs: str = ""  # the coordinate system of the stations, as WKT ("" when not given)
    grid_scale: float = 1.0  # its grid distance over ground distance at the stations
    init_poses: Mapping[int, np.ndarray] = field(default_factory=dict)  # approximate
    # T_world_scan per scan (--init-poses), each within init_sigma (m, degrees)
    init_sigma: tuple[float, float] = DEFAULT_SIGMA

    @property
    def classic(self) -> bool:
        return self.neighbours == 1

    @property
    def given(self) -> set[tuple[int, int]]:
        """The user's pairs (lo, hi)."""
        return {k.pair for k in self.pairs}
