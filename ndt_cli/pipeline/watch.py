"""Field mode: a folder watched for scans, each registered into the campaign once it has landed.

A scan has *landed* when its file is complete: its size and modification time have not changed
for :data:`SETTLE_S` seconds (a scanner or a copy writing it slowly in place), or it was renamed
in whole (then it is stable from the start). Hidden files and the temporary names of copies
(``.part``, ``.tmp``, ``.crdownload``) are ignored until renamed. Scans are taken in the order
they landed (modification time, then natural order of names), which is the campaign's order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from ndt_cli.pipeline.scans import natural_key

SETTLE_S = 0.5  # s a file's size and time must stay the same before it counts as complete
TEMPORARY = (".part", ".tmp", ".crdownload", ".partial")


@dataclass(frozen=True)
class Landed:
    """A scan file that has landed, and when (its modification time, s since the epoch)."""

    path: Path
    mtime: float


@dataclass
class FolderWatch:
    """The scans of ``folder`` (files whose suffix is one of ``suffixes``) as they land.

    :meth:`poll` returns the files that have landed since the last call, in landing order.
    """

    folder: Path
    suffixes: tuple[str, ...]
    settle_s: float = SETTLE_S
    seen: dict[Path, tuple[int, int, float]] = field(default_factory=dict)  # size, mtime, since
    done: set[Path] = field(default_factory=set)

    def _candidates(self) -> list[Path]:
        try:
            entries = list(self.folder.iterdir())
        except OSError:
            return []
        return [
            p
            for p in entries
            if not p.name.startswith(".")
            and p.suffix.lower() in self.suffixes
            and not p.name.lower().endswith(TEMPORARY)
            and p not in self.done
        ]

    def poll(self, now: float | None = None) -> list[Landed]:
        """The files complete since the last call (see the module docstring)."""
        now = time.monotonic() if now is None else now
        landed = []
        for path in self._candidates():
            try:
                st = path.stat()
            except OSError:  # renamed or removed meanwhile
                continue
            state = (st.st_size, st.st_mtime_ns)
            before = self.seen.get(path)
            if before is None or before[:2] != state:
                self.seen[path] = (*state, now)
            elif st.st_size > 0 and now - before[2] >= self.settle_s:
                landed.append(Landed(path, st.st_mtime_ns / 1e9))
        for scan in landed:
            self.done.add(scan.path)
            self.seen.pop(scan.path, None)
        return sorted(landed, key=lambda s: (s.mtime, natural_key(s.path.name)))

    @property
    def pending(self) -> int:
        """Files seen that have not landed yet."""
        return len(self.seen)
