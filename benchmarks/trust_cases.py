"""The cases of the trust sweep (``benchmarks/trust_sweep.py``) on streets, and what every
world's cases share: a :class:`Case` (files, true poses, the expected verdicts) and the cache
of simulated scans (``benchmarks/.cache/trust``, keyed by the simulator's sources and the
world's parameters).

Clean streets (at least 8 scans each) vary the ground (grades up to 8 %, vertical curves,
camber, cross-fall), the scanners (tilted up to 1 deg, or compensated), the density (0.2 M and
2 M points a scan), the spacing (up to 35 m), the clutter (trees, people, passing cars) and
the shape (bends); hostile cases put a scan of another street or a truncated scan in the
middle of a street, run a corridor of uniform facades, append scans of another street, and
register scans of different streets directly. The real MULLS street sequence (``../shared``)
is compared with its published ICP reference.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.data import sim_key
from ndt_cli import io, sim
from ndt_cli.analysis import trust
from ndt_cli.config import Config
from ndt_cli.ndt.prepare import prepare
from ndt_cli.ndt.register import register_prepared
from ndt_cli.sim.worlds import DENSE, StreetWorld

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / ".cache" / "trust"
SHARED = ROOT.parent / "shared" / "data"


def clean_streets() -> list[StreetWorld]:
    """At least 20 clean streets of at least 8 scans across the parameters."""
    W = StreetWorld
    return [
        W(seed=1, grade=0.02, camber=0.02, tilt_deg=0.5),
        W(seed=2, grade=0.03, camber=0.025, tilt_deg=0.3, rays=DENSE, n_scans=6 + 2),
        W(seed=3, grade=0.05, curve=0.0003, cross_fall=0.015, tilt_deg=0.8),
        W(seed=4, grade=0.08, camber=0.03, tilt_deg=1.0),
        W(seed=5, grade=-0.07, curve=-0.0004, camber=0.02, tilt_deg=1.0, spacing=(15, 30)),
        W(seed=6, grade=0.04, camber=0.035, compensated=True),
        W(seed=7, grade=0.06, cross_fall=0.025, tilt_deg=0.6, trees=True),
        W(seed=8, grade=0.04, camber=0.02, tilt_deg=0.5, people=15, traffic=1, trees=True),
        W(seed=9, grade=0.05, camber=0.03, tilt_deg=0.7, people=25, traffic=2, spacing=(15, 35)),
        W(seed=10, grade=0.02, curve=0.0005, camber=0.025, tilt_deg=0.4, bend_deg=20),
        W(seed=11, grade=0.03, camber=0.02, tilt_deg=0.6, bend_deg=-30, n_scans=16),
        W(seed=12, grade=0.0, camber=0.03, tilt_deg=0.9, spacing=(20, 35)),
        W(seed=13, grade=0.07, curve=-0.0003, tilt_deg=0.3, rays=DENSE),
        W(seed=14, grade=0.01, cross_fall=0.02, compensated=True, trees=True, people=10),
        W(seed=15, grade=0.06, camber=0.035, tilt_deg=1.0, spacing=(20, 35), people=20),
        W(seed=16, grade=-0.04, camber=0.015, tilt_deg=0.5, bend_deg=15, trees=True),
        W(seed=17, grade=0.05, curve=0.0004, cross_fall=0.01, tilt_deg=0.8, n_scans=12),
        W(seed=18, grade=0.08, camber=0.02, compensated=True, spacing=(15, 30)),
        W(seed=19, grade=0.03, camber=0.03, tilt_deg=0.5, rays=(1000, 120)),
        W(seed=20, grade=0.04, camber=0.025, tilt_deg=0.6, rays=DENSE, people=20, traffic=2),
        W(seed=21, grade=-0.02, curve=0.0005, camber=0.01, tilt_deg=1.0, bend_deg=35),
        W(seed=22, grade=0.0, tilt_deg=0.0),
        W(
            seed=23,
            grade=0.06,
            camber=0.02,
            tilt_deg=0.7,
            trees=True,
            people=20,
            traffic=2,
            spacing=(20, 35),
            n_scans=10,
        ),
        W(seed=24, grade=0.03, camber=0.035, tilt_deg=0.4, spacing=(13, 22), n_scans=12),
    ]


def quick_streets() -> list[StreetWorld]:
    """The reduced tier (``--quick``, and the tests): three varied sparse streets."""
    W = StreetWorld
    return [
        W(seed=31, grade=0.05, curve=0.0003, camber=0.025, tilt_deg=0.8),
        W(seed=32, grade=-0.06, camber=0.03, tilt_deg=0.6, people=15, traffic=1, trees=True),
        W(seed=33, grade=0.03, cross_fall=0.02, compensated=True, bend_deg=20),
    ]


@dataclass(frozen=True)
class Case:
    """A campaign to run: its scans (files), true poses, which scans should come out ok,
    approximate poses of its scans (``--init-poses``; none: the search alone), and whether it is
    hostile though every scan should be ok (its guesses lie about their uncertainty)."""

    name: str
    files: list[Path]
    truth: list[np.ndarray]
    expected: list[bool]
    guesses: dict[int, np.ndarray] = field(default_factory=dict)
    hostile: bool = False


Simulate = Callable[[object], tuple[object, list[np.ndarray], list[np.ndarray]]]


def cached(
    world: object, simulate: Simulate, modules: tuple[str, ...], prefix: str
) -> tuple[list[Path], list[np.ndarray]]:
    """The world's scans as LAS files and their true poses, simulated once: the cache is keyed
    by the sources of the simulator's ``modules`` (``ndt_cli/sim/<name>.py``) and the world's
    parameters (``repr``)."""
    folder = CACHE / f"{prefix}{world.seed}_{sim_key(world, modules)}"
    poses_file = folder / "poses.npy"
    if poses_file.exists():
        poses = list(np.load(poses_file))
        files = [folder / f"scan_{k:02d}.las" for k in range(len(poses))]  # in the poses' order
        if all(f.exists() for f in files):
            return files, poses
    folder.mkdir(parents=True, exist_ok=True)
    print(f"  simulating {world.describe()} ...", flush=True)
    _, scans, poses = simulate(world)
    files = [folder / f"scan_{k:02d}.las" for k in range(len(scans))]
    for f, pts in zip(files, scans, strict=True):
        io.write(f, pts)
    np.save(poses_file, np.array(poses))
    return files, poses


def simulated(world: StreetWorld) -> tuple[list[Path], list[np.ndarray]]:
    """A street's scans as LAS files and their true poses, cached."""
    return cached(world, sim.scan_street, ("ground", "scene", "scanner", "worlds"), "s")


