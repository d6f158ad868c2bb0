"""Tables that fit the terminal without cutting a name or a number.

rich shrinks a table that is too wide by wrapping its columns, and as a last resort cuts
every column alike: a scan name or a number would lose characters. Here a table is built in
layouts from the richest to the leanest (optional columns dropped, a link's two names on two
lines); every column but one holds names, numbers or status words at their full width, and
the one text column (reasons) wraps between words. The first layout whose width, with that
column at :data:`MIN_TEXT` characters, fits the terminal is printed; when none does (names
longer than the terminal), each row is printed as a short block of lines instead.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

MIN_TEXT = 16  # characters the text column keeps at least
STYLES = {
    **dict.fromkeys(("ok", "anchor", "confirmed", "used"), "green"),
    **dict.fromkeys(("suspect", "degenerate", "not checked"), "yellow"),
    **dict.fromkeys(("not used", "not planned", "other way kept"), "dim"),
}
"""Colour of a status word on the terminal (green ok, yellow to check, red failed, rejected,
unposed and the rest, dim: not part of the result)."""


def styled(word: str) -> Any:
    """A status word as coloured text (``not_converged`` written ``not converged``)."""
    from rich.text import Text

    text = word.replace("_", " ")
    return Text(text, style=STYLES.get(text, "red") if text else "")


@dataclass(frozen=True)
class Col:
    """A column: its header, its cells (plain text, or rich Text for a status), whether it is
    the wrapping text column, its alignment, and its width ('' cells: at least the header's)."""

    header: str
    cells: Sequence[Any]
    text: bool = False
    justify: str = "left"
    width: int | None = None

    def full(self) -> int:
        """Width of its longest cell or header (the width a fixed column gets)."""
        if self.width is not None:
            return self.width
        longest = max((len(str(c)) for c in self.cells), default=0)
        return max(longest, *(len(w) for w in self.header.split("\n")))


def table(cols: Sequence[Col], title: str, text_width: int | None) -> Any:
    """A rich table of ``cols``: fixed columns at their full width, never wrapped; the text
    column wraps (its width ``text_width``, None: what is left)."""
    from rich import box
    from rich.table import Table

    t = Table(title=title, box=box.SIMPLE_HEAD, pad_edge=False, title_justify="left")
    for c in cols:
        if c.text:
            t.add_column(c.header, width=text_width, overflow="fold", min_width=MIN_TEXT)
        else:
            t.add_column(c.header, width=c.full(), justify=c.justify, overflow="fold")
    for row in zip(*(c.cells for c in cols), strict=True):
        t.add_row(*(_text(v) for v in row))
    return t


def _text(value: Any) -> Any:
    """A cell as rich Text (plain strings are never read as markup: names may hold '[')."""
    from rich.text import Text

    return value if isinstance(value, Text) else Text(str(value))


def width_of(console: Any, renderable: Any) -> int:
    """The width a renderable takes at most on an unbounded line."""
    from rich.measure import Measurement

    return Measurement.get(console, console.options.update_width(100_000), renderable).maximum


def fitted(console: Any, layouts: Sequence[Sequence[Col]], title: str) -> Any | None:
    """The first layout that fits the console's width as a table (see the module docstring);
    None when none does."""
    for cols in layouts:
        if width_of(console, table(cols, title, MIN_TEXT)) <= console.width:
            return table(cols, title, None)
    return None


def print_blocks(console: Any, cols: Sequence[Col], title: str, head: int = 1) -> None:
    """Each row as its first ``head`` cells, then a line ``header: value`` per other cell,
    indented (when no table fits: names longer than the terminal)."""
    from rich.padding import Padding
    from rich.text import Text

    console.print(Text(title, style="italic"), soft_wrap=False)
    for row in zip(*(c.cells for c in cols), strict=True):
        first = Text(" ").join(_text(v) for v in row[:head])
        console.print(first, soft_wrap=False, overflow="fold")
        for c, v in zip(cols[head:], row[head:], strict=True):
            if str(v):
                line = Text(f"{c.header.replace(chr(10), ' ')}: ") + _text(v)
                console.print(Padding(line, (0, 0, 0, 2)), soft_wrap=False, overflow="fold")


def print_fitted(console: Any, layouts: Sequence[Sequence[Col]], title: str, head: int = 1) -> None:
    """Print the first layout that fits, or the leanest as blocks of lines."""
    found = fitted(console, layouts, title)
    if found is not None:
        console.print(found)
    else:
        print_blocks(console, layouts[-1], title, head)
