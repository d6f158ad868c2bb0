"""Point files as text: xyz/txt/csv/3d, the first three numeric columns of each row."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError
from ndt_cli.io.formats import PointReader
from ndt_cli.io.record_types import Chunk, Summary

_SPLIT = re.compile(r"[\s,;]+")
_HEAD_LINES = 200  # leading lines searched for the first row of points


def _parse_row(line: str) -> tuple[float, float, float] | None:
    """First three numbers of a text row, or None if it does not start with three numbers."""
    tokens = [t for t in _SPLIT.split(line.strip(), maxsplit=3)[:3] if t]
    if len(tokens) < 3:
        return None
    try:
        return float(tokens[0]), float(tokens[1]), float(tokens[2])
    except ValueError:
        return None


def _strip_comment(line: str) -> str:
    return line.split("#", 1)[0].split("//", 1)[0].strip()


_DECIMAL_COMMA = re.compile(r"^[-+]?\d+,\d+$")


def _has_decimal_commas(line: str) -> bool:
    """Numbers written with a decimal comma ('1,5;2,5;3,5' or '1,5 2,5 3,5')."""
    tokens = [t for t in re.split(r"[\s;]+", line.strip()) if t]
    return len(tokens) >= 3 and all(_DECIMAL_COMMA.match(t) for t in tokens[:3])


def _numeric(line: str) -> bool:
    """Every field of the row is a number."""
    try:
        [float(t) for t in _SPLIT.split(line.strip()) if t]
    except ValueError:
        return False
    return True


def _first_data_row(lines: list[str]) -> int | None:
    """Index of the first row of points among leading lines: it starts with three numbers, and
    a row that also holds words is a header when the row after it is numbers only ('2024 11 23
    survey' above '1.0 2.0 3.0')."""
    rows = [(k, c) for k, line in enumerate(lines) if (c := _strip_comment(line))]
    for n, (k, content) in enumerate(rows):
        if _parse_row(content) is None:
            continue
        following = rows[n + 1][1] if n + 1 < len(rows) else None
        if _numeric(content) or following is None or not _numeric(following):
            return k
    return None


class TextReader(PointReader):
    """xyz/txt/csv: first three numeric columns, separated by whitespace, comma or semicolon.

    Leading lines that are not a row of points (headers, ``#`` or ``//`` comments) are skipped:
    the first row starts with three numbers (a line that also holds words above a row of numbers
    only is a header). After
    it, blank and comment lines are allowed but any other row is an error. Decimal commas
    ('1,5;2,5;3,5') are reported, never misread.
    """

    suffixes = (".xyz", ".txt", ".csv", ".3d")  # .3d: 3DTK's plain "x y z" lines
    name = "text"

    def summary(self, path: Path) -> Summary:
        return Summary(path, self.name, None, None, ())

    def records(self, path: Path, chunk_points: int) -> Iterator[Chunk]:
        """x, y, z only: a text file has no other attribute."""
        xyz = self.read_xyz(path)
        for start in range(0, len(xyz), chunk_points):
            part = xyz[start : start + chunk_points]
            yield {a: np.ascontiguousarray(part[:, k]) for k, a in enumerate("xyz")}

    def check(self, path: Path) -> None:
        """Raise unless a row of x y z numbers starts among the first lines."""
        if _first_data_row(self._head(path)) is None:
            raise InputError(f"no row of x y z numbers in its first {_HEAD_LINES} lines", path)

    @staticmethod
    def _head(path: Path) -> list[str]:
        """The leading lines (decimal commas refused)."""
        try:
            with path.open(encoding="utf-8-sig") as fh:
                head = [line for _, line in zip(range(_HEAD_LINES), fh, strict=False)]
        except UnicodeDecodeError as exc:
            raise InputError(
                f"not a UTF-8 text file ({exc.reason} at byte {exc.start})", path
            ) from exc
        for number, line in enumerate(head, 1):
            if _has_decimal_commas(_strip_comment(line)):
                raise InputError(
                    f"line {number}: decimal commas ({line.strip()[:30]!r}) are not supported; "
                    "write the numbers with decimal points",
                    path,
                )
        return head

    def read_xyz(self, path: Path) -> np.ndarray:
        head = self._head(path)
        n_header = _first_data_row(head)
        if n_header is None:
            return np.empty((0, 3))
        first = _strip_comment(head[n_header])
        delimiter = "," if "," in first else ";" if ";" in first else None
        try:  # fast path: numpy's C parser
            return np.loadtxt(
                path,
                dtype=np.float64,
                delimiter=delimiter,
                comments=("#", "//"),
                skiprows=n_header,
                usecols=(0, 1, 2),
                ndmin=2,
                encoding="utf-8-sig",
            )
        except ValueError:
            return self._read_slow(path, n_header)
        except UnicodeDecodeError as exc:
            raise InputError(
                f"not a UTF-8 text file ({exc.reason} at byte {exc.start})", path
            ) from exc

    @staticmethod
    def _read_slow(path: Path, n_header: int) -> np.ndarray:
        """Row-by-row parse (mixed separators, ragged rows); reports the first bad line."""
        rows = []
        with path.open(encoding="utf-8-sig") as fh:
            for number, line in enumerate(fh, start=1):
                content = _strip_comment(line)
                if number <= n_header or not content:
                    continue
                row = _parse_row(content)
                if row is None:
                    shown = content if len(content) <= 40 else content[:37] + "..."
                    raise InputError(f"line {number}: expected three numbers, got {shown!r}", path)
                rows.append(row)
        return np.array(rows, dtype=np.float64).reshape(-1, 3)