def clean_case(world: StreetWorld) -> Case:
    files, truth = simulated(world)
    return Case(world.describe(), files, truth, [True] * len(files))


def foreign_case(seed: int) -> Case:
    """A sparse street with the middle scan taken from another street."""
    files, truth = simulated(StreetWorld(seed=seed, grade=0.04, camber=0.025, tilt_deg=0.5))
    other, _ = simulated(StreetWorld(seed=seed + 500, n_scans=2, grade=-0.03, tilt_deg=0.5))
    mid = len(files) // 2
    files = [*files[:mid], other[0], *files[mid + 1 :]]
    expected = [k != mid for k in range(len(files))]
    return Case(f"seed {seed}: a scan of another street in the middle", files, truth, expected)


def truncated_case(seed: int) -> Case:
    """A sparse street whose middle scan keeps only a 60 degree sector of its points."""
    files, truth = simulated(StreetWorld(seed=seed, grade=0.05, camber=0.02, tilt_deg=0.6))
    mid = len(files) // 2
    pts = io.read(files[mid]).points
    az = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
    cut = files[mid].with_name("truncated.las")
    if not cut.exists():
        io.write(cut, pts[np.abs(az) < 30.0])
    files = [*files[:mid], cut, *files[mid + 1 :]]
    expected = [k != mid for k in range(len(files))]
    return Case(f"seed {seed}: a truncated scan in the middle", files, truth, expected)


def corridor_case(seed: int) -> Case:
    """Uniform facades: the position along the corridor is unobservable (only the anchor
    should be ok)."""
    files, truth = simulated(StreetWorld(seed=seed, corridor=True, grade=0.03, tilt_deg=0.5))
    expected = [k == 0 for k in range(len(files))]
    return Case(f"seed {seed}: corridor", files, truth, expected)


def two_streets_case(seed: int) -> Case:
    """Eight scans of one street, then four of another (only the first street in the anchor's
    frame)."""
    a, ta = simulated(StreetWorld(seed=seed, grade=0.03, camber=0.02, tilt_deg=0.5))
    b, tb = simulated(StreetWorld(seed=seed + 500, n_scans=4, grade=-0.05, tilt_deg=0.5))
    far = np.eye(4)
    far[:3, 3] = (5000.0, 0.0, 0.0)  # never correct in the anchor's frame
    expected = [True] * len(a) + [False] * len(b)
    return Case(f"seed {seed}: two streets", [*a, *b], [*ta, *[far @ T for T in tb]], expected)


def mulls_case() -> Case | None:
    folder = SHARED / "mulls_demo_hdl64_sequence"
    if not folder.is_dir():
        return None
    rel = np.loadtxt(folder / "reference_icp_relative_4x4.txt").reshape(-1, 4, 4)
    poses = [np.eye(4)]
    for T in rel:
        poses.append(poses[-1] @ T)
    files = sorted(folder.glob("*.pcd"))
    return Case("real: MULLS HDL-64 street (ICP reference)", files, poses, [True] * len(files))


def cross_scene_pairs(cfg: Config, n: int = 12) -> list[dict]:
    """Scans of different streets registered directly (every one wrong): a row per pair."""
    worlds = quick_streets() + clean_streets()[: max(3, n // 4)]
    files = [simulated(w)[0] for w in worlds]
    m = len(files)
    rows = []
    for k in range(n):
        a, b = files[k % m][k // m % 3], files[(k + 1 + k // m) % m][(k + 1) % 3]
        pa, pb = (prepare(io.read(f).points, cfg, f) for f in (a, b))
        r = register_prepared(pa, pb, cfg)
        rows.append(
            {
                "case": "cross-scene",
                "target": 0,
                "source": 1,
                "kind": "cross",
                "correct": False,
                "status": r.status,  # written as its value
                "state": "",
                **trust.metrics(r),
                "warnings": "; ".join(r.warnings),
            }
        )
    return rows


def street_cases(quick: bool) -> list[Case]:
    """The streets' cases: clean streets, then the hostile ones (and the real sequence)."""
    streets = quick_streets() if quick else clean_streets()
    out = [clean_case(w) for w in streets]
    out += [foreign_case(41), truncated_case(42), corridor_case(43)]
    if not quick:
        out += [foreign_case(44), truncated_case(45), two_streets_case(46)]
        mulls = mulls_case()
        if mulls is not None:
            out.append(mulls)
    return out
