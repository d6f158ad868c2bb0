"""Which scan pairs a campaign registers: the network of links.

Each scan is linked to its ``neighbours`` predecessors in the scan order (``adjacent`` to the
one before it, ``skip`` to those before that), to the pairs the user lists (``user``), and,
after a first adjustment, to the scans that the network puts within the loop radius but that
no link joins yet (``loop``: a street that comes back to its start, two passes of one place).
Redundant links are what lets the adjustment check one link against the others.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError, read_user_text

LOOP_RADIUS_FACTOR = 2.0  # default loop radius: this times the median adjacent link length
MAX_LOOPS_PER_SCAN = 2  # loop candidates per scan, nearest first


class LinkKind(StrEnum):
    """Why a pair of scans is registered."""

    ADJACENT = "adjacent"  # a scan and the one before it
    SKIP = "skip"  # a scan and one two or more before it
    LOOP = "loop"  # close according to the network, registered with its pose as a guess too
    USER = "user"  # listed by the user (--pairs)


@dataclass(frozen=True)
class PlannedLink:
    """A pair to register: ``source`` onto ``target`` (scan indices), and why."""

    target: int
    source: int
    kind: LinkKind


def plan_sequence(
    n_scans: int, neighbours: int, unreadable: Iterable[int] = ()
) -> list[PlannedLink]:
    """Each scan against its ``neighbours`` nearest readable predecessors.

    A scan that cannot be read gets one (failing) link from the readable scan before it, so
    that the outputs say why it has no pose; readable scans skip over it, so that they keep
    ``neighbours`` links (with one neighbour: the old chain, scan i against the last readable
    scan before it).
    """
    bad = set(unreadable)
    links = []
    for j in range(1, n_scans):
        readable = [i for i in range(j - 1, -1, -1) if i not in bad]
        earlier = readable[:neighbours] if j not in bad else readable[:1]
        if not readable:  # nothing readable before it: one link that says why
            earlier = [j - 1]
        for rank, i in enumerate(earlier):
            kind = LinkKind.ADJACENT if rank == 0 else LinkKind.SKIP
            links.append(PlannedLink(i, j, kind))
    return links


def read_pairs(path: Path, names: Sequence[str]) -> list[PlannedLink]:
    """User pairs from a CSV of ``target,source`` rows (scan names as the outputs show them,
    file names, or 0-based indices; a header row and ``#`` comments are allowed)."""
    lookup = {name: k for k, name in enumerate(names)}
    lookup.update({Path(name).name: k for k, name in enumerate(names)})
    rows = csv.reader(read_user_text(path, "pairs").splitlines())
    links = []
    for number, row in enumerate(rows, 1):
        cells = [c.strip() for c in row]
        if not cells or not cells[0] or cells[0].startswith("#"):
            continue
        if len(cells) < 2:
            raise InputError(f"line {number}: expected 'target,source'", path)
        ends = [_scan_index(c, lookup, len(names)) for c in cells[:2]]
        if None in ends:
            if number == 1:
                continue  # a header
            raise InputError(f"line {number}: no scan named {cells[ends.index(None)]!r}", path)
        if ends[0] == ends[1]:
            raise InputError(f"line {number}: a scan cannot be registered onto itself", path)
        links.append(PlannedLink(ends[0], ends[1], LinkKind.USER))
    return links


def _scan_index(cell: str, lookup: dict[str, int], n: int) -> int | None:
    if cell in lookup:
        return lookup[cell]
    return int(cell) if cell.isdigit() and int(cell) < n else None


def merge(links: Iterable[PlannedLink]) -> list[PlannedLink]:
    """One link per unordered pair (the first planned wins), in a stable order."""
    seen: set[tuple[int, int]] = set()
    out = []
    for link in links:
        pair = (min(link.target, link.source), max(link.target, link.source))
        if pair not in seen:
            seen.add(pair)
            out.append(link)
    return out


def median_adjacent_length(
    links: Sequence[PlannedLink], poses: Sequence[np.ndarray | None]
) -> float:
    """Median distance (m) between the scans of the adjacent links whose scans both have a
    pose; NaN when none has."""
    lengths = [
        float(np.linalg.norm(poses[k.target][:3, 3] - poses[k.source][:3, 3]))
        for k in links
        if k.kind is LinkKind.ADJACENT
        and poses[k.target] is not None
        and poses[k.source] is not None
    ]
    return float(np.median(lengths)) if lengths else float("nan")


def plan_loops(
    poses: Sequence[np.ndarray | None],
    existing: Iterable[PlannedLink],
    radius: float,
) -> list[PlannedLink]:
    """Loop candidates: pairs of posed scans at most ``radius`` m apart (scanner positions in
    the world) that no link joins yet, at most ``MAX_LOOPS_PER_SCAN`` per scan, nearest first;
    the later scan is the source."""
    joined = {(min(k.target, k.source), max(k.target, k.source)) for k in existing}
    posed = [k for k, T in enumerate(poses) if T is not None]
    pairs = []
    for a in posed:
        for b in posed:
            if a < b and (a, b) not in joined:
                d = float(np.linalg.norm(poses[a][:3, 3] - poses[b][:3, 3]))
                if d <= radius:
                    pairs.append((d, a, b))
    count: dict[int, int] = {}
    loops = []
    for _, a, b in sorted(pairs):
        if count.get(a, 0) < MAX_LOOPS_PER_SCAN and count.get(b, 0) < MAX_LOOPS_PER_SCAN:
            loops.append(PlannedLink(a, b, LinkKind.LOOP))
            count[a], count[b] = count.get(a, 0) + 1, count.get(b, 0) + 1
    return loops
