"""Point files as text: xyz/txt/csv/3d, the first three numeric columns of each row."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError
from ndt_cli.io.formats import PointReader

_SPLIT = re.compile(r"[\s,;]+")


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


class TextReader(PointReader):
    """xyz/txt/csv: first three numeric columns, separated by whitespace, comma or semicolon.

    Leading lines that are not a row of numbers (headers, ``#`` or ``//`` comments) are skipped;
    after the first data row, blank and comment lines are allowed but any other row is an error.
    """

    suffixes = (".xyz", ".txt", ".csv", ".3d")  # .3d: 3DTK's plain "x y z" lines

    def read_xyz(self, path: Path) -> np.ndarray:
        try:
            with path.open(encoding="utf-8-sig") as fh:
                n_header, delimiter = 0, None
                for line in fh:
                    content = _strip_comment(line)
                    if content and _parse_row(content) is not None:
                        delimiter = "," if "," in content else ";" if ";" in content else None
                        break
                    n_header += 1
                else:
                    return np.empty((0, 3))
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
