"""Export benchmark: wall time and peak memory of writing a 10-20 M point campaign.

The campaign is made once into ``benchmarks/.cache/export_<points>``: simulated street scans
(``ndt_cli.sim``), each tiled with jitter until it holds ``points / files`` points, written as LAS
1.4 point format 7 (intensity, GPS time, RGB, classification, an extra-bytes dimension, a WKT
CRS) in georeferenced coordinates near (500000, 5.7e6). Every export runs in a fresh child
process (``benchmarks/measure.py``), whose peak resident memory comes from
``getrusage(RUSAGE_CHILDREN)``. Figures are printed, never asserted::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/export_bench.py [--points 15000000]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import laspy  # noqa: E402
import numpy as np  # noqa: E402
from laspy.vlrs.known import WktCoordinateSystemVlr  # noqa: E402

from ndt_cli import sim  # noqa: E402
from ndt_cli.core.transforms import translation  # noqa: E402

CACHE = ROOT / "benchmarks" / ".cache"
WKT = 'PROJCS["ETRS89 / UTM zone 32N",AUTHORITY["EPSG","25832"]]'
GEO = np.array([500123.0, 5700456.0, 87.0])  # world (simulator) origin in the georeferenced frame
WRITE_CHUNK = 1_000_000


def _header(offsets: np.ndarray) -> laspy.LasHeader:
    header = laspy.LasHeader(point_format=7, version="1.4")
    header.scales = np.full(3, 0.001)
    header.offsets = offsets
    header.add_extra_dim(laspy.ExtraBytesParams("reflectance", "int16", "dB x 100"))
    header.vlrs.append(WktCoordinateSystemVlr(WKT))
    header.global_encoding.wkt = True
    return header


def _write_tiled(path: Path, pts: np.ndarray, n: int, seed: int) -> None:
    """``n`` points: copies of ``pts`` (scanner frame + GEO), each jittered by 5 mm."""
    rng = np.random.default_rng(seed)
    with laspy.open(path, mode="w", header=_header(np.floor(pts.min(axis=0)))) as writer:
        for start in range(0, n, WRITE_CHUNK):
            m = min(WRITE_CHUNK, n - start)
            idx = (start + np.arange(m)) % len(pts)
            rec = laspy.ScaleAwarePointRecord.zeros(m, header=writer.header)
            xyz = pts[idx] + rng.normal(0.0, 0.005, (m, 3))
            rec.x, rec.y, rec.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
            rec.intensity = rng.integers(0, 65536, m, dtype=np.uint16)
            rec.gps_time = 1.4e9 + (start + np.arange(m)) * 1e-6
            for c in ("red", "green", "blue"):
                rec[c] = rng.integers(0, 65536, m, dtype=np.uint16)
            rec.classification = rng.integers(0, 20, m, dtype=np.uint8)
            rec.array["reflectance"] = rng.integers(-3000, 3000, m).astype(np.int16)
            writer.write_points(rec)


def campaign(points: int, files: int) -> tuple[list[Path], list[np.ndarray]]:
    """The LAS files and their ``T_world_file`` (file to georeferenced world), made once."""
    folder = CACHE / f"export_{points}_{files}"
    _, scans, poses = sim.make_sequence(
        seed=5, n_scans=files, spacing=(13.0, 17.0), scan_kwargs={"n_azimuth": 360}
    )
    paths = [folder / f"scan_{k:02d}.las" for k in range(files)]
    offsets = [np.round(T[:3, 3] + GEO) for T in poses]  # rough georeference of each file
    transforms = [
        translation(GEO) @ T @ translation(-c) for T, c in zip(poses, offsets, strict=True)
    ]
    if not all(p.exists() for p in paths):
        folder.mkdir(parents=True, exist_ok=True)
        print(f"making {points:,} points in {folder} (once) ...", flush=True)
        for k, (p, pts, c) in enumerate(zip(paths, scans, offsets, strict=True)):
            _write_tiled(p, pts + c, points // files, seed=k)
    return paths, transforms


def child(out: str, voxel: float | None, points: int, files: int) -> None:
    """Run one export (in the measured child process) and print its result as the last line."""
    from ndt_cli.io.export import ExportScan, export

    paths, transforms = campaign(points, files)
    scans = [
        ExportScan(p, p.name, k, T, anchor=k == 0)
        for k, (p, T) in enumerate(zip(paths, transforms, strict=True))
    ]
    t0 = time.perf_counter()
    result = export(scans, out, voxel=voxel)
    size = Path(out).stat().st_size / 1e6
    print(
        json.dumps(
            {"export_s": time.perf_counter() - t0, "written": result.points_written, "mb": size}
        )
    )


def measure(out: Path, voxel: float | None, points: int, files: int) -> dict:
    cmd = [sys.executable, str(Path(__file__)), "--child", str(out), "--points", str(points)]
    cmd += ["--files", str(files)] + (["--voxel", str(voxel)] if voxel else [])
    run = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "measure.py"), *cmd],
        capture_output=True,
        text=True,
        check=True,
    )
    figures = json.loads(run.stdout.strip().splitlines()[-1])
    return {**figures, **json.loads(figures["last"])}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=15_000_000)
    parser.add_argument("--files", type=int, default=5)
    parser.add_argument("--voxel", type=float)
    parser.add_argument("--child")
    parser.add_argument("--only", nargs="*", help="output names to run, e.g. merged.laz")
    args = parser.parse_args()
    if args.child:
        child(args.child, args.voxel, args.points, args.files)
        return 0
    campaign(args.points, args.files)
    out_dir = CACHE / "export_out"
    out_dir.mkdir(parents=True, exist_ok=True)
    cases = [("merged.laz", None), ("merged.las", None), ("merged.ply", None)]
    cases += [("merged.e57", None), ("thin_2cm.laz", 0.02), ("thin_2mm.laz", 0.002)]
    print(f"{args.points:,} points in {args.files} LAS files (format 7, extra bytes, WKT CRS)")
    columns = ("output", "voxel", "written", "wall s", "pts/s", "peak MB", "MB")
    widths = (-14, 7, 13, 9, 12, 9, 8)
    print(
        "".join(
            f"{c:<{-w}}" if w < 0 else f"{c:>{w}}" for c, w in zip(columns, widths, strict=True)
        )
    )
    for name, voxel in cases:
        if args.only and name not in args.only:
            continue
        r = measure(out_dir / name, voxel, args.points, args.files)
        rate = args.points / r["export_s"]
        print(
            f"{name:<14}{voxel or '-':>7}{r['written']:>13,}{r['wall_s']:>9.1f}{rate:>12,.0f}"
            f"{r['peak_mb']:>9.0f}{r['mb']:>8.0f}",
            flush=True,
        )
        (out_dir / name).unlink()
    return 0


if __name__ == "__main__":
    sys.exit(main())
