"""Make the shipped sample data: a simulated street sequence of terrestrial laser scans.

Writes ``scan_00.laz`` ... (points in each scanner's own frame, z up, metres) and
``poses_T_world_scan.txt`` (the ground truth) into ``--out``. Deterministic: the same seed
always gives the same files.

    python tools/make_sample_data.py --out sample_data --seed 7 --n-scans 5
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ndt_cli import atomic, io, simulate


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("sample_data"))
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--n-scans", type=int, default=5)
    ap.add_argument("--tilt-deg", type=float, default=0.0, help="max roll/pitch of the scanner")
    args = ap.parse_args(argv)
    _, scans, poses = simulate.make_sequence(
        seed=args.seed, n_scans=args.n_scans, tilt_deg=args.tilt_deg
    )
    lines = [
        "# Ground truth of the simulated sequence: file name, then the 16 numbers of T_world_scan",
        "# (4x4, row-major, metres). T_world_scan maps the scan's points (scanner frame) into the",
        "# world frame; a pair's T_target_source = inv(T_world_target) @ T_world_source.",
        f"# made by: python tools/make_sample_data.py --seed {args.seed} --n-scans {args.n_scans}"
        f" --tilt-deg {args.tilt_deg:g}",
    ]
    for k, (points, T) in enumerate(zip(scans, poses, strict=True)):
        name = f"scan_{k:02d}.laz"
        io.write(args.out / name, points)
        lines.append(name + " " + " ".join(f"{v:.17g}" for v in T.ravel()))
        print(f"{name}: {len(points):,} points")
    atomic.write_text(args.out / "poses_T_world_scan.txt", "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
