"""Progress of a chain: a bar on a terminal, one line per finished link in a log.

On a terminal (stderr is a TTY) a rich progress bar runs; otherwise (a script writing to a
log file, a cron job) every finished link is one line such as
``link 3/9 scan_002 <- scan_003: ok, 2.1 s``. ``--verbose`` adds each link's levels.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from types import TracebackType
from typing import Any

from ndt_cli.cli.common import PROGRESS

log = logging.getLogger(PROGRESS)


class ChainProgress:
    """Context manager yielding the callback the chain calls for every finished link."""

    def __init__(self, names: tuple[str, ...], total: int, enabled: bool) -> None:
        self.names = names
        self.total = total
        self.enabled = enabled
        self.done = 0
        self._bar: Any = None
        self._task: Any = None

    def __enter__(self) -> Callable[[Any], None]:
        if self.enabled and sys.stderr.isatty():
            from rich.progress import Progress

            self._bar = Progress(transient=True)
            self._bar.start()
            self._task = self._bar.add_task("links", total=self.total)
        return self.advance

    def advance(self, link: Any) -> None:
        """One link finished: move the bar, or write its line."""
        self.done += 1
        if self._bar is not None:
            self._bar.update(self._task, total=max(self.total, self.done))
            self._bar.advance(self._task)
        elif self.enabled:
            seconds = 0.0 if link.result is None else link.result.runtime_s
            why = f" ({link.reason})" if link.reason and not link.ok else ""
            log.info(
                "link %d/%d %s <- %s: %s, %.1f s%s",
                self.done,
                max(self.total, self.done),
                self.names[link.target],
                self.names[link.source],
                link.status.value,
                seconds,
                why,
            )
        log.debug("link %d levels: %s", link.index, link.describe_levels() or link.reason)

    def __exit__(
        self, kind: type | None, value: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._bar is not None:
            self._bar.stop()
