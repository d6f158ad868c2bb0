"""matplotlib, when it is installed (extra ``[plot]``), and figures as PNG bytes."""

from __future__ import annotations

import logging
import threading
from typing import Any

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


def png_bytes(fig: Any, dpi: int | None = None, *, tight: bool = True) -> bytes:
    """A figure as PNG bytes; the figure is closed. ``tight``: cropped to what is drawn, which
    draws the figure twice (a figure of many points sets its margins instead)."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight" if tight else None, dpi=dpi)
    plt.close(fig)
    return buf.getvalue()


def _warm_up() -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        from matplotlib.figure import Figure
    except ImportError:
        return
    fig = Figure(figsize=(1, 1))
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1], ".", label="x")
    ax.legend()
    fig.canvas.draw()  # loads the fonts and the renderer once


def start_warm_up() -> threading.Thread:
    """Import matplotlib and draw once, in a daemon thread: a command whose process waits on
    workers pays the plotting library's start-up (about a second) while it waits, not at the
    end. A figure made later in the process waits for it if it is still running."""
    thread = threading.Thread(target=_warm_up, name="plot-warm-up", daemon=True)
    thread.start()
    return thread
