"""Campaigns the method cannot solve are results, never tracebacks: a corridor of uniform walls
(the position along it is unobservable: the paper's own limit) and scans that share nothing
but a ground plane. Every scan but the anchor is not ok, with a reason; the outputs are
written; the exit code is 1."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

CHAIN = [sys.executable, "-c", "from ndt_cli.cli import chain_app; chain_app()"]
STANDPOINTS = (0.0, 8.0, 16.0, 24.0)  # m along the corridor


def _scan(rng: np.random.Generator, x0: float, walls: bool, n: int = 30_000) -> np.ndarray:
    """A scan at ``x0`` in its own frame (turned by a random heading): a floor 1.7 m below the
    scanner and, with ``walls``, two uniform walls 6 m either side, 10 m high."""
    r, a = np.sqrt(rng.uniform(1.0, 900.0, n)), rng.uniform(0, 2 * np.pi, n)
    parts = [np.column_stack([r * np.cos(a), np.clip(r * np.sin(a), -5.9, 5.9), np.full(n, -1.7)])]
    for y in (-6.0, 6.0) if walls else ():
        x, z = rng.uniform(-30, 30, n), rng.uniform(-1.7, 10.0, n)
        parts.append(np.column_stack([x, np.full(n, y), z]))
    P = np.vstack(parts)
    yaw = rng.uniform(-np.pi, np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    P[:, :2] = P[:, :2] @ np.array([[c, s], [-s, c]]).T
    return P + rng.normal(0.0, 0.005, P.shape)


@pytest.mark.slow
@pytest.mark.parametrize("walls", [True, False], ids=["uniform corridor", "ground plane only"])
def test_an_unsolvable_campaign_is_a_result_with_reasons(tmp_path, walls):
    rng = np.random.default_rng(7)
    files = []
    for k, x0 in enumerate(STANDPOINTS):
        files.append(tmp_path / f"scan_{k}.xyz")
        np.savetxt(files[-1], _scan(rng, x0, walls), fmt="%.4f")
    out = tmp_path / "out"
    run = subprocess.run(
        [*CHAIN, *map(str, files), "-o", str(out), "-j", "1", "-q"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 1, run.stderr
    assert "Traceback" not in run.stderr
    rows = list(csv.DictReader((out / "poses.csv").open()))
    assert [Path(r["file"]).name for r in rows] == [f.name for f in files]
    for row in rows[1:]:
        assert row["status"] != "ok" and row["reason"], row
        word = "degenerate" if walls else "no points in any slice"
        assert word in row["reason"] or "not determined" in row["reason"], row
    assert (out / "report.html").exists() and (out / "summary.json").exists()
