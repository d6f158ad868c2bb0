"""ndt-cli: marker-free registration of terrestrial laser scans with multi-slice 2D NDT.

>>> import ndt_cli
>>> callable(ndt_cli.register)
True
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ndt_cli.config import Config
    from ndt_cli.result import RegistrationResult

__all__ = ["register"]
__version__ = "0.1.0"


def register(
    target: str | Path | np.ndarray,
    source: str | Path | np.ndarray,
    config: Config | str | Path | None = None,
    init: np.ndarray | None = None,
) -> RegistrationResult:
    """Register SOURCE onto TARGET; the result's ``T_target_source`` maps source to target.

    ``target``/``source`` are point files (PLY, LAS/LAZ, xyz/txt/csv, PCD) or (N,3) arrays in
    metres; ``config`` a :class:`~ndt_cli.config.Config`, a YAML path or ``None`` for the defaults;
    ``init`` an optional 4x4 guess of ``T_target_source`` (no guess: a start search is run).
    """
    from dataclasses import replace

    from ndt_cli import config as config_mod
    from ndt_cli.engine import register_prepared
    from ndt_cli.prepare import load_and_prepare

    t0 = time.perf_counter()
    cfg = config if isinstance(config, config_mod.Config) else config_mod.load(config)
    tgt = load_and_prepare(target, cfg)
    src = load_and_prepare(source, cfg)
    t_read = time.perf_counter() - t0
    result = register_prepared(tgt, src, cfg, init)
    timings = {"read_prepare_s": t_read, **result.timings}
    return replace(result, runtime_s=time.perf_counter() - t0, timings=timings)
