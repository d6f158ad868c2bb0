"""The method: slices, NDT grids, kernels, optimisers, the staged registration, ICP refinement.

``register`` (file paths or arrays) and ``register_prepared`` (prepared scans) are the entry
points; every stage is public in its own module.

The compiled kernels are cached beside this package; where it cannot be written (a read-only
install, another user's checkout) the cache goes to ``NUMBA_CACHE_DIR``, by default a folder in
the user's cache or temporary directory, so that no import fails for want of a cache.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _cache_dir() -> str | None:
    """A writable folder for Numba's cache when the package folder is not writable."""
    if os.environ.get("NUMBA_CACHE_DIR") or os.access(Path(__file__).parent, os.W_OK):
        return None
    for base in (Path.home() / ".cache", Path(tempfile.gettempdir())):
        folder = base / f"ndt-cli-numba-{os.getuid()}"
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(folder, os.W_OK):
            return str(folder)
    return None


if (_dir := _cache_dir()) is not None:
    os.environ["NUMBA_CACHE_DIR"] = _dir
