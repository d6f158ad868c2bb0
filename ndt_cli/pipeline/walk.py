"""The order a campaign's scans were taken in: its walk.

A surveyor scans a street standpoint after standpoint, so the scans taken one after another
stand next to each other: the walk is the campaign's first hint where a new scan is
(:mod:`ndt_cli.pipeline.discovery`). The files' order is not always the walk: two scanners'
files merged, a numbering that restarted, a second day added, names that sort otherwise.
When every scan says when it was taken (:func:`ndt_cli.io.acquired`: a LAS file's GPS times,
an E57 scan's acquisition start), the walk is their time order; otherwise it is the order
the scans were given in. Either way the campaign still checks that the walk places its scans
(:func:`~ndt_cli.pipeline.discovery.order_is_a_hint`) before it follows it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence


class Walk:
    """The campaign's scans (indices in the order they were given) in walk order; not
    ``by_time``: always the order given (the classic chain)."""

    def __init__(self, by_time: bool = True) -> None:
        self.by_time = by_time
        self.times: list[float | None] = []  # per scan: when it was taken (s), or None
        self.order: list[int] = []  # the scans in walk order
        self._rank: dict[int, int] = {}

    @property
    def timed(self) -> bool:
        """Whether every scan has a time (the walk is then their time order, ``by_time``)."""
        return bool(self.times) and all(t is not None for t in self.times)

    def add(self, times: Sequence[float | None]) -> None:
        """Scans given next (their acquisition times, None for a scan without one)."""
        self.times.extend(times)
        n = len(self.times)
        if self.by_time and self.timed:
            self.order = sorted(range(n), key=lambda s: (self.times[s], s))
        else:
            self.order = list(range(n))
        self._rank = {s: k for k, s in enumerate(self.order)}

    @property
    def reordered(self) -> bool:
        """Whether the walk differs from the order the scans were given in."""
        return self.order != sorted(self.order)

    @property
    def adjacent(self) -> set[tuple[int, int]]:
        """Pairs (lo, hi) of scans next to each other along the walk."""
        return {(min(a, b), max(a, b)) for a, b in zip(self.order, self.order[1:], strict=False)}

    def neighbours(self, aside: Iterable[int] = ()) -> set[tuple[int, int]]:
        """Pairs (lo, hi) of scans taken one after the other (:attr:`adjacent`), and of the
        scans either side of one scan in ``aside`` (a scan that tied in nothing: a room seen
        only through its door, taken between two standpoints along the corridor)."""
        out, skip, order = self.adjacent, set(aside), self.order
        for a, b, c in zip(order, order[1:], order[2:], strict=False):
            if b in skip and a not in skip and c not in skip:
                out.add((min(a, c), max(a, c)))
        return out

    def beside(self, scan: int, offsets: Iterable[int]) -> list[int]:
        """The scans ``offsets`` places from ``scan`` along the walk (those that exist)."""
        k = self._rank[scan]
        return [self.order[k + d] for d in offsets if 0 <= k + d < len(self.order)]

    def sort(self, scans: Iterable[int]) -> list[int]:
        """``scans`` in walk order."""
        return sorted(scans, key=self._rank.__getitem__)
