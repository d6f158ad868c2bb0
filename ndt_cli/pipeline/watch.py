"""Field mode's eye on a folder: which files appeared, changed or went, and when each has
settled (is no longer being written).

A file has *settled* when its size, modification and change times and inode have not changed
for ``settle_s`` seconds (a scanner or a copy writing it slowly in place), or when the kernel
reported it closed after writing or renamed in whole since the last look and it has not changed
since (:mod:`ndt_cli.pipeline.closed_files`: at once, where the system tells). A file is
handed out (:attr:`Look.settled`) once per state it settles in: again when it changes and
settles again (a copy over it, a permission fixed), or once more when asked
(:meth:`FolderWatch.again`: a file that could not be read is looked at once more after the
settle time). Hidden files, the temporary names of copies (``.part``, ``.tmp``,
``.crdownload``), other suffixes and the files given in ``skip`` (the run's control file) are
never looked at; an empty file only once it has bytes (or when it was handed out before: a
copy over it has begun). Settled files come in the order they landed (modification time, then
natural order of names): the campaign's order.

The watch is *busy* while a file it has not been told to leave alone (:meth:`FolderWatch.
leave_alone`: no scan) is new, changing or settling, for at most ``hold_s`` seconds of changes
in a row: an empty file is not looked at, and a file that never settles (a log appended to all
the time) holds the watch no longer than that, so an idle watch always ends.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

from ndt_cli.pipeline.closed_files import ClosedFiles
from ndt_cli.pipeline.scans import natural_key

SETTLE_S = 0.5  # s a file's size and times must stay the same before it counts as complete
TEMPORARY = (".part", ".tmp", ".crdownload", ".partial")
MISSING_LOOKS = 2  # looks in a row a handed-out file must be missing to count as gone

Signature = tuple[int, int, int, int]  # size (bytes), modification and change time (ns), inode


def signature(path: Path) -> Signature | None:
    """A file's size, times and inode now (None when it cannot be stat-ed)."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino


@dataclass(frozen=True)
class Settled:
    """A file handed out: its path, its signature, its modification time (s since the epoch)
    and when the watch found it settled (``time.monotonic()``, s)."""

    path: Path
    signature: Signature
    mtime: float
    seen: float


@dataclass(frozen=True)
class Look:
    """One look at the folder: the files settled since the last look (in landing order), the
    handed-out files gone, whether the watch is busy, and whether the folder could be read."""

    settled: tuple[Settled, ...] = ()
    gone: tuple[Path, ...] = ()
    busy: bool = False
    present: bool = True


@dataclass
class _File:
    """What the watch knows of one file."""

    signature: Signature
    since: float  # monotonic s of its last change
    began: float  # monotonic s of the first of its latest changes in a row
    handed: Signature | None = None  # the state it was last handed out in
    quiet: bool = False  # left alone: its changes keep nobody busy
    retry: Signature | None = None  # the state it is handed out once more in
    retried: Signature | None = None
    missing: int = 0  # looks in a row it was not found
    finished: Signature | None = None  # the state its writer closed it (or renamed it) in


