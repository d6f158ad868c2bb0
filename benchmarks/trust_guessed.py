"""The trust sweep's world of approximate poses (``ndt-chain --init-poses``): scans of the
other worlds, each given a pose within the default ``--init-sigma`` of its true one (1 m and
5 degrees, about the scanner's own position: GNSS and a compass, a placement by hand).

Every link between two scans with a guess is registered from the search and from the guess
(:mod:`ndt_cli.pipeline.guesses`), so this world judges the guess's path: its refinement from
cells as coarse as twice its uncertainty, where a pose may slide along a uniform scene. Busy
streets with scans 36-48 m apart (pedestrians and a passing car in every scan) are the hard
case: the search alone misses some of their pairs, and a guess must rescue them without
making a wrong pose ok. Hostile: the same streets with guesses 3-5 m and 20-30 degrees off
while they claim 1 m and 5 degrees; a wrong guess must never make a wrong link ok.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from benchmarks.trust_cases import Case, clean_case, quick_streets
from benchmarks.trust_worlds import forest_cases, interior_cases
from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.pipeline.options import DEFAULT_SIGMA
from ndt_cli.sim.worlds import StreetWorld

BUSY = {"n_scans": 4, "spacing": (36, 48), "people": 20, "traffic": 1, "grade": 0.03}
BUSY |= {"camber": 0.02, "tilt_deg": 0.5}


def perturbed(
    truth: list[np.ndarray], seed: int, reach: tuple[float, float], least: float = 0.0
) -> dict[int, np.ndarray]:
    """Each true ``T_world_scan`` moved about the scanner's own position: by up to
    ``reach[0]`` m (uniform over the disc; at least ``least`` times it) and ``reach[1]``
    degrees (uniform, at least ``least`` times it), seeded."""
    rng = np.random.default_rng([seed, 11])
    out = {}
    for k, T in enumerate(truth):
        r = reach[0] * np.sqrt(rng.uniform(least**2, 1.0))
        a = rng.uniform(0.0, 2.0 * np.pi)
        yaw = rng.choice([-1.0, 1.0]) * reach[1] * rng.uniform(least, 1.0)
        out[k] = T @ pose2d_matrix(r * np.cos(a), r * np.sin(a), np.radians(yaw))
    return out


def _guessed(case: Case, seed: int, reach=DEFAULT_SIGMA, least: float = 0.0) -> Case:
    name = f"{case.name}, guessed within {reach[0]:g} m / {reach[1]:g} deg"
    return replace(case, name=name, guesses=perturbed(case.truth, seed, reach, least))


def busy_streets(quick: bool) -> list[StreetWorld]:
    """Busy streets of scans 36-48 m apart (2 in the reduced tier)."""
    seeds = (13, 15) if quick else (13, 15, 16, 17, 18)
    return [StreetWorld(seed=s, **BUSY) for s in seeds]


def guessed_cases(quick: bool) -> list[Case]:
    """Busy and sparse streets, interiors and forests with guesses within the default sigma;
    in the full tier also with guesses far outside it (hostile: every scan should still be
    ok, as the search alone finds them)."""
    streets = [clean_case(w) for w in busy_streets(quick)]
    others = streets + [clean_case(w) for w in quick_streets()]
    others += interior_cases(True) + forest_cases(True)
    if not quick:
        others += interior_cases(False)[:3] + forest_cases(False)[:2]
    out = [_guessed(c, k) for k, c in enumerate(others)]
    if not quick:
        far = [clean_case(w) for w in quick_streets()]
        lying = [_guessed(c, 100 + k, (5.0, 30.0), least=0.6) for k, c in enumerate(far)]
        out += [replace(c, hostile=True) for c in lying]
    return out
