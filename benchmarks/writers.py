"""LAS and LAZ files as other writers lay them out, at today's density: the dense pair
(:func:`benchmarks.data.street_dense`) rewritten in point formats 1, 3, 6 and 7, in the rays'
azimuth-major order and in elevation-major order (scan lines of equal elevation), and in the
layout scanner software writes (LAS 1.4, 0.1 mm scale, per-point attributes filled, extra
bytes). Each pair is read by ``laspy.read`` and by ndt-cli's own reader in this process, warm,
and registered by ``ndt-register`` against a bare ``laspy.read`` of it as fresh processes
taken in turns in the same run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import laspy
import numpy as np

from benchmarks import data
from benchmarks.common import RUN_PY, fmt, interleaved, ratio, table, target
from benchmarks.fresh import OUT, REGISTER


@dataclass(frozen=True)
class Layout:
    """How a writer lays a scan out."""

    name: str
    point_format: int
    version: str
    order: str  # "azimuth-major" (the rays as scanned) or "elevation-major"
    scale: float = 0.001
    extra: bool = False  # extra bytes per point, as scanner software adds (range, deviation)
    suffix: str = ".las"


OWN = Layout("pf0 (ndt-cli's writer)", 0, "1.2", "azimuth-major")  # the dense pair as made
OWN_LAZ = Layout("pf0 (ndt-cli's writer)", 0, "1.2", "azimuth-major", suffix=".laz")
LAYOUTS = (
    Layout("pf1", 1, "1.2", "azimuth-major"),
    Layout("pf3", 3, "1.2", "azimuth-major"),
    Layout("pf6", 6, "1.4", "azimuth-major", 0.0001),
    Layout("pf6 lines", 6, "1.4", "elevation-major", 0.0001),
    Layout("pf7", 7, "1.4", "azimuth-major", 0.0001),
    Layout("pf6 extra bytes", 6, "1.4", "azimuth-major", 0.00025, extra=True),
    Layout("pf1", 1, "1.2", "azimuth-major", suffix=".laz"),
    Layout("pf6", 6, "1.4", "azimuth-major", 0.0001, suffix=".laz"),
)
BARE_READ = "import sys, laspy\nfor f in sys.argv[1:]:\n    laspy.read(f)\n"
READ_LIMIT = 1.0  # ndt-cli's read of a LAS pair / laspy.read of it, warm, in one process
BEYOND_LIMIT = 1.2  # ndt-register beyond a bare read of its pair / the same for ndt-cli's own
# pair in the same format (a LAZ pair is decoded inside ndt-register: its time beyond the read
# holds a second decoding, which only a LAZ pair has)


def _order(xyz: np.ndarray, order: str) -> np.ndarray:
    """Row order of the points: as scanned, or by scan line (elevation step), then azimuth."""
    if order == "azimuth-major":
        return np.arange(len(xyz))
    el = np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))
    step = np.radians(140.0 / data.DENSE_RAYS["n_elevation"])
    return np.lexsort((np.arctan2(xyz[:, 1], xyz[:, 0]), np.round(el / step)))


def _write(src: Path, dst: Path, lay: Layout) -> None:
    """``src`` rewritten to ``dst`` in layout ``lay``, with plausible attributes filled."""
    las = laspy.read(src)
    xyz = np.column_stack([las.x, las.y, las.z])
    idx = _order(xyz, lay.order)
    header = laspy.LasHeader(point_format=lay.point_format, version=lay.version)
    if lay.extra:
        header.add_extra_dims(
            [laspy.ExtraBytesParams("range", "f4"), laspy.ExtraBytesParams("deviation", "u2")]
        )
    header.scales = np.full(3, lay.scale)
    header.offsets = np.floor(xyz.min(axis=0))
    out = laspy.LasData(header)
    out.x, out.y, out.z = xyz[idx, 0], xyz[idx, 1], xyz[idx, 2]
    n = len(idx)
    out.intensity = (np.arange(n) * 7919 % 65_536).astype(np.uint16)
    out.gps_time = np.arange(n, dtype=np.float64) * 2e-6
    out.return_number = np.ones(n, np.uint8)
    out.number_of_returns = np.ones(n, np.uint8)
    if "red" in out.point_format.dimension_names:
        out.red = out.green = out.blue = (np.arange(n) % 65_536).astype(np.uint16)
    if lay.extra:
        out.range = np.linalg.norm(xyz[idx], axis=1).astype(np.float32)
        out.deviation = np.zeros(n, np.uint16)
    tmp = dst.with_suffix(".tmp" + lay.suffix)
    out.write(str(tmp), do_compress=lay.suffix == ".laz")
    tmp.replace(dst)


def files() -> dict[Layout, list[Path]]:
    """The dense pair in every layout (made once, from the dense LAS pair; cached)."""
    dense, _ = data.street_dense()
    src = dense[".las"][:2]
    folder = src[0].parent / "writers"
    folder.mkdir(exist_ok=True)
    out = {OWN: src, OWN_LAZ: dense[".laz"][:2]}
    for lay in LAYOUTS:
        paths = [folder / f"{s.stem}_{lay.name.replace(' ', '_')}{lay.suffix}" for s in src]
        for s, p in zip(src, paths, strict=True):
            if not p.exists():
                print(f"writing {p.name} ...", flush=True)
                _write(s, p, lay)
        out[lay] = paths
    return out


def _header(path: Path) -> laspy.LasHeader:
    with laspy.open(path) as reader:
        return reader.header


def _warm_reads(pair: list[Path], repeat: int = 3) -> tuple[float, float]:
    """Seconds of ``laspy.read`` of both files and of ndt-cli's read of them (its blocks of
    usable points), in this process, warm (best of ``repeat``, taken in turns)."""
    from ndt_cli import io

    def ours() -> None:
        for f in pair:
            for _ in io.read_blocks(f):
                pass

    def theirs() -> None:
        for f in pair:
            laspy.read(f)

    ours(), theirs()  # the page cache and the kernels warm
    best = [float("inf"), float("inf")]
    for _ in range(repeat):
        for k, fn in enumerate((theirs, ours)):
            t0 = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t0)
    return best[0], best[1]


def section(repeat: int = 2) -> None:
    """Reading each layout's pair, warm, by ndt-cli and by ``laspy.read``; and ``ndt-register``
    of it against a bare ``laspy.read`` of it, as fresh processes in turns: its time beyond the
    read, against the same for the pair as ndt-cli writes it."""
    pairs = files()
    rows, own_beyond = [], {}
    for lay, (a, b) in pairs.items():
        laspy_s, ours_s = _warm_reads([a, b])
        reg, bare = interleaved(
            [
                [REGISTER, str(a), str(b), "--quiet", "--out", str(OUT / "writers")],
                [RUN_PY, "-c", BARE_READ, str(a), str(b)],
            ],
            repeat,
        )
        beyond = reg["wall_s"] - bare["wall_s"]
        if lay in (OWN, OWN_LAZ):
            own_beyond[lay.suffix] = beyond
        r_read = ratio(ours_s, laspy_s)
        r_beyond = ratio(beyond, own_beyond.get(lay.suffix, float("nan")))
        if lay.suffix == ".las":
            target(f"read, {lay.name} LAS pair, warm / laspy.read", r_read, READ_LIMIT, "<= 1")
        if lay not in (OWN, OWN_LAZ):
            kind = lay.suffix[1:].upper()
            what = f"ndt-register beyond the read, {lay.name} {kind} / ndt-cli's {kind}"
            target(what, r_beyond, BEYOND_LIMIT, f"<= {BEYOND_LIMIT:g}")
        size = _header(a).point_format.size
        rows.append(
            [
                lay.name,
                f"{lay.version} / {size} B",
                lay.order,
                lay.suffix[1:].upper(),
                f"{laspy_s:.2f}",
                f"{ours_s:.2f}",
                fmt(r_read),
                f"{bare['wall_s']:.2f}",
                f"{reg['wall_s']:.2f}",
                f"{beyond:.2f}",
                fmt(r_beyond),
                f"{reg['peak_mb']:.0f}",
            ]
        )
    n = _header(pairs[OWN][0]).point_count * 2 / 1e6
    print(f"## Files of other writers: the dense pair ({n:.1f} M points) in every layout")
    print("(reads warm in this process, best of 3; then fresh processes, taken in turns, best")
    print(f"of {repeat}: a bare laspy.read of the pair and ndt-register of it)\n")
    head = ["layout", "LAS / record", "order", "file", "laspy.read (s)", "ndt-cli read (s)"]
    head += ["/ laspy", "fresh laspy.read (s)", "ndt-register (s)", "beyond the read (s)"]
    table([*head, "/ ndt-cli's", "peak (MB)"], rows)
    outputs(pairs[LAYOUTS[2]])


def outputs(pair: list[Path]) -> None:
    """Where the outputs of ``ndt-register`` spend their time, in this process: hashing the
    two scan files (done beside the registration by the command), and the rest."""
    from ndt_cli import register
    from ndt_cli.config import Config
    from ndt_cli.pipeline.scans import file_hash
    from ndt_cli.report.register_outputs import write_register_outputs

    result = register(*map(str, pair))
    t0 = time.perf_counter()
    for p in pair:
        file_hash(p, reuse=False)
    hashing = time.perf_counter() - t0
    t0 = time.perf_counter()
    write_register_outputs(OUT / "writers_outputs", result, Config())
    rest = time.perf_counter() - t0
    print("## The outputs of ndt-register (the pf6 pair, in this process)\n")
    table(
        ["part", "seconds"],
        [
            ["SHA-256 of both files (beside the registration in the command)", f"{hashing:.2f}"],
            ["the rest: report, CSV, JSON, config, published together", f"{rest:.2f}"],
        ],
    )
