"""Progress of a chain: a bar on a terminal, one line per stage and per finished link in a log.

The campaign says what it is doing through the progress logger: a stage (``preparing 5
scan(s)``, ``adjusting the network of 12 link(s)``) or a batch of registrations
(``registering 3 link(s)``, the pairs riding on the record as ``links``). Links are found, not
assumed, so how many will be registered is not known at the start: the counts are those
announced so far, and every count adds up (``link 7/9``: the seventh of the nine registrations
announced; the last line's count is the number of registrations the report lists).

On a terminal (stderr is a TTY) a rich progress bar names the link at work and the stage, each
finished link is a line above it (with its reason when it is not ok), and the bar ends at
100 %; stage lines and the bar never mix (the progress logger writes through the bar while it
runs). Otherwise (a script writing to a log file, a cron job) every stage and every finished
link is one line, e.g. ``link 3/9 scan_002 <- scan_003: ok, 2.1 s``. ``--verbose`` adds each
link's levels.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable, Iterator
from types import TracebackType
from typing import Any

from ndt_cli.cli.common import PROGRESS

log = logging.getLogger(PROGRESS)

STYLES = {"ok": "green", "suspect": "yellow", "degenerate": "yellow"}  # others: red
# Columns the bar leaves free at its right: a terminal echoes each Ctrl-C as "^C" where the
# cursor is, the end of the bar; on a full line the echo wraps, the display loses count of its
# lines and leaves one behind when it stops
ECHO_ROOM = 4


class _Through(logging.Handler):
    """Hands the progress logger's records to the display (and, on a terminal, instead of
    writing them to stderr)."""

    def __init__(self, take: Callable[[logging.LogRecord], None]) -> None:
        super().__init__()
        self.take = take

    def emit(self, record: logging.LogRecord) -> None:
        self.take(record)


class ChainProgress:
    """Context manager for a chain's progress: :meth:`link_done` is the callback the chain
    calls for every finished link, :meth:`stage` names what the command does next."""

    def __init__(self, names: tuple[str, ...], enabled: bool) -> None:
        self.names, self.enabled = names, enabled
        self.done, self.total = 0, 0
        self.at_work: list[tuple[int, int]] = []
        self._bar: Any = None
        self._task: Any = None
        self._handlers: list[logging.Handler] = []
        self._through = _Through(self._record)

    def __enter__(self) -> ChainProgress:
        self._handlers = list(log.handlers)
        if self.enabled and sys.stderr.isatty():
            self._start_bar()
            log.handlers[:] = [self._through]
        else:
            log.handlers.append(self._through)
        return self

    def _start_bar(self) -> None:
        from rich.console import Console
        from rich.constrain import Constrain
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
        from rich.text import Text

        class TwoLines(Progress):
            """The stage or the link at work on a line of its own (wrapped, never cut: names
            are long), the bar with its counts below it; nothing once hidden (a command
            stopped by Ctrl-C leaves only its one line)."""

            def get_renderables(self) -> Iterator[Any]:
                shown = [task for task in self.tasks if task.visible]  # none once stopped
                for task in shown:
                    yield Text(task.description, overflow="fold")
                if shown:  # the terminal echoes each Ctrl-C as ^C after the bar: room for it
                    width = max(self.console.width - ECHO_ROOM, 1)
                    yield Constrain(self.make_tasks_table(shown), width)

        self._bar = TwoLines(
            BarColumn(bar_width=None),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=Console(file=sys.stderr),
            transient=False,
            expand=True,
        )
        self._bar.start()
        self._task = self._bar.add_task("starting", total=None)

    def _pair(self, pair: tuple[int, int]) -> str:
        return f"{self.names[pair[0]]} <- {self.names[pair[1]]}"

    def _record(self, record: logging.LogRecord) -> None:
        """A record of the progress logger: a batch announced, or a stage."""
        pairs = getattr(record, "links", None)
        if pairs is not None:
            self.total += len(pairs)
            self.at_work += [tuple(p) for p in pairs]
        if self._bar is None:
            return
        if record.levelno != logging.INFO:  # --verbose lines and warnings: above the bar
            line = f"{record.levelname.lower()}: {record.getMessage()}"
            self._bar.console.print(line, highlight=False, markup=False)
        elif pairs is not None:
            self._describe()
        else:
            self._bar.update(self._task, description=record.getMessage())

    def _describe(self) -> None:
        """The bar's counts, and its text: the link at work (and how many more)."""
        self._bar.update(self._task, total=self.total, completed=self.done)
        if self.at_work:
            more = f" (+{len(self.at_work) - 1})" if len(self.at_work) > 1 else ""
            text = f"registering {self._pair(self.at_work[0])}{more}"
            self._bar.update(self._task, description=text)

    def link_done(self, link: Any) -> None:
        """One link finished: its line (above the bar on a terminal), the counts."""
        self.done += 1
        pair = (link.target, link.source)
        if pair in self.at_work:
            self.at_work.remove(pair)
        else:  # taken from an earlier run, or failed with its scan: never announced
            self.total += 1
        seconds = 0.0 if link.result is None else link.result.runtime_s
        why = f" ({link.reason})" if link.reason and not link.ok else ""
        status = link.status.value
        head = f"link {self.done}/{self.total} {self._pair(pair)}"
        if self._bar is not None:
            from rich.markup import escape

            style = STYLES.get(status, "red")
            text = f"{escape(head)}: [{style}]{status}[/], {seconds:.1f} s{escape(why)}"
            self._bar.console.print(text, highlight=False)
            self._describe()
        elif self.enabled:
            log.info("%s: %s, %.1f s%s", head, status, seconds, why)
        log.debug("link %d levels: %s", link.index, link.describe_levels() or link.reason)

    def stage(self, text: str) -> None:
        """What the command does next (after the campaign: writing the outputs)."""
        log.info("%s", text)

    def __exit__(
        self, kind: type | None, value: BaseException | None, tb: TracebackType | None
    ) -> None:
        log.handlers[:] = self._handlers
        if self._bar is None:
            return
        if kind is None:
            total = max(self.total, 1)
            text = f"done: {self.done} registration(s)"
            self._bar.update(self._task, description=text, total=total, completed=total)
        else:
            self._bar.update(self._task, visible=False)
        self._bar.stop()
