"""Helpers shared by the benchmark sections: fresh-process measurements, timers, tables, ratios
and the list of targets that ``run.py`` prints at the end."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PY = sys.executable
RUN_VENV = ROOT / ".venv-run"
"""The environment the commands are timed in as fresh processes: the runtime dependencies only,
as ``pip install ndt-cli`` installs them (``make bench`` creates it). The development
environment's extras change what every process imports: Open3D brings requests, which laspy
then imports (+40-60 ms for any process that reads a LAS file, the bare read included), and
scipy, a test reference, makes Numba import scipy.linalg when it starts (+0.1 s)."""
RUN_BIN = RUN_VENV / "bin" if (RUN_VENV / "bin" / "ndt-register").exists() else BIN
RUN_PY = str(RUN_BIN / "python")
MEASURE = ROOT / "benchmarks" / "measure.py"
TARGETS: list[list[str]] = []  # [what, measured, target, met], printed at the end of a run


def byte_compile_package() -> None:
    """Write the package's bytecode, as ``pip install`` does for an installed package, so that
    the commands are timed as a surveyor runs them. The benchmark's environment holds the
    package as an editable install; where PYTHONDONTWRITEBYTECODE is set, every process would
    otherwise compile the package's modules from source (about 50 ms of a pair), while the
    peers and the bare read import theirs from bytecode."""
    import compileall

    compileall.compile_dir(ROOT / "ndt_cli", quiet=1)


def best_of(fn: Callable[[], object], repeat: int = 5) -> float:
    """Shortest wall time (s) of ``repeat`` calls of ``fn``."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def timed(fn: Callable[[], object]) -> tuple[float, object]:
    """Wall time (s) of one call of ``fn`` and its result."""
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def measured(cmd: list[str], env: dict[str, str] | None = None) -> dict:
    """Wall time, exit code, last printed line and peak memory of ``cmd`` as a fresh child."""
    out = subprocess.run(
        [PY, str(MEASURE), *cmd],
        capture_output=True,
        text=True,
        env={**os.environ, **(env or {})},
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def interleaved(cmds: list[list[str]], repeat: int) -> list[dict]:
    """Each command ``repeat`` times, taking turns (so that load changes hit all alike); the run
    with the shortest wall time of each."""
    runs: list[list[dict]] = [[] for _ in cmds]
    for _ in range(repeat):
        for k, cmd in enumerate(cmds):
            runs[k].append(measured(cmd))
    return [min(r, key=lambda x: x["wall_s"]) for r in runs]


def python_c(code: str) -> list[str]:
    """A fresh interpreter of the commands' environment (:data:`RUN_BIN`) running ``code``."""
    return [RUN_PY, "-c", code]


def last_json(run: dict) -> dict:
    """The JSON object a measured child printed as its last line."""
    return json.loads(run["last"])


def ratio(a: float, b: float) -> float:
    return a / b if np.isfinite(a) and np.isfinite(b) and b > 0 else float("nan")


def fmt(value: float, spec: str = ".2f") -> str:
    return "-" if not np.isfinite(value) else format(value, spec)


def table(header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows, strict=True)]
    for r in [header, ["-" * w for w in widths], *rows]:
        print("  ".join(str(x).ljust(w) for x, w in zip(r, widths, strict=True)).rstrip())
    print()


def target(
    what: str, value: float, limit: float, text: str, unit: str = "", ok: bool = True
) -> None:
    """Record a figure against its target (met when ``value <= limit`` and ``ok``)."""
    met = "-" if not np.isfinite(value) else ("yes" if value <= limit and ok else "NO")
    TARGETS.append([what, fmt(value) + (unit if np.isfinite(value) else ""), text, met])


def cpu_mhz() -> float:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("cpu MHz"):
                return float(line.split(":")[1])
    except OSError:
        pass
    return float("nan")
