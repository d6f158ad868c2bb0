"""Benchmark sections at today's density (~17 M points a scan, benchmarks/data.py): a pair as
LAZ, LAS and E57 against a bare read of the same two files, and the network of six LAZ scans
against one LAZ pair; fresh processes in turns (:func:`benchmarks.common.interleaved`). And
the warm-process question: how a registration in a process that has everything loaded
compares with a fresh bare read of a full-density pair."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchmarks.common import RUN_PY, fmt, interleaved, ratio, table, target, timed
from benchmarks.fresh import CHAIN, LASPY_READ, OUT, REGISTER, Pair, _chain_figures
from benchmarks.peers import errors
from ndt_cli.io.matrices import read_matrix, read_pose_list

E57_READ = (  # pye57's own read of each file's scan, as a user of pye57 writes it
    "import sys, pye57, numpy as np\n"
    "for f in sys.argv[1:]:\n"
    "    data = pye57.E57(f).read_scan(0, transform=False, ignore_missing_fields=True)\n"
    "    xyz = np.column_stack([data['cartesianX'], data['cartesianY'], data['cartesianZ']])\n"
    "print(len(xyz))"
)
READERS = {
    ".laz": ("laspy", LASPY_READ),
    ".las": ("laspy", LASPY_READ),
    ".e57": ("pye57", E57_READ),
}
LIMITS = {".laz": 1.5, ".las": 3.0, ".e57": 2.0}  # ndt-register / bare read, the targets
PEAK_GB = 1.5


def _has_pye57() -> bool:
    import subprocess

    run = subprocess.run([RUN_PY, "-c", "import pye57"], capture_output=True, check=False)
    return run.returncode == 0


def _gt(files: list[Path], poses_file: Path) -> np.ndarray:
    poses = {Path(k).stem: T for k, T in read_pose_list(poses_file).items()}
    return np.linalg.inv(poses[files[0].stem]) @ poses[files[1].stem]


def _row(suffix: str, out: Path, reg: dict, read: dict, gt: np.ndarray) -> list[str]:
    rot, trans = errors(read_matrix(out / "T_target_source.txt"), gt)
    status = json.loads((out / "result.json").read_text()).get("status", "?")
    r = ratio(reg["wall_s"], read["wall_s"])
    lib = READERS[suffix][0]
    target(
        f"dense pair {suffix[1:].upper()}: ndt-register / {lib} read",
        r,
        LIMITS[suffix],
        f"<= {LIMITS[suffix]:g}",
        " x",
    )
    return [
        suffix[1:].upper(),
        f"{reg['wall_s']:.2f}",
        f"{reg['peak_mb']:.0f}",
        f"{read['wall_s']:.2f}",
        f"{read['peak_mb']:.0f}",
        fmt(r),
        f"{rot:.4f} / {trans * 100:.2f}",
        status,
    ]


def pairs(files: dict[str, list[Path]], poses_file: Path, repeat: int) -> dict[str, float]:
    """``ndt-register`` of the first two dense scans in each format against a bare read of the
    same files (laspy, pye57), in turns, best of ``repeat``; returns the best wall times."""
    rows, best, peaks = [], {}, []
    for suffix, fs in files.items():
        if suffix == ".e57" and not _has_pye57():
            rows.append(["E57", "-", "-", "-", "-", "-", "-", "pye57 not installed"])
            continue
        a, b = fs[:2]
        out = OUT / f"dense_pair_{suffix[1:]}"
        reg_cmd = [REGISTER, str(a), str(b), "--quiet", "--out", str(out)]
        read_cmd = [RUN_PY, "-c", READERS[suffix][1], str(a), str(b)]
        reg, read = interleaved([reg_cmd, read_cmd], repeat)
        rows.append(_row(suffix, out, reg, read, _gt(fs, poses_file)))
        best[suffix], best[f"{suffix} read"] = reg["wall_s"], read["wall_s"]
        peaks.append(reg["peak_mb"])
    n = sum(_points(f) for f in files[".laz"][:2]) / 1e6
    print(f"## A pair at today's density ({n:.1f} M points): ndt-register (no guess) vs a bare")
    print(f"read of its two files (fresh processes, taken in turns, best of {repeat})\n")
    head = ["format", "ndt-register (s)", "peak (MB)", "bare read (s)", "read peak (MB)"]
    table([*head, "ratio", "error (deg / cm)", "status"], rows)
    worst = max(peaks) / 1e3 if peaks else float("nan")
    target("peak memory, the dense pair (worst format)", worst, PEAK_GB, f"<= {PEAK_GB} GB", " GB")
    return best


def _points(path: Path) -> int:
    from ndt_cli import io

    return int(io.count(path) or 0)


def network(files: list[Path], poses_file: Path, repeat: int) -> None:
    """``ndt-chain`` of the six dense LAZ scans (``--jobs 2``) against one LAZ pair, in turns,
    and the floor of any network of them: a bare laspy read of the six files."""
    pair_out, chain_out = OUT / "dense_pair_laz", OUT / "dense_net"
    pair = [REGISTER, str(files[0]), str(files[1]), "--quiet", "--out", str(pair_out)]
    chain = [CHAIN, *map(str, files), "--quiet", "--jobs", "2", "--out", str(chain_out)]
    read = [RUN_PY, "-c", LASPY_READ, *map(str, files)]
    reg, net, floor = interleaved([pair, chain, read], repeat)
    gt = {Path(k).name: T for k, T in read_pose_list(poses_file).items()}
    links, ok, err = _chain_figures(chain_out, gt)
    r = ratio(net["wall_s"], reg["wall_s"])
    print(f"## The network of {len(files)} scans at today's density (LAZ)")
    print(f"(fresh processes, taken in turns, best of {repeat})\n")
    head = ["run", "wall (s)", "peak (MB)", "/ one pair", "links (by kind)", "scans ok"]
    rows = [
        [
            "ndt-register, one pair",
            f"{reg['wall_s']:.2f}",
            f"{reg['peak_mb']:.0f}",
            "1",
            "1",
            "-",
            "-",
        ],
        ["ndt-chain (network), --jobs 2", f"{net['wall_s']:.2f}", f"{net['peak_mb']:.0f}"],
        [f"bare laspy read of the {len(files)} files", f"{floor['wall_s']:.2f}"],
    ]
    rows[1] += [fmt(r), links, ok, err]
    rows[2] += [
        f"{floor['peak_mb']:.0f}",
        fmt(ratio(floor["wall_s"], reg["wall_s"])),
        "-",
        "-",
        "-",
    ]
    table([*head, "worst error (deg / cm)"], rows)
    print(
        "(the pair is about its read; a network of these scans reads three pairs' worth, so the"
        " links and the network fit under 3x only in the read's margin)\n"
    )
    target("dense ndt-chain network --jobs 2 / one pair", r, 3.0, "<= 3", " x")


def warm_process(p: Pair, fresh_read_s: float, repeat: int = 3) -> None:
    """What a persistent worker could give a shell loop that calls ndt-register once a pair:
    the registration in a warm process (everything imported, kernels loaded, caches filled)
    against a fresh bare read of the same files; a worker adds its client's start and the
    hand-over to that."""
    import ndt_cli

    ndt_cli.register(p.a, p.b)  # warm
    best = min(timed(lambda: ndt_cli.register(p.a, p.b))[0] for _ in range(repeat))
    r = ratio(best, fresh_read_s)
    print(f"## A warm process for shell loops ({p.label})\n")
    rows = [
        ["registration in a warm process (the least a worker could take)", f"{best:.2f}"],
        ["bare laspy read of the two files, fresh process", f"{fresh_read_s:.2f}"],
    ]
    table(["what", "wall (s)"], rows)
    print(f"warm registration / fresh read: {fmt(r)} (a worker's best case; target <= 2)\n")
    target("warm-process pair (best case of a worker) / fresh read", r, 2.0, "<= 2", " x")