class FolderWatch:
    """The files of ``folder`` whose suffix is one of ``suffixes`` (see the module docstring):
    :meth:`look` reports what settled and what went since the last look."""

    def __init__(
        self,
        folder: Path,
        suffixes: tuple[str, ...],
        settle_s: float = SETTLE_S,
        skip: tuple[Path, ...] = (),
        hold_s: float = float("inf"),
    ) -> None:
        self.folder, self.suffixes, self.settle_s = folder, suffixes, settle_s
        self.hold_s = hold_s
        self.skip = {_real(p) for p in skip}
        self.files: dict[Path, _File] = {}
        self.closed: ClosedFiles | None = None  # made once the folder is there
        self.carried: dict[str, bool] = {}  # events read after the last look's states

    def look(self, now: float | None = None) -> Look:
        """What settled and what went since the last look (see the module docstring)."""
        now = time.monotonic() if now is None else now
        before = self._events()  # the writers' events, then the files' states, then again:
        listed = self._listing()
        if listed is None:
            return Look(present=False)
        states = [(path, signature(path)) for path in listed]
        self.carried = self._events()  # a file written or closed meanwhile waits a look
        alone = sum(self._pending(path, sig) for path, sig in states) <= 1
        settled, busy = [], False
        for path, sig in states:
            if sig is not None:
                done = before.get(path.name, False) and path.name not in self.carried
                state, found = self._update(path, sig, now, done and alone)
                busy |= state
                settled += [Settled(path, sig, sig[1] / 1e9, now)] if found else []
        gone = self._gone(set(listed))
        settled.sort(key=lambda s: (s.mtime, natural_key(s.path.name)))
        return Look(tuple(settled), gone, busy)

    def leave_alone(self, path: Path) -> None:
        """The file is no scan: its changes keep the watch busy no more (it is still handed
        out again when it changes and settles)."""
        if path in self.files:
            self.files[path].quiet = True

    def again(self, path: Path, now: float | None = None) -> None:
        """Hand the file out once more after the settle time, unchanged (once per state)."""
        f = self.files.get(path)
        if f is not None and f.retried != f.signature:
            f.retry = f.signature
            f.since = time.monotonic() if now is None else now
            f.finished = None  # once more after the settle time, not at the next look

    def writing(self) -> list[Path]:
        """Files with bytes, not left alone, not handed out in their present state: being
        written (or settling)."""
        return [
            p
            for p, f in self.files.items()
            if f.handed != f.signature and f.signature[0] and not f.quiet
        ]

    def _listing(self) -> list[Path] | None:
        """The folder's files to look at, or None when the folder cannot be read."""
        try:
            entries = list(os.scandir(self.folder))
        except OSError:
            return None
        paths = [Path(e.path) for e in entries]
        return [
            p
            for p in paths
            if not p.name.startswith(".")
            and p.suffix.lower() in self.suffixes
            and not p.name.lower().endswith(TEMPORARY)
            and _real(p) not in self.skip
        ]

    def _pending(self, path: Path, sig: Signature | None) -> bool:
        """Whether the file waits to be handed out (it has bytes, is not left alone and was
        not handed out in this state). A file its writer finished is handed out at once only
        when it is the only one waiting: otherwise it settles by time with the others, so
        that files still come in the order they landed (a file present before the watch
        began sends no event, and one landing after it must not overtake it)."""
        f = self.files.get(path)
        if sig is None or sig[0] == 0:
            return False
        return f is None or (not f.quiet and f.handed != sig)

    def _events(self) -> dict[str, bool]:
        """The writers' latest events since the last call, those carried over first (see
        :meth:`ClosedFiles.events`). The folder is watched from the first look it is there;
        a watch that stopped (the folder gone, events lost) starts again."""
        events, self.carried = self.carried, {}
        if (self.closed is None or not self.closed.active) and self.folder.is_dir():
            self.closed = ClosedFiles(self.folder)
        for name, done in ({} if self.closed is None else self.closed.events()).items():
            events.pop(name, None)
            events[name] = done
        return events

    def _update(
        self, path: Path, sig: Signature, now: float, finished: bool = False
    ) -> tuple[bool, bool]:
        """Note the file's state (``finished``: its writer closed or renamed it since the last
        look): (whether it keeps the watch busy, whether it settled)."""
        f = self.files.get(path)
        if f is None or f.signature != sig:
            quiet = f is not None and f.quiet
            handed = None if f is None else f.handed
            streak = f is not None and f.handed != f.signature and now - f.since < self.settle_s
            began = f.began if f is not None and streak else now
            f = self.files[path] = _File(sig, now, began, handed, quiet)
            if not finished:
                return self._holds(f, now), False
        f.missing = 0
        if finished:
            f.finished = sig
        if f.signature[0] == 0 and f.handed is None:
            return False, False  # empty, never handed out: not looked at
        settling = now - f.since < self.settle_s and f.finished != sig
        if f.handed == sig and f.retry != sig:
            return False, False
        if settling:
            return self._holds(f, now), False
        f.handed, f.retried = sig, f.retry if f.retry == sig else f.retried
        f.retry = None
        return False, True

    def _holds(self, f: _File, now: float) -> bool:
        """Whether a file that changed keeps the watch busy (see the module docstring)."""
        looked_at = f.signature[0] > 0 or f.handed is not None
        return not f.quiet and looked_at and now - f.began < self.hold_s

    def _gone(self, listed: set[Path]) -> tuple[Path, ...]:
        """Handed-out files missing :data:`MISSING_LOOKS` looks in a row (others are
        forgotten at once)."""
        gone = []
        for path in [p for p in self.files if p not in listed]:
            f = self.files[path]
            f.missing += 1
            if f.handed is None or f.missing >= MISSING_LOOKS:
                del self.files[path]
                gone += [path] if f.handed is not None else []
        return tuple(sorted(gone, key=lambda p: natural_key(p.name)))


def _real(path: Path) -> Path:
    try:
        return path.resolve()
    except OSError:
        return path.absolute()
