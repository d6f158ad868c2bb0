"""matplotlib, when it is installed (extra ``[plot]``), and atomic PNG writing."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from ndt_cli.io import atomic

log = logging.getLogger(__name__)


def pyplot() -> Any | None:
    """matplotlib's pyplot on the Agg backend, or None (logged) when it is not installed."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log.warning("matplotlib is not installed (pip install 'ndt-cli[plot]'): PNG skipped")
        return None
    return plt


def save_png(fig: Any, path: Path, dpi: int | None = None) -> Path:
    """Write a figure atomically as PNG and close it."""
    import matplotlib.pyplot as plt

    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight", dpi=dpi)
    plt.close(fig)
    return path
