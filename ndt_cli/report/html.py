"""The client-facing registration report: one self-contained HTML5 file.

The caller describes a run with the frozen dataclasses below and :func:`render_html` turns them
into one page, laid out like a surveyor's registration report: a header block (title, command
line, creation time, software), the verdict with everything it rests on named, the summary and
the network's figures, the control stations, the plan and other figures, the table of scans,
the table of links (registration, state in the network, strength), the link inspector (the two
scans' slices overlaid, per link), the registrations tried and left out, notes, and the
configuration as an appendix.

The page needs nothing but itself: the CSS is inline, the figures are PNG data URIs, there is no
JavaScript, and a Content-Security-Policy forbids every fetch but ``data:`` images. It prints
on A4 and reads on a phone (:mod:`ndt_cli.report.html_css`). Status values are written as text
and coloured. Every value is HTML-escaped (:mod:`ndt_cli.report.html_parts`).
"""

from __future__ import annotations

import base64
import struct
from dataclasses import dataclass
from datetime import datetime

from ndt_cli.report.html_css import CSS
from ndt_cli.report.html_parts import STATUS_CLASSES, esc, kv_table, status_class
from ndt_cli.report.html_sections import (
    ControlRow,
    LinkCard,
    LinkRow,
    ScanRow,
    control_section,
    inspector_section,
    tables,
    tried_section,
)

__all__ = [
    "STATUS_CLASSES",
    "ControlRow",
    "Figure",
    "HtmlReport",
    "LinkCard",
    "LinkRow",
    "ScanRow",
    "Verdict",
    "render_html",
    "status_class",
]


@dataclass(frozen=True)
class Verdict:
    """The overall outcome: ``ok``, a one-line ``reason`` and the ``remarks`` it rests on (one
    line each, naming what they are about); ``level``: ``ok``, ``remarks`` (ok, with things to
    know) or ``bad`` ('' : from ``ok``)."""

    ok: bool
    reason: str = ""
    remarks: tuple[str, ...] = ()
    level: str = ""

    @property
    def css(self) -> str:
        return self.level or ("ok" if self.ok else "bad")


@dataclass(frozen=True)
class Figure:
    """A picture (PNG bytes) with its caption; ``alt`` defaults to the caption."""

    png: bytes
    caption: str
    alt: str = ""


@dataclass(frozen=True)
class HtmlReport:
    """Everything the report shows.

    ``command``: the command line that produced the results ('' when none did: a library
    call); ``created``: when (a datetime or text); ``version``: the software and its version,
    e.g. ``ndt-cli 0.2.0``; ``summary`` and ``network``: (label, value) pairs shown in order;
    ``controls``: the control stations (none: no section), ``control_note`` what the table
    rests on (the grid scale); ``cards``: the link inspector's figures; ``tried``: the
    registrations left out of the network and ``tried_note`` why scans are left out;
    ``config_yaml``: the configuration used, as YAML text; ``notes``: paragraphs of text.
    """

    title: str
    command: str
    created: datetime | str
    version: str
    verdict: Verdict
    summary: tuple[tuple[str, str], ...] = ()
    network: tuple[tuple[str, str], ...] = ()
    controls: tuple[ControlRow, ...] = ()
    control_note: str = ""
    scans: tuple[ScanRow, ...] = ()
    links: tuple[LinkRow, ...] = ()
    figures: tuple[Figure, ...] = ()
    cards: tuple[LinkCard, ...] = ()
    tried: tuple[LinkRow, ...] = ()
    tried_note: tuple[str, ...] = ()
    config_yaml: str = ""
    notes: tuple[str, ...] = ()


_CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(png: bytes) -> tuple[int, int]:
    """Width and height of a PNG from its IHDR chunk; ValueError when it is not a PNG."""
    if len(png) < 24 or not png.startswith(_PNG_SIGNATURE) or png[12:16] != b"IHDR":
        raise ValueError("figure is not a PNG image")
    width, height = struct.unpack(">II", png[16:24])
    return int(width), int(height)


def img(png: bytes, alt: str) -> str:
    """An ``<img>`` of the PNG as a data URI, with its size."""
    width, height = png_size(png)
    data = base64.b64encode(png).decode("ascii")
    return (
        f'<img src="data:image/png;base64,{data}" width="{width}" height="{height}" '
        f'alt="{esc(alt)}">'
    )


def _figure(number: int, fig: Figure) -> str:
    """A ``<figure>`` with the PNG and a numbered caption."""
    return (
        f'<figure id="figure-{number}">{img(fig.png, fig.alt or fig.caption)}\n'
        f"<figcaption>Figure {number}. {esc(fig.caption)}</figcaption></figure>"
    )


