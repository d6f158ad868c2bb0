"""matplotlib, when it is installed (extra ``[plot]``), and figures as PNG bytes."""

from __future__ import annotations

import logging
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


def png_bytes(fig: Any, dpi: int | None = None) -> bytes:
    """A figure as PNG bytes, cropped to what is drawn; the figure is closed."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight", dpi=dpi)
    plt.close(fig)
    return buf.getvalue()
