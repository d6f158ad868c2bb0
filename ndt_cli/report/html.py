"""The client-facing registration report: one self-contained HTML5 file.

The caller describes a run with the frozen dataclasses below (it reads the result folder, this
module does not) and :func:`render_html` turns them into one page, laid out like a surveyor's
registration report: a header block (title, command line, creation time, software), the
verdict and a summary, the table of scans (pose and standard deviations), the table of links
(registration and network adjustment), the figures, optional notes and the configuration as an
appendix.

The page needs nothing but itself: the CSS is inline, the figures are PNG data URIs, there is no
JavaScript, and a Content-Security-Policy forbids every fetch but ``data:`` images. It prints
on A4 (long cells wrap, table headers repeat, figures are not split). Status values are written
as text and coloured (green ok, amber suspect or degenerate, red failed, rejected or unposed).
Every value is HTML-escaped, its characters that are not printable (bidi controls) shown as
escapes. Missing numbers (None, NaN) show as an en dash.
"""

from __future__ import annotations

import base64
import html
import math
import struct
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import datetime
from typing import Any

__all__ = [
    "STATUS_CLASSES",
    "Figure",
    "HtmlReport",
    "LinkRow",
    "ScanRow",
    "Verdict",
    "render_html",
    "status_class",
]


@dataclass(frozen=True)
class Verdict:
    """The overall outcome: ``ok``, and when not ok a one-line ``reason``."""

    ok: bool
    reason: str = ""


@dataclass(frozen=True)
class ScanRow:
    """One scan: its pose in the world frame and its standard deviations (1 sigma).

    ``status`` is free text such as ``ok``, ``anchor``, ``unposed`` or ``unreadable``; any
    number may be None (not known). ``reason`` explains a status that is not ok.
    """

    name: str
    status: str = ""
    x_m: float | None = None
    y_m: float | None = None
    z_m: float | None = None
    yaw_deg: float | None = None
    sd_x_cm: float | None = None
    sd_y_cm: float | None = None
    sd_z_cm: float | None = None
    sd_yaw_deg: float | None = None
    reason: str = ""