def _created(created: datetime | str) -> str:
    """The creation time as text (a datetime to the second, with its zone when known)."""
    if isinstance(created, datetime):
        return created.isoformat(sep=" ", timespec="seconds")
    return str(created)


def _header(report: HtmlReport) -> str:
    """The header block: title, command line (when there is one), creation time and software."""
    command = (("Command", f"<code>{esc(report.command)}</code>"),) if report.command else ()
    rows = (
        *command,
        ("Created", esc(_created(report.created))),
        ("Software", esc(report.version)),
    )
    body = "".join(f'<tr><th scope="row">{k}</th><td>{v}</td></tr>' for k, v in rows)
    return f'<header><h1>{esc(report.title)}</h1>\n<table class="meta">{body}</table></header>'


def _verdict(verdict: Verdict) -> str:
    """The verdict box: the outcome in words and, one line each, what it rests on."""
    word = {"ok": "OK", "remarks": "OK, with remarks", "bad": "NOT OK"}[verdict.css]
    reason = f" \u2014 {esc(verdict.reason)}" if verdict.reason else ""
    items = "".join(f"<li>{esc(r)}</li>" for r in verdict.remarks)
    remarks = f"<ul>{items}</ul>" if items else ""
    return (
        f'<div class="verdict {verdict.css}" id="verdict"><p><strong>Result: {word}</strong>'
        f"{reason}</p>{remarks}</div>"
    )


class _Numbers:
    """Section numbers, counted as sections are written."""

    def __init__(self) -> None:
        self.n = 0

    def next(self) -> int:
        self.n += 1
        return self.n


def _summary(report: HtmlReport, n: _Numbers) -> str:
    """The verdict, the summary pairs and the network's figures."""
    network = ""
    if report.network:
        network = "<h3>Network</h3>\n" + kv_table(report.network, "network")
    return (
        f'<section id="summary-section"><h2>{n.next()}. Summary</h2>\n'
        f"{_verdict(report.verdict)}\n{kv_table(report.summary, 'summary')}\n{network}</section>"
    )


def _figures(report: HtmlReport, n: _Numbers) -> str:
    """The figures section (only when there is a figure)."""
    if not report.figures:
        return ""
    figures = "\n".join(_figure(k, f) for k, f in enumerate(report.figures, start=1))
    return f'<section id="figures-section"><h2>{n.next()}. Plan</h2>\n{figures}</section>'


def _notes(report: HtmlReport, n: _Numbers) -> str:
    if not report.notes:
        return ""
    notes = "\n".join(f"<p>{esc(note)}</p>" for note in report.notes)
    return f'<section id="notes-section"><h2>{n.next()}. Notes</h2>\n{notes}</section>'


def _appendix(report: HtmlReport) -> str:
    """The configuration appendix."""
    text = esc(report.config_yaml) if report.config_yaml.strip() else "(not recorded)"
    return (
        '<section class="appendix" id="config-section"><h2>Appendix A. Configuration</h2>\n'
        f'<pre class="config">{text}</pre></section>'
    )


def _main(report: HtmlReport) -> str:
    """Every numbered section, in order."""
    n = _Numbers()
    parts = [_summary(report, n)]
    if report.controls:
        parts.append(control_section(report.controls, report.control_note, n.next()))
    parts.append(_figures(report, n))
    parts.append(tables(report.scans, report.links, n.next(), n.next()))
    if report.cards:
        parts.append(inspector_section(report.cards, n.next(), img))
    if report.tried or report.tried_note:
        parts.append(tried_section(report.tried, report.tried_note, n.next()))
    parts.append(_notes(report, n))
    return "\n".join(p for p in parts if p)


def render_html(report: HtmlReport) -> str:
    """The whole report as one self-contained HTML5 document (UTF-8 text)."""
    title = esc(report.title)
    footer = f"{esc(report.version)} \u2014 {esc(_created(report.created))}"
    return "\n".join(
        (
            "<!DOCTYPE html>",
            '<html lang="en">',
            "<head>",
            '<meta charset="utf-8">',
            f'<meta http-equiv="Content-Security-Policy" content="{_CSP}">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            '<meta name="color-scheme" content="light">',
            f'<meta name="generator" content="{esc(report.version)}">',
            f"<title>{title}</title>",
            f"<style>{CSS}</style>",
            "</head>",
            "<body>",
            _header(report),
            "<main>",
            _main(report),
            _appendix(report),
            "</main>",
            f"<footer>Report generated by {footer}.</footer>",
            "</body>",
            "</html>",
            "",
        )
    )
