"""The pieces every section of the HTML report is made of: escaped text, coloured status
badges, numbers, key-value tables and data tables.

A data table is a real table on a wide screen and in print; on a narrow screen (a phone) the
page's CSS stacks each row into a card, every cell preceded by its column's name (its
``data-label``), so that nothing scrolls sideways. Missing numbers (None, NaN) show as an en
dash.
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

DASH = "\u2013"

STATUS_CLASSES = {
    **dict.fromkeys(("ok", "anchor", "confirmed", "used"), "ok"),
    **dict.fromkeys(("suspect", "degenerate"), "warn"),
    **dict.fromkeys(("failed", "not_converged", "no_overlap", "unposed", "rejected"), "bad"),
    "not_checked": "info",
}
"""The colour of every status a report shows: a registration's (:class:`ndt_cli.ndt.result.Status`),
a scan's (:class:`ndt_cli.pipeline.verify.NodeStatus`, and ``anchor``), a control station's
(used, rejected) and a link's state in the network as the report words it: ``confirmed``
(green), ``not checked`` (a kept link no cycle checks: blue-grey, never green), ``rejected``
(red); ``not used``, ``not planned`` and ``other way kept`` are not coloured."""


def esc(value: object) -> str:
    """``value`` as HTML-escaped text (quotes too); characters that are not printable (bidi
    overrides and isolates, which would reverse the text around them, other invisible format
    characters, controls, bytes of a name that is not UTF-8) are shown as ``\\uXXXX``."""
    text = "".join(c if c.isprintable() or c in "\n\t" else f"\\u{ord(c):04x}" for c in str(value))
    return html.escape(text, quote=True)


def status_class(status: str) -> str:
    """CSS class of a status: ``ok`` (green), ``warn`` (amber), ``bad`` (red), ``info``
    (blue-grey) or ``none``."""
    key = status.strip().lower().replace(" ", "_").replace("-", "_")
    return STATUS_CLASSES.get(key, "none")


def badge(status: str) -> str:
    """A status written as text in a coloured box (an en dash when empty)."""
    if not status:
        return DASH
    text = status.replace("_", " ")
    return f'<span class="st st-{status_class(status)}">{esc(text)}</span>'


def num(value: float | None, digits: int, scale: float = 1.0) -> str:
    """``value * scale`` with ``digits`` decimals; '' when missing or not finite."""
    if value is None or not math.isfinite(value):
        return ""
    text = f"{value * scale:.{digits}f}"
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text


@dataclass(frozen=True)
class Column:
    """A column of a data table: its header (plain text), how to get a row's cell text, and
    its kind: ``num`` (right-aligned), ``status`` (a coloured badge), ``name`` (a scan's name:
    the head of a stacked row), ``word`` (short text broken only between words), ``text``
    (broken anywhere when needed: reasons, warnings) or ``html`` (markup made by the caller,
    already escaped)."""

    header: str
    get: Callable[[Any], str]
    kind: str = "text"


def numeric(attr: str, digits: int, scale: float = 1.0) -> Callable[[Any], str]:
    """A cell getter: attribute ``attr`` formatted as a number."""
    return lambda row: num(getattr(row, attr), digits, scale)


def text(attr: str) -> Callable[[Any], str]:
    """A cell getter: attribute ``attr`` as text."""
    return lambda row: str(getattr(row, attr))


def cell(value: str, column: Column) -> str:
    """One ``<td>`` labelled with its column (for stacked rows); empty cells show an en dash,
    line breaks in text are kept."""
    label = f' data-label="{esc(column.header)}"'
    kind = column.kind
    if not value:
        return f'<td class="empty"{label}>{DASH}</td>'
    if kind == "status":
        return f"<td{label}>{badge(value)}</td>"
    if kind == "html":
        return f"<td{label}>{value}</td>"
    if kind in ("num", "word", "name"):
        return f'<td class="{kind}"{label}>{esc(value)}</td>'
    return f"<td{label}>" + "<br>".join(esc(line) for line in value.split("\n")) + "</td>"


def data_table(
    rows: Iterable[Any],
    columns: tuple[Column, ...],
    groups: tuple[tuple[str, int], ...],
    table_id: str,
) -> str:
    """A data table with a row of column groups above the column headers (none when
    ``groups`` is empty)."""
    group_row = "".join(
        f'<th colspan="{span}" scope="colgroup">{esc(label)}</th>' for label, span in groups
    )
    header_row = "".join(f'<th scope="col">{esc(c.header)}</th>' for c in columns)
    body = "\n".join(
        "<tr>" + "".join(cell(c.get(row), c) for c in columns) + "</tr>" for row in rows
    )
    if not body:
        body = f'<tr><td colspan="{len(columns)}" class="empty">none</td></tr>'
    head = f'<tr class="group">{group_row}</tr>\n' if groups else ""
    return (
        f'<div class="table-wrap"><table class="data" id="{table_id}">\n'
        f"<thead>{head}<tr>{header_row}</tr></thead>\n"
        f"<tbody>\n{body}\n</tbody></table></div>"
    )


def kv_table(pairs: Iterable[tuple[str, str]], table_id: str) -> str:
    """A two-column table of (label, value) text pairs ('' when there are none)."""
    rows = "".join(
        f'<tr><th scope="row">{esc(label)}</th><td>{esc(value)}</td></tr>' for label, value in pairs
    )
    return f'<table class="kv" id="{table_id}">{rows}</table>' if rows else ""
