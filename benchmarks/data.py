"""Benchmark data, made once and cached in ``benchmarks/.cache``: simulated street scans at full
terrestrial density (~2 M points each, LAS), the same street scanned with a tenth of the rays
(~0.2 M points each), the same standpoints at today's density (~17 M points each: LAZ, the
first two as LAS and E57 too) and large files tiled from the full scans for the scaling curve.
The cache key includes the simulator's source, so a changed simulator remakes the data.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import laspy
import numpy as np

from ndt_cli import io, sim
from ndt_cli.io.matrices import format_matrix
from ndt_cli.io.writers import LAS_SCALE

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "benchmarks" / ".cache"
N_SCANS = 6
SEED = 7
RAYS = {"n_azimuth": 4500, "n_elevation": 640}  # ~2 M points per scan
SMALL_RAYS = {"n_azimuth": 1424, "n_elevation": 202}  # a tenth of the rays: ~0.2 M points


def sim_key(params: object, modules: tuple[str, ...] | None = None) -> str:
    """A cache key of simulated data: the sources of the simulator's ``modules``
    (``ndt_cli/sim/<name>.py``; None: all of them) and the parameters' ``repr``."""
    folder = ROOT / "ndt_cli" / "sim"
    sources = (
        sorted(folder.glob("*.py")) if modules is None else [folder / f"{m}.py" for m in modules]
    )
    text = b"".join(f.read_bytes() for f in sources)
    return hashlib.sha256(text + repr(params).encode()).hexdigest()[:12]


def _key(rays: dict[str, int]) -> str:
    return sim_key((N_SCANS, SEED, rays))


def street() -> tuple[list[Path], Path]:
    """Six ~2 M-point LAS scans of one street and their ``T_world_scan`` poses file."""
    return _street("street", RAYS)


def street_small() -> tuple[list[Path], Path]:
    """The same six standpoints and poses scanned with a tenth of the rays (~0.2 M points)."""
    return _street("street_small", SMALL_RAYS)


def _street(name: str, rays: dict[str, int]) -> tuple[list[Path], Path]:
    folder = CACHE / f"{name}_{_key(rays)}"
    files = [folder / f"scan_{k:02d}.las" for k in range(N_SCANS)]
    poses_file = folder / "poses_T_world_scan.txt"
    if poses_file.exists() and all(f.exists() for f in files):
        return files, poses_file
    folder.mkdir(parents=True, exist_ok=True)
    print(f"making {N_SCANS} scans ({rays}) in {folder} (once) ...", flush=True)
    _, scans, poses = sim.make_sequence(seed=SEED, n_scans=N_SCANS, scan_kwargs=rays)
    for f, pts in zip(files, scans, strict=True):
        io.write(f, pts)
    lines = [
        f"{f.name} {format_matrix(T).replace(chr(10), ' ')}"
        for f, T in zip(files, poses, strict=True)
    ]
    poses_file.write_text("\n".join(lines) + "\n")
    return files, poses_file


def tiled(base: Path, n_points: int, suffix: str = ".las") -> Path:
    """A LAS (or LAZ) file of ``n_points`` points: copies of ``base`` turned about z by
    different angles (a denser scan of the same kind of scene), written chunk by chunk."""
    out = base.parent / f"tiled_{n_points // 1_000_000}M_{n_points % 1_000_000}{suffix}"
    if out.exists():
        return out
    pts = io.read(base).points
    if n_points < len(pts):  # a regular subset: the same scene, thinner
        pts = pts[np.linspace(0, len(pts) - 1, n_points).astype(np.int64)]
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.full(3, LAS_SCALE)
    header.offsets = np.zeros(3)
    tmp = out.with_suffix(".tmp" + suffix)
    written, k = 0, 0
    with laspy.open(tmp, mode="w", header=header) as writer:
        while written < n_points:
            a = np.radians(137.5 * k)  # golden-angle turns: no two copies coincide
            R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0, 0, 1]])
            part = pts[: n_points - written] @ R.T
            record = laspy.ScaleAwarePointRecord.zeros(len(part), header=header)
            record.x, record.y, record.z = part[:, 0], part[:, 1], part[:, 2]
            writer.write_points(record)
            written += len(part)
            k += 1
    tmp.rename(out)
    return out


def las_points(path: Path) -> int:
    """Points announced by a LAS file's header."""
    return int(io.count(path) or 0)


DENSE_RAYS = {"n_azimuth": 12_000, "n_elevation": 2_050}  # ~17 M points per scan


def street_dense() -> tuple[dict[str, list[Path]], Path]:
    """The six standpoints of :func:`street` scanned at today's density (~17 M points a scan):
    every scan as LAZ (the chain), the first two as LAS and E57 too (the pair in each format);
    returns the files by suffix and the ``T_world_scan`` poses file."""
    folder = CACHE / f"street_dense_{_key(DENSE_RAYS)}"
    names = [f"scan_{k:02d}" for k in range(N_SCANS)]
    files = {
        ".laz": [folder / f"{n}.laz" for n in names],
        ".las": [folder / f"{n}.las" for n in names[:2]],
        ".e57": [folder / f"{n}.e57" for n in names[:2]],
    }
    poses_file = folder / "poses_T_world_scan.txt"
    if poses_file.exists() and all(f.exists() for fs in files.values() for f in fs):
        return files, poses_file
    folder.mkdir(parents=True, exist_ok=True)
    print(f"making {N_SCANS} scans ({DENSE_RAYS}) in {folder} (once, minutes) ...", flush=True)
    scene, poses, seeds = _standpoints()
    for k, T in enumerate(poses):
        pts = sim.simulate_scan(scene, T, seed=seeds[k], **DENSE_RAYS)
        for path in (fs[k] for fs in files.values() if k < len(fs)):
            if not path.exists():
                _write(path, pts)
        del pts
    lines = [
        f"{n}.laz {format_matrix(T).replace(chr(10), ' ')}"
        for n, T in zip(names, poses, strict=True)
    ]
    poses_file.write_text("\n".join(lines) + "\n")
    return files, poses_file


def _standpoints() -> tuple[sim.Scene, list[np.ndarray], list[int]]:
    """The scene, poses and per-scan noise seeds of :func:`ndt_cli.sim.make_sequence` for
    ``SEED``, so that each dense scan is simulated alone (six at once would take gigabytes).
    The seeds are drawn as ``make_sequence`` draws them; a few rays check that they are."""
    rays = {"n_azimuth": 16, "n_elevation": 8}
    scene, scans, poses = sim.make_sequence(seed=SEED, n_scans=N_SCANS, scan_kwargs=rays)
    rng = np.random.default_rng(SEED)
    rng.uniform(13.0, 30.0, N_SCANS - 1)  # spacing, lateral offsets, headings
    rng.uniform(-3.0, 3.0, N_SCANS)
    rng.uniform(-180.0, 180.0, N_SCANS)
    seeds = [int(s) for s in rng.integers(0, 2**31 - 1, N_SCANS)]
    for pts, T, seed in zip(scans, poses, seeds, strict=True):
        if not np.array_equal(pts, sim.simulate_scan(scene, T, seed=seed, **rays)):
            raise RuntimeError("sim.make_sequence draws its scans' seeds otherwise now")
    return scene, poses, seeds


def _write(path: Path, pts: np.ndarray) -> None:
    if path.suffix == ".e57":
        from ndt_cli.io import e57

        e57.write(path, [pts], [None])
    else:
        io.write(path, pts)
