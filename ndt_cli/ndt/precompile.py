"""A first run's kernels compiled on both cores.

On an empty Numba cache a run compiles every kernel in turn under one lock: most of a first run.
The kernels that prepare a scan, those of the global search and that of the NDT levels are
independent. When the search's are not in the cache, :func:`search_kernels_ahead` starts a child
process that compiles them into the same cache (``python -m ndt_cli.ndt.precompile``) while this
process reads and prepares the scans; this process then compiles the NDT levels' kernel while
the child ends, and the search loads the child's from the cache. If the cache cannot be
written, this process compiles them itself, as it would without the child: the results are the
same either way.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

WAIT_S = 300.0  # longest wait for the child (it takes seconds); then it is stopped


def search_dispatchers() -> tuple:
    """The compiled kernels of the global search (the child compiles them)."""
    from ndt_cli.ndt import bnb_kernels

    return (bnb_kernels._root_bounds, bnb_kernels._search_round, bnb_kernels.feed_anchors)


def level_dispatchers() -> tuple:
    """The compiled kernel of the NDT levels (compiled here while the child ends)."""
    from ndt_cli.ndt import kernels

    return (kernels._accumulate,)


def cached(dispatcher: object) -> bool:
    """Whether Numba's cache holds an index for ``dispatcher``: the file Numba names after the
    source file's stem, the qualified name, the first line and the Python version. Whether the
    entry is still fresh is Numba's to check when it loads it."""
    f = dispatcher.py_func
    version = f"{sys.version_info[0]}{sys.version_info[1]}{getattr(sys, 'abiflags', '')}"
    stem, line = Path(f.__code__.co_filename).stem, f.__code__.co_firstlineno
    index = f"{stem}.{f.__qualname__}-{line}.py{version}.nbi"
    return (Path(dispatcher.stats.cache_path) / index).is_file()


def _start_child() -> subprocess.Popen | None:
    """The child that compiles the search's kernels; None when it cannot start."""
    try:
        return subprocess.Popen(
            [sys.executable, "-m", __name__],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except OSError:  # this process compiles them itself
        return None


def _stop(child: subprocess.Popen) -> None:
    child.kill()
    child.wait()


@contextmanager
def search_kernels_ahead(enabled: bool = True) -> Iterator[None]:
    """Within the block, a child compiles the search's kernels if any is not cached (and
    ``enabled``); the block's end compiles the NDT levels' kernel and waits for the child. An
    error in the block stops the child."""
    cold = enabled and not all(cached(d) for d in search_dispatchers())
    child = _start_child() if cold else None
    try:
        yield
        if child is not None and not all(cached(d) for d in level_dispatchers()):
            compile_level_kernels()
    except BaseException:
        if child is not None:
            _stop(child)
        raise
    if child is not None:
        try:
            child.wait(timeout=WAIT_S)
        except subprocess.TimeoutExpired:
            _stop(child)


def _walls(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """Three slices of (n,2) points on three walls of a street corner, metres."""
    out = []
    for _ in range(3):
        t = rng.uniform(-20.0, 20.0, n)
        side = rng.integers(0, 3, n)
        x = np.where(side == 2, 15.0, t)
        y = np.where(side == 0, 8.0, np.where(side == 1, -8.0, 0.4 * t))
        out.append(np.column_stack([x, y]) + rng.normal(0.0, 0.02, (n, 2)))
    return out


def compile_search_kernels() -> None:
    """Search a small synthetic pair of slices globally: this compiles the search's kernels
    with the argument types of a real run (its wrappers fix them)."""
    from ndt_cli.ndt import bnb

    rng = np.random.default_rng(0)
    field = bnb.likelihood_field(_walls(rng, 400), resolution=0.5)
    bnb.search_field(field, _walls(rng, 300), window=8.0, yaw_step=np.radians(5.0))


def compile_level_kernels() -> None:
    """Score a few poses of synthetic slices on their NDT map, with and without the
    Levenberg-Marquardt terms: this compiles the NDT levels' kernel."""
    from ndt_cli.ndt.grid import build_map
    from ndt_cli.ndt.kernels import SourcePoints, accumulate

    rng = np.random.default_rng(0)
    ndt_map = build_map(_walls(rng, 400), 2.0)
    src = SourcePoints.from_slices(_walls(rng, 300))
    for lm in (False, True):
        accumulate(ndt_map, src, np.zeros((2, 3)), lm)


if __name__ == "__main__":
    compile_search_kernels()
