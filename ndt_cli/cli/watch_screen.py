"""Field mode's screen: each event of :mod:`ndt_cli.pipeline.field_events` as lines on stderr
(statuses coloured on a terminal, lines wrapped between words at its width, never cut), or as
one JSON object per line on stdout (``--json``). ``quiet`` shows only what needs the operator:
scans that are not ok, files that cannot be read, the folder gone, and the closing lines."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from typing import Any

from ndt_cli.pipeline.field_events import (
    Event,
    EventKind,
    FileNote,
    FolderNote,
    Landed,
    LinkNote,
    Placed,
    Revised,
    Started,
    Stopped,
    Tally,
    Verdict,
    event_dict,
)

HANG = 4  # columns a wrapped line's continuation is indented by, beyond the line's own
STYLES = {
    "ok": "green",
    "suspect": "yellow",
    "unposed": "bold red",
    "fits nowhere": "bold red",
    "apart": "yellow",
}


class Screen:
    """Shows events (see the module docstring)."""

    def __init__(self, json_out: bool = False, quiet: bool = False, console: Any = None) -> None:
        """``console``: a rich console to print to (None: stderr, as wide as its terminal, or
        never wrapping when it is no terminal)."""
        from rich.console import Console

        self.json_out, self.quiet = json_out, quiet
        tty = sys.stderr.isatty()
        self.console = console or Console(
            file=sys.stderr, width=None if tty else 10_000, highlight=False, emoji=False
        )

    def show(self, event: Event) -> None:
        if self.json_out:
            _write_json(event)
            return
        if self.quiet and not _needs_you(event):
            return
        if isinstance(event, Stopped) and event.why == "interrupted" and self.console.is_terminal:
            self.console.print()  # the terminal echoed the Ctrl-C as "^C": a line of its own
        for line in lines(event):
            self._print(line)

    def _print(self, line: Any) -> None:
        """A line wrapped between words at the console's width, its continuation lines
        indented under its text (a name longer than a line is folded, never cut)."""
        from rich.text import Text

        indent = len(line.plain) - len(line.plain.lstrip(" "))
        hang = indent + HANG
        width = self.console.width
        if len(line.plain) <= width or width <= hang + 20:
            self.console.print(line, overflow="fold", crop=False)
            return
        parts = line[indent:].wrap(self.console, width - hang, overflow="fold")
        for k, part in enumerate(parts):
            part.rstrip()
            self.console.print(Text(" " * (indent if k == 0 else hang)) + part, crop=False)


def _write_json(event: Event) -> None:
    """The event's JSON line on stdout, at once; a reader gone away is a one-line error."""
    import os

    from ndt_cli.errors import OutputError

    try:
        sys.stdout.write(json.dumps(event_dict(event), ensure_ascii=False) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - nothing more is written there
        raise OutputError("stdout was closed: the program reading --json stopped") from None


def _needs_you(event: Event) -> bool:
    """Whether ``-q`` shows the event."""
    if isinstance(event, Placed | Revised):
        return event.verdict.label != "ok"
    if isinstance(event, FolderNote):
        return not event.present
    return event.kind in (EventKind.UNREADABLE, EventKind.STOPPED)


def lines(event: Event) -> list[Any]:
    """The lines (rich Text) of an event."""
    from rich.text import Text

    show = _SHOW.get(type(event))
    return [Text.from_markup(s) if isinstance(s, str) else s for s in show(event)] if show else []


def _started(e: Started) -> list[Any]:
    idle = (
        f"exits after {e.exit_when_idle_s:g} s without one, or on Ctrl-C"
        if e.exit_when_idle_s is not None
        else "Ctrl-C stops it"
    )
    out = [
        f"[bold]ndt-watch[/]: watching {_esc(e.folder)}",
        f"  outputs: {_esc(e.out)}, published after each scan; config: {_esc(e.config)}; "
        f"{e.jobs} process{'es' if e.jobs != 1 else ''}",
    ]
    if e.control:
        out.append(f"  control: {_esc(e.control)}" + (f" ({_esc(e.crs)})" if e.crs else ""))
    lands = f"a scan lands once its copy is closed, or unchanged for {e.settle_s:g} s"
    return [*out, f"  {lands}; {idle}"]


def _landed(e: Landed) -> list[Any]:
    what = _points(e.points)
    many = f", {len(e.scans)} scans" if len(e.scans) > 1 else ""
    return [f"[bold]{_esc(e.file)}[/] landed{many}{what}: registering…"]


def _points(n: int | None) -> str:
    if n is None:
        return ""
    if n >= 1_000_000:
        return f", {n / 1e6:.1f} M points"
    return f", {n / 1e3:.0f} k points" if n >= 1000 else f", {n} points"


def _placed(e: Placed) -> list[Any]:
    v = e.verdict
    timing = f"{e.took_s:.1f} s ({e.since_landed_s:.1f} s since it landed)"
    if v.anchor and not v.links:
        head = f"[bold]{_esc(v.scan)}[/]: the first scan, {_esc(e.role)}; {timing}"
    elif v.fits_nowhere:
        why = f": {_esc(v.reason)}" if v.reason else ""
        head = f"[bold]{_esc(v.scan)}[/]: [bold red]FITS NOWHERE[/]{why}; scan again here? {timing}"
    else:
        head = f"[bold]{_esc(v.scan)}[/]: {_verdict(v)}; {timing}"
    return [head, *_links(v), _tally(e.tally)]


def _verdict(v: Verdict) -> str:
    """The verdict, coloured, with the position and the reason when not ok."""
    style = STYLES.get("apart" if v.status.value == "ok" and v.cluster else v.status.value, "")
    word = f"[{style}]{_esc(v.label)}[/]" if style else _esc(v.label)
    shown = v.position is not None and v.cluster == 0  # elsewhere: its cluster's own frame
    where = " at ({:.2f}, {:.2f}, {:.2f}) m".format(*v.position) if shown else ""
    why = f" ({_esc(v.reason)})" if v.reason and v.label != "ok" else ""
    return f"{word}{why}{where}"


def _links(v: Verdict) -> list[str]:
    """A line per link of the scan: the kept ones first, checked or not; the others with why
    they are not kept."""
    order = {"confirmed": 0, "used": 1, "rejected": 2, "unused": 3}
    return [f"    {_link(k)}" for k in sorted(v.links, key=lambda k: order[k.state.value])]


def _link(k: LinkNote) -> str:
    overlap = "" if k.overlap is None else f"overlap {100 * k.overlap:.0f} %, "
    if k.checked:
        state = f"[green]checked[/], residual {k.residual_cm:.1f} cm"
    elif k.state.value == "used":
        state = "[yellow]not checked[/] (no cycle checks it)"
    else:
        word = "rejected" if k.state.value == "rejected" else "not kept"
        state = word + (f": {_esc(k.reason)}" if k.reason else "")
    return f"↔ {_esc(k.scan)}: {overlap}{state}"


def _tally(t: Tally) -> str:
    return f"  [dim]so far:[/] {tally_text(t)}"


def tally_text(t: Tally) -> str:
    """'9 scans: 8 ok, 1 suspect; 1 file waiting' (zero counts left out)."""
    parts = [
        f"[green]{t.ok} ok[/]" if t.ok else "",
        f"[yellow]{t.apart} ok apart from the anchor's cluster[/]" if t.apart else "",
        f"[yellow]{t.suspect} suspect[/]" if t.suspect else "",
        f"[bold red]{t.unposed} unposed[/]" if t.unposed else "",
    ]
    text = f"{t.scans} scan{'s' if t.scans != 1 else ''}: " + ", ".join(p for p in parts if p)
    if not t.scans:
        text = "no scan yet"
    if t.waiting:
        text += f"; {t.waiting} file{'s' if t.waiting != 1 else ''} waiting to be read whole"
    return text


def _revised(e: Revised) -> list[Any]:
    v = e.verdict
    linked = [k.scan for k in v.links if k.state.value in ("confirmed", "used")]
    to = f", linked to {_esc(', '.join(linked))}" if linked else ""
    word = _verdict(replace(v, position=None))
    return [f"[bold]{_esc(v.scan)}[/]: now {word} (was {_esc(e.was)}){to}", _tally(e.tally)]


_FILE_TAILS = {
    EventKind.UNREADABLE: "read again when it changes",
    EventKind.SKIPPED: "left alone",
    EventKind.REPLACED: "registering it anew",
    EventKind.REMOVED: "dropped from the campaign",
}
_STATES = {
    "incomplete": "incomplete",
    "unreadable": "cannot be read",
    "not_a_scan": "not a scan",
    "copy": "a copy",
}


def _file(e: FileNote) -> list[Any]:
    what = _STATES.get(e.state, "")
    what = f"{what} ({_esc(e.reason)})" if what else _esc(e.reason)
    style = "yellow" if e.kind is EventKind.UNREADABLE else "dim"
    tail = "waiting for the rest" if e.state == "incomplete" else _FILE_TAILS[e.kind]
    if e.dropped and e.kind is not EventKind.REMOVED:
        tail += "; its earlier registration is dropped"
    return [f"[bold]{_esc(e.file)}[/]: [{style}]{what}[/]: {tail}"]


def _folder(e: FolderNote) -> list[Any]:
    if e.present:
        return [f"the watched folder {_esc(e.folder)} can be read again"]
    return [
        f"[bold yellow]the watched folder {_esc(e.folder)} cannot be read[/] (card pulled out?): "
        "waiting for it"
    ]


def _stopped(e: Stopped) -> list[Any]:
    head = {"idle": "idle", "interrupted": "stopped (Ctrl-C)", "terminated": "stopped"}
    lines = [f"[bold]{head.get(e.why, e.why)}[/]: {tally_text(e.tally)}"]
    for name, label in e.not_ok:
        lines.append(f"  {_esc(name)}: [{STYLES.get(label, 'yellow')}]{_esc(label)}[/]")
    for name, why in e.waiting:
        lines.append(f"  {_esc(name)}: [yellow]{_esc(why)}[/]")
    if e.why == "idle":
        lines.append(f"outputs in {_esc(e.out)}")
    else:
        lines.append(
            f"the outputs in {_esc(e.out)} hold every scan registered so far; "
            "start ndt-watch again to continue"
        )
    return [*lines, *(_esc(line) for line in e.world)]


def _esc(text: str) -> str:
    from rich.markup import escape

    return escape(str(text))


_SHOW = {
    Started: _started,
    Landed: _landed,
    Placed: _placed,
    Revised: _revised,
    FileNote: _file,
    FolderNote: _folder,
    Stopped: _stopped,
}
