"""PTX, the text export of Leica Cyclone: one or more scans per file.

Each scan is a header of ten lines, then ``columns x rows`` point lines:

- the number of columns, then of rows;
- the scanner's position (3 numbers) and its x, y and z axes (3 numbers each);
- a 4x4 transform of the scan into the registered frame, written transposed (its last line is
  the translation and 1), so that ``[x y z 1] @ M`` is the registered point;
- per point ``x y z intensity`` or ``x y z intensity red green blue``, in the scanner's frame;
  ``0 0 0`` marks a missing return.

A scan is named ``FILE.ptx#K`` (K from 0); a plain ``FILE.ptx`` means its only scan. As for
E57, points are read in each scan's own frame and the stored transform is not applied (it is
reported, never used for registration).
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np

from ndt_cli.errors import InputError
from ndt_cli.io.multiscan import split_spec, which_scan

HEADER_LINES = 10


@dataclass(frozen=True)
class PtxScan:
    """The header of one scan: where its point lines start (0-based line number), its grid,
    and ``transform`` (4x4, column convention: scanner frame to the registered frame)."""

    first_line: int
    columns: int
    rows: int
    transform: np.ndarray

    @property
    def count(self) -> int:
        """Point lines of the scan (missing returns included)."""
        return self.columns * self.rows


def _numbers(line: str, n: int, what: str, number: int, path: Path) -> list[float]:
    try:
        values = [float(v) for v in line.split()]
    except ValueError:
        values = []
    if len(values) != n or not np.isfinite(values).all():
        raise InputError(f"line {number}: expected {what} ({n} numbers)", path)
    return values


def _header(lines: list[str], start: int, path: Path) -> PtxScan:
    """The scan whose header is ``lines`` (ten lines, the first one is line ``start``)."""
    grid = []
    for k, what in enumerate(("the number of columns", "the number of rows")):
        text = lines[k].strip()
        if not (text.isascii() and text.isdigit()):
            raise InputError(f"line {start + k + 1}: expected {what} of a PTX scan", path)
        grid.append(int(text))
    for k in range(2, 6):
        _numbers(lines[k], 3, "the scanner's position or an axis", start + k + 1, path)
    rows = [_numbers(lines[k], 4, "a row of the 4x4", start + k + 1, path) for k in range(6, 10)]
    M = np.array(rows)
    return PtxScan(start + HEADER_LINES, grid[0], grid[1], M.T)


def scans(path: str | Path) -> list[PtxScan]:
    """The headers of every scan of a PTX file (the point lines are skipped, not parsed; kept
    while the file is unchanged, so that its scans are not listed again for each one)."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or exc})", p) from None
    return list(_scans(p, st.st_mtime_ns, st.st_size))


@functools.lru_cache(maxsize=8)
def _scans(p: Path, mtime_ns: int, size: int) -> tuple[PtxScan, ...]:
    out: list[PtxScan] = []
    try:
        with open(p, encoding="ascii", errors="replace") as fh:
            line_no = 0
            while True:
                head = [fh.readline() for _ in range(HEADER_LINES)]
                if not head[0].strip() and all(not h for h in head[1:]):
                    break  # end of the file
                if not all(head):
                    raise InputError(f"line {line_no + 1}: a scan header is cut short", p)
                scan = _header(head, line_no, p)
                for _ in range(scan.count):
                    if not fh.readline():
                        raise InputError(f"scan #{len(out)} ends before its {scan.count} points", p)
                out.append(scan)
                line_no = scan.first_line + scan.count
    except OSError as exc:
        raise InputError(f"cannot read ({exc.strerror or exc})", p) from None
    if not out:
        raise InputError("not a PTX file: no scan header", p)
    return tuple(out)


def scan_count(path: str | Path) -> int:
    """Number of scans in a PTX file."""
    return len(scans(path))


def scan_of(spec: str | Path) -> PtxScan:
    """The header of the scan ``spec`` names (``FILE.ptx#K``)."""
    path, index = split_spec(spec)
    found = scans(path)
    return found[which_scan(path, index, len(found), str(spec))]


def _skip(fh: IO[str], lines: int) -> None:
    for _ in range(lines):
        fh.readline()


def chunks(spec: str | Path, chunk_points: int) -> Iterator[np.ndarray]:
    """The point lines of the scan ``spec`` names, as (m, 4) or (m, 7) float64 arrays of at
    most ``chunk_points`` rows: x, y, z (scanner frame), intensity, and red, green, blue."""
    path, _ = split_spec(spec)
    scan = scan_of(spec)
    with open(path, encoding="ascii", errors="replace") as fh:
        _skip(fh, scan.first_line)
        width = None
        for start in range(0, scan.count, chunk_points):
            n = min(chunk_points, scan.count - start)
            try:
                block = np.loadtxt(fh, max_rows=n, ndmin=2)
            except ValueError as exc:
                raise InputError(f"scan point lines: {exc}", spec) from None
            cols = block.shape[1]
            if block.shape[0] != n or cols not in (4, 7) or width not in (None, cols):
                line = scan.first_line + start + 1
                raise InputError(f"lines from {line}: expected {n} points of 4 or 7 numbers", spec)
            width = block.shape[1]
            yield block


def read_xyz(spec: str | Path) -> np.ndarray:
    """(N,3) float64 points of one scan, in the scanner's frame (transform not applied)."""
    parts = [block[:, :3] for block in chunks(spec, 1_000_000)]
    return np.concatenate(parts) if parts else np.empty((0, 3))


def header_pose(spec: str | Path) -> np.ndarray:
    """The 4x4 transform stored in a scan's header (scanner frame to the registered frame)."""
    return scan_of(spec).transform
