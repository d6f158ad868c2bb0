"""Make the shipped sample data: a simulated street sequence of terrestrial laser scans.

Writes ``scan_00.laz`` ... (points in each scanner's own frame, z up, metres),
``poses_T_world_scan.txt`` (the ground truth) and ``README.md`` into ``--out``.
Deterministic: the same arguments always give the same files.

    python tools/make_sample_data.py --out sample_data --seed 7 --n-scans 5
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

try:
    from ndt_cli import io, sim
    from ndt_cli.io import atomic
except ImportError:  # run from a checkout without an installed package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from ndt_cli import io, sim
    from ndt_cli.io import atomic

POSES_NAME = "poses_T_world_scan.txt"


def command(seed: int, n_scans: int, tilt_deg: float) -> str:
    """The command line that reproduces the data (``--out`` aside)."""
    return (
        f"python tools/make_sample_data.py --out sample_data --seed {seed} --n-scans {n_scans}"
        f" --tilt-deg {tilt_deg:g}"
    )


def poses_text(names: list[str], poses: list[np.ndarray], cmd: str) -> str:
    """Pose file: ``#`` header, then per scan its file name and the 16 numbers of T_world_scan."""
    lines = [
        "# Ground truth of the simulated sequence: file name, then the 16 numbers of T_world_scan",
        "# (4x4, row-major, metres). T_world_scan maps the scan's points (scanner frame) into the",
        "# world frame; a pair's T_target_source = inv(T_world_target) @ T_world_source.",
        f"# made by: {cmd.replace(' --out sample_data', '')}",
    ]
    for name, T in zip(names, poses, strict=True):
        lines.append(name + " " + " ".join(f"{v:.17g}" for v in np.asarray(T).ravel()))
    return "\n".join(lines) + "\n"


def readme_text(
    names: list[str],
    scans: list[np.ndarray],
    poses: list[np.ndarray],
    cmd: str,
    tilt_deg: float,
) -> str:
    """README of the sample data folder: what the data is, how it was made, its frames."""
    rows = [
        f"| `{name}` | {len(pts):,} | ({T[0, 3]:.2f}, {T[1, 3]:.2f}, {T[2, 3]:.2f}) "
        f"| {np.degrees(np.arctan2(T[1, 0], T[0, 0])):.1f} |"
        for name, pts, T in zip(names, scans, poses, strict=True)
    ]
    steps = ", ".join(
        f"{np.linalg.norm(b[:3, 3] - a[:3, 3]):.1f}" for a, b in itertools.pairwise(poses)
    )
    level = (
        "levelled (roll = pitch = 0)"
        if tilt_deg == 0
        else f"tilted by up to {tilt_deg:g} deg in roll and pitch"
    )
    table = "\n".join(rows)
    return f"""# Sample data: simulated terrestrial laser scans of a street

Synthetic data, no real measurements: {len(scans)} static terrestrial laser scans of one street,
made by the deterministic ray-casting simulator `ndt_cli/sim/`. The street runs along
the world x axis with buildings on both sides (blocks 8-30 m wide, 6-25 m high, with depth,
gaps and side streets, facade relief of 0.1-0.6 m: window and door niches, balconies,
pilasters, cornices), parked cars, lamp posts, sign posts and tree trunks on a flat ground
(z = 0). Each scan is a full 360 deg x (-60..+80 deg) grid of 1440 x 160 rays from a scanner
1.6 m above the ground; nearest hit with occlusion, maximum range 120 m, Gaussian range
noise 8 mm. Scanners are {level}.
Consecutive standpoints are 13-30 m apart along the street, each with a random heading, so
neighbouring scans overlap well but are not aligned with each other.
Distances between consecutive scanner centres (m): {steps}.

Made with (from the repository root; the same command always gives the same points and poses):

```
{cmd}
```

## Files

| file | points | scanner centre in the world (m) | heading (deg) |
|---|---|---|---|
{table}

* `scan_NN.laz`: LAS 1.2, point format 0, LAZ-compressed, x/y/z in metres with a scale of
  0.001 m (coordinates are rounded to 1 mm) and offsets at the data minimum.
* `{POSES_NAME}`: the ground truth, one line per scan: the file name, then the
  16 numbers of its 4x4 `T_world_scan`, row-major, full double precision; `#` lines are comments.

## Frames

* The points of each scan are in **that scanner's own frame**: origin at the scanner centre,
  z up (the scanner's axis), metres.
* `T_world_scan` maps the points of its scan into the world frame:
  `p_world = R @ p_scan + t` (world: z up, ground plane z = 0, street along x).
* The ground-truth relative transform of a pair, which maps source points into the target
  scan's frame, is `T_target_source = inv(T_world_target) @ T_world_source`.
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("sample_data"))
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--n-scans", type=int, default=5)
    ap.add_argument("--tilt-deg", type=float, default=0.0, help="max roll/pitch of the scanner")
    args = ap.parse_args(argv)
    _, scans, poses = sim.make_sequence(
        seed=args.seed, n_scans=args.n_scans, tilt_deg=args.tilt_deg
    )
    names = [f"scan_{k:02d}.laz" for k in range(len(scans))]
    for name, points in zip(names, scans, strict=True):
        io.write(args.out / name, points)  # LAS 1.2 / format 0, 1 mm, temp file + os.replace
        print(f"{name}: {len(points):,} points")
    cmd = command(args.seed, args.n_scans, args.tilt_deg)
    atomic.write_text(args.out / POSES_NAME, poses_text(names, poses, cmd))
    atomic.write_text(args.out / "README.md", readme_text(names, scans, poses, cmd, args.tilt_deg))
    return 0


if __name__ == "__main__":
    sys.exit(main())
