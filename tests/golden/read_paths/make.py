"""Write ``poses.json``: the sample pair registered from LAZ, LAS and E57 copies, read in chunks
of 20,000 points (so every path of the reading is taken: chunks held, chunks streamed twice).

Run from the project folder, with the package it should pin first on the path:
``PYTHONPATH=<checkout> python tests/golden/read_paths/make.py``. The values in the repository
were first written by the code of commit 7fc18e1, before a LAZ file was decoded once and a
scan held as integers, so the test held the new reading to the old results; they were written
again when ICP stopped pairing surfaces the two scans saw differently (the reading unchanged).
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
CHUNK = 20_000
FORMATS = (".laz", ".las", ".e57")


def copies(folder: Path) -> dict[str, tuple[Path, Path]]:
    """The sample pair (scan_00 target, scan_01 source) in each format."""
    from ndt_cli import io
    from ndt_cli.io import e57

    out = {}
    for suffix in FORMATS:
        pair = []
        for name in ("scan_00", "scan_01"):
            src = ROOT / "sample_data" / f"{name}.laz"
            dst = folder / f"{name}{suffix}"
            if suffix == ".laz":
                dst = src
            elif suffix == ".e57":
                e57.write(dst, [io.read(src).points], [None])
            else:
                io.write(dst, io.read(src).points)
            pair.append(dst)
        out[suffix] = (pair[0], pair[1])
    return out


def poses(folder: Path) -> dict[str, list[list[float]]]:
    import ndt_cli
    from ndt_cli.config import Config

    cfg = Config().replace(input={"chunk_points": CHUNK})
    return {
        suffix: np.asarray(ndt_cli.register(a, b, cfg).T_target_source).tolist()
        for suffix, (a, b) in copies(folder).items()
    }


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        found = poses(Path(tmp))
    text = json.dumps({"chunk_points": CHUNK, "poses": found}, indent=1)
    (HERE / "poses.json").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