@dataclass(frozen=True)
class LinkRow:
    """One link of the network: its registration and its residual after the adjustment.

    ``kind``: adjacent, skip, loop, user...; ``status``: the registration's status (ok,
    suspect, degenerate, not_converged, no_overlap, failed); ``state``: the link in the
    network (used, confirmed, rejected...). ``overlap`` is a fraction (0-1, shown in %),
    ``ambiguity`` the second candidate's evidence over the best one's.
    """

    kind: str
    target: str
    source: str
    status: str = ""
    state: str = ""
    score_per_point: float | None = None
    overlap: float | None = None
    ambiguity: float | None = None
    icp_rms_cm: float | None = None
    residual_deg: float | None = None
    residual_cm: float | None = None
    warnings: tuple[str, ...] = ()


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
    call); ``created``: when (a datetime
    or text); ``version``: the software and its version, e.g. ``ndt-cli 0.2.0``;
    ``summary``: (label, value) pairs shown in order; ``config_yaml``: the configuration
    used, as YAML text; ``notes``: paragraphs of free text.
    """

    title: str
    command: str
    created: datetime | str
    version: str
    verdict: Verdict
    summary: tuple[tuple[str, str], ...] = ()
    scans: tuple[ScanRow, ...] = ()
    links: tuple[LinkRow, ...] = ()
    figures: tuple[Figure, ...] = ()
    config_yaml: str = ""
    notes: tuple[str, ...] = ()


_CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"

CSS = """
:root { --ok: #1b7a32; --ok-bg: #e3f4e6; --warn: #8a5a00; --warn-bg: #fff1cc;
  --bad: #b3261e; --bad-bg: #fde4e1; --grey: #555; --rule: #c8cdd2; --head: #eef1f4; }
* { box-sizing: border-box; }
html { color: #111; background: #fff; }
body { font: 14px/1.45 "Helvetica Neue", Arial, "Liberation Sans", "DejaVu Sans", sans-serif;
  max-width: 1200px; margin: 0 auto; padding: 24px; }
h1 { font-size: 1.6em; margin: 0 0 0.4em; }
h2 { font-size: 1.2em; margin: 1.6em 0 0.5em; padding-bottom: 0.2em;
  border-bottom: 2px solid #234; }
header { border-bottom: 3px solid #234; padding-bottom: 0.8em; }
code, pre { font-family: "DejaVu Sans Mono", "Liberation Mono", Consolas, monospace;
  font-size: 0.9em; }
table { border-collapse: collapse; width: 100%; }
th, td { padding: 3px 6px; text-align: left; vertical-align: top;
  overflow-wrap: anywhere; word-break: normal; }
th, td.word { overflow-wrap: normal; }
table.meta th, table.kv th { width: 14em; font-weight: 600; color: var(--grey); }
table.meta td, table.kv td { border-bottom: 1px solid #e3e6ea; }
table.kv { width: auto; min-width: 50%; }
table.data { font-size: 0.88em; }
table.data th { background: var(--head); border: 1px solid var(--rule); font-weight: 600;
  vertical-align: bottom; }
table.data thead tr.group th { text-align: center; }
table.data td { border: 1px solid var(--rule); }
table.data tbody tr:nth-child(even) td { background: #f8f9fa; }
td.num { text-align: right; white-space: nowrap; font-variant-numeric: tabular-nums; }
td.empty { color: #888; text-align: center; }
.st { display: inline-block; padding: 0 5px; border: 1px solid; border-radius: 3px;
  font-weight: 600; white-space: nowrap; }
.st-ok { color: var(--ok); background: var(--ok-bg); }
.st-warn { color: var(--warn); background: var(--warn-bg); }
.st-bad { color: var(--bad); background: var(--bad-bg); }
.st-none { color: var(--grey); background: #f1f1f1; }
.verdict { margin: 1em 0; padding: 0.6em 0.9em; border: 2px solid; border-radius: 4px;
  font-size: 1.1em; }
.verdict.ok { color: var(--ok); background: var(--ok-bg); }
.verdict.bad { color: var(--bad); background: var(--bad-bg); }
.legend, figcaption, footer { color: var(--grey); font-size: 0.88em; }
.table-wrap { overflow-x: auto; }
figure { margin: 1em 0; text-align: center; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--rule); }
pre.config { background: #f6f8fa; border: 1px solid var(--rule); padding: 8px;
  white-space: pre-wrap; overflow-wrap: anywhere; }
footer { margin-top: 2em; border-top: 1px solid var(--rule); padding-top: 0.5em; }
@page { size: A4; margin: 14mm 12mm; }
@media print {
  * { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  body { font-size: 9pt; max-width: none; padding: 0; }
  table.data { font-size: 7.5pt; }
  th, td { padding: 2px 3px; }
  .table-wrap { overflow: visible; }
  h2 { break-after: avoid; }
  tr, figure, .verdict, table.kv { break-inside: avoid; }
  thead { display: table-header-group; }
  figure img { max-height: 230mm; width: auto; }
  section.appendix { break-before: page; }
}
"""

STATUS_CLASSES = {
    **dict.fromkeys(("ok", "anchor", "confirmed", "used"), "ok"),
    **dict.fromkeys(("suspect", "degenerate"), "warn"),
    **dict.fromkeys(("failed", "not_converged", "no_overlap", "unposed", "rejected"), "bad"),
}
"""The colour of every status a report shows: a registration's (:class:`ndt_cli.ndt.result.Status`),
a scan's (:class:`ndt_cli.pipeline.verify.NodeStatus`, and ``anchor``) and a link's state in the
network (:class:`ndt_cli.pipeline.verify.EdgeState`; ``unused`` is not coloured)."""
_DASH = "\u2013"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _e(value: object) -> str:
    """``value`` as HTML-escaped text (quotes too); characters that are not printable (bidi
    overrides and isolates, which would reverse the text around them, other invisible format
    characters, controls, bytes of a name that is not UTF-8) are shown as ``\\uXXXX``."""
    text = "".join(c if c.isprintable() or c in "\n\t" else f"\\u{ord(c):04x}" for c in str(value))
    return html.escape(text, quote=True)


def status_class(status: str) -> str:
    """CSS class of a status: ``ok`` (green), ``warn`` (amber), ``bad`` (red) or ``none``."""
    key = status.strip().lower().replace(" ", "_").replace("-", "_")
    return STATUS_CLASSES.get(key, "none")


def _badge(status: str) -> str:
    """A status written as text in a coloured box (an en dash when empty)."""
    if not status:
        return _DASH
    text = status.replace("_", " ")
    return f'<span class="st st-{status_class(status)}">{_e(text)}</span>'


def _num(value: float | None, digits: int, scale: float = 1.0) -> str:
    """``value * scale`` with ``digits`` decimals; '' when missing or not finite."""
    if value is None or not math.isfinite(value):
        return ""
    return f"{value * scale:.{digits}f}"


# a column of a data table: header (plain text), how to get the cell's text, and its kind:
# "num" (right-aligned), "status" (a coloured badge), "word" (short text broken only between
# words) or "text" (broken anywhere when needed: names, reasons, warnings)
_Column = tuple[str, Callable[[Any], str], str]


def _numeric(attr: str, digits: int, scale: float = 1.0) -> Callable[[Any], str]:
    """A cell getter: attribute ``attr`` formatted as a number."""
    return lambda row: _num(getattr(row, attr), digits, scale)


def _text(attr: str) -> Callable[[Any], str]:
    """A cell getter: attribute ``attr`` as text."""
    return lambda row: str(getattr(row, attr))


_SCAN_GROUPS = (("Scan", 2), ("Pose in the world frame", 4), ("Standard deviation (1σ)", 4))
_SCAN_GROUPS += (("", 1),)
_SCAN_COLUMNS: tuple[_Column, ...] = (
    ("scan", _text("name"), "text"),
    ("status", _text("status"), "status"),
    ("x (m)", _numeric("x_m", 3), "num"),
    ("y (m)", _numeric("y_m", 3), "num"),
    ("z (m)", _numeric("z_m", 3), "num"),
    ("yaw (deg)", _numeric("yaw_deg", 4), "num"),
    ("σx (cm)", _numeric("sd_x_cm", 2), "num"),
    ("σy (cm)", _numeric("sd_y_cm", 2), "num"),
    ("σz (cm)", _numeric("sd_z_cm", 2), "num"),
    ("σyaw (deg)", _numeric("sd_yaw_deg", 4), "num"),
    ("reason", _text("reason"), "text"),
)
_LINK_GROUPS = (("Link", 3), ("Registration", 5), ("Network adjustment", 3), ("", 1))
_LINK_COLUMNS: tuple[_Column, ...] = (
    ("kind", _text("kind"), "word"),
    ("target", _text("target"), "text"),
    ("source", _text("source"), "text"),
    ("status", _text("status"), "status"),
    ("score / point", _numeric("score_per_point", 3), "num"),
    ("overlap (%)", _numeric("overlap", 1, 100.0), "num"),
    ("ambiguity (2nd / best)", _numeric("ambiguity", 3), "num"),
    ("ICP RMS (cm)", _numeric("icp_rms_cm", 2), "num"),
    ("state", _text("state"), "status"),
    ("residual (deg)", _numeric("residual_deg", 4), "num"),
    ("residual (cm)", _numeric("residual_cm", 2), "num"),
    ("warnings", lambda link: "\n".join(link.warnings), "text"),
)


def _cell(text: str, kind: str) -> str:
    """One ``<td>``: empty cells show an en dash; line breaks in text are kept."""
    if not text:
        return f'<td class="empty">{_DASH}</td>'
    if kind == "status":
        return f"<td>{_badge(text)}</td>"
    if kind in ("num", "word"):
        return f'<td class="{kind}">{_e(text)}</td>'
    return "<td>" + "<br>".join(_e(line) for line in text.split("\n")) + "</td>"


def _data_table(
    rows: Iterable[Any],
    columns: tuple[_Column, ...],
    groups: tuple[tuple[str, int], ...],
    table_id: str,
) -> str:
    """A data table with a row of column groups above the column headers."""
    group_row = "".join(
        f'<th colspan="{span}" scope="colgroup">{_e(label)}</th>' for label, span in groups
    )
    header_row = "".join(f'<th scope="col">{_e(header)}</th>' for header, _, _ in columns)
    body = "\n".join(
        "<tr>" + "".join(_cell(get(row), kind) for _, get, kind in columns) + "</tr>"
        for row in rows
    )
    if not body:
        body = f'<tr><td colspan="{len(columns)}" class="empty">none</td></tr>'
    return (
        f'<div class="table-wrap"><table class="data" id="{table_id}">\n'
        f'<thead><tr class="group">{group_row}</tr>\n<tr>{header_row}</tr></thead>\n'
        f"<tbody>\n{body}\n</tbody></table></div>"
    )


def _png_size(png: bytes) -> tuple[int, int]:
    """Width and height of a PNG from its IHDR chunk; ValueError when it is not a PNG."""
    if len(png) < 24 or not png.startswith(_PNG_SIGNATURE) or png[12:16] != b"IHDR":
        raise ValueError("figure is not a PNG image")
    width, height = struct.unpack(">II", png[16:24])
    return int(width), int(height)


def _figure(number: int, fig: Figure) -> str:
    """A ``<figure>`` with the PNG as a data URI and a numbered caption."""
    width, height = _png_size(fig.png)
    data = base64.b64encode(fig.png).decode("ascii")
    alt = fig.alt or fig.caption
    return (
        f'<figure id="figure-{number}"><img src="data:image/png;base64,{data}" '
        f'width="{width}" height="{height}" alt="{_e(alt)}">\n'
        f"<figcaption>Figure {number}. {_e(fig.caption)}</figcaption></figure>"
    )


def _created(created: datetime | str) -> str:
    """The creation time as text (a datetime to the second, with its zone when known)."""
    if isinstance(created, datetime):
        return created.isoformat(sep=" ", timespec="seconds")
    return str(created)


def _header(report: HtmlReport) -> str:
    """The header block: title, command line (when there is one), creation time and software."""
    command = (("Command", f"<code>{_e(report.command)}</code>"),) if report.command else ()
    rows = (
        *command,
        ("Created", _e(_created(report.created))),
        ("Software", _e(report.version)),
    )
    body = "".join(f'<tr><th scope="row">{k}</th><td>{v}</td></tr>' for k, v in rows)
    return f'<header><h1>{_e(report.title)}</h1>\n<table class="meta">{body}</table></header>'


def _summary(report: HtmlReport) -> str:
    """The verdict and the summary pairs."""
    verdict = report.verdict
    word, cls = ("OK", "ok") if verdict.ok else ("NOT OK", "bad")
    reason = f" \u2014 {_e(verdict.reason)}" if verdict.reason else ""
    rows = "".join(
        f'<tr><th scope="row">{_e(label)}</th><td>{_e(value)}</td></tr>'
        for label, value in report.summary
    )
    table = f'<table class="kv" id="summary">{rows}</table>' if rows else ""
    return (
        f'<section id="summary-section"><h2>1. Summary</h2>\n'
        f'<p class="verdict {cls}" id="verdict"><strong>Result: {word}</strong>{reason}</p>\n'
        f"{table}</section>"
    )


_LEGEND = (
    '<p class="legend">Status colours: <span class="st st-ok">green</span> ok, used, '
    'confirmed; <span class="st st-warn">amber</span> suspect, degenerate; '
    '<span class="st st-bad">red</span> failed, rejected, unposed. '
    f"{_DASH} : no value.</p>"
)


def _tables(report: HtmlReport) -> str:
    """The sections of the scan table and the link table."""
    n_scans, n_links = len(report.scans), len(report.links)
    scans = _data_table(report.scans, _SCAN_COLUMNS, _SCAN_GROUPS, "scans")
    links = _data_table(report.links, _LINK_COLUMNS, _LINK_GROUPS, "links")
    return (
        f'<section id="scans-section"><h2>2. Scans ({n_scans})</h2>\n{scans}\n{_LEGEND}</section>\n'
        f'<section id="links-section"><h2>3. Links ({n_links})</h2>\n{links}\n'
        '<p class="legend">Registration: the pairwise result of the link; network adjustment: '
        "its state in the network and its residual after the global adjustment.</p></section>"
    )


def _figures_and_notes(report: HtmlReport) -> str:
    """The figures section and the notes section (each only when there is something)."""
    parts = []
    if report.figures:
        figures = "\n".join(_figure(k, f) for k, f in enumerate(report.figures, start=1))
        parts.append(f'<section id="figures-section"><h2>4. Figures</h2>\n{figures}</section>')
    if report.notes:
        number = 4 + len(parts)
        notes = "\n".join(f"<p>{_e(note)}</p>" for note in report.notes)
        parts.append(f'<section id="notes-section"><h2>{number}. Notes</h2>\n{notes}</section>')
    return "\n".join(parts)


def _appendix(report: HtmlReport) -> str:
    """The configuration appendix."""
    text = _e(report.config_yaml) if report.config_yaml.strip() else "(not recorded)"
    return (
        '<section class="appendix" id="config-section"><h2>Appendix A. Configuration</h2>\n'
        f'<pre class="config">{text}</pre></section>'
    )


def render_html(report: HtmlReport) -> str:
    """The whole report as one self-contained HTML5 document (UTF-8 text)."""
    title = _e(report.title)
    footer = f"{_e(report.version)} \u2014 {_e(_created(report.created))}"
    return "\n".join(
        (
            "<!DOCTYPE html>",
            '<html lang="en">',
            "<head>",
            '<meta charset="utf-8">',
            f'<meta http-equiv="Content-Security-Policy" content="{_CSP}">',
            '<meta name="viewport" content="width=device-width, initial-scale=1">',
            '<meta name="color-scheme" content="light">',
            f'<meta name="generator" content="{_e(report.version)}">',
            f"<title>{title}</title>",
            f"<style>{CSS}</style>",
            "</head>",
            "<body>",
            _header(report),
            "<main>",
            _summary(report),
            _tables(report),
            _figures_and_notes(report),
            _appendix(report),
            "</main>",
            f"<footer>Report generated by {footer}.</footer>",
            "</body>",
            "</html>",
            "",
        )
    )
