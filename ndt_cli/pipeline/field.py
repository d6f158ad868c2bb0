"""Field mode's campaign: the scans of a watched folder registered as they land, dropped when
their file goes, registered anew when it is replaced; what happened told as events
(:mod:`ndt_cli.pipeline.field_events`).

Each file that settled (:mod:`ndt_cli.pipeline.watch`) gets a first look
(:func:`ndt_cli.io.probe.probe`):

- a whole scan is registered. A scan's file that settles again with the same content (a
  ``touch``, a permission) changes nothing; new content under the same name drops the old
  registration and is registered anew, in its place in the campaign order;
- an incomplete or unreadable file gets one line and is looked at again whenever it changes
  (and once more after the settle time); a scan it was is dropped, so that no output ever
  gives the old content's pose to the new file;
- a file that is no scan gets one line and is left alone;
- a scan whose points cannot be read although its header could is dropped and waits as an
  unreadable file; a scan's file that is gone is dropped.

Dropping a scan builds the campaign again from its store of finished links (every link and scan
summary is reused: a fraction of a second for a street). The outputs are published only while
every registered file is in the state it was registered in; otherwise the next look sees the
change and the campaign follows it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from ndt_cli.errors import EXIT_INTERRUPTED, EXIT_OK, EXIT_REGISTRATION
from ndt_cli.io.probe import FileKind, Probe, probe
from ndt_cli.pipeline.campaign import Campaign
from ndt_cli.pipeline.field_events import (
    Event,
    EventKind,
    FileNote,
    FolderNote,
    Landed,
    Placed,
    Revised,
    Stopped,
    Tally,
    Verdict,
    tally,
    verdicts,
)
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.scans import DuplicateScanError, file_hash
from ndt_cli.pipeline.watch import FolderWatch, Settled, Signature, signature


@dataclass(eq=False)
class _Entry:
    """A file registered: its scans (one, or ``FILE.e57#K`` each), the state it was
    registered in, and when it landed (monotonic s)."""

    file: Path
    specs: tuple[Path, ...]
    signature: Signature
    seen: float


@dataclass(frozen=True)
class Publisher:
    """What the command does with a result: ``named`` gives its reasons the scans' names,
    ``write`` publishes its outputs."""

    named: Callable[[ChainResult], ChainResult]
    write: Callable[[ChainResult], None]
    role: Callable[[ChainResult], str] = lambda result: "it defines the world frame"


class FieldCampaign:
    """The campaign of the scans landing in a watched folder (see the module docstring).
    ``make(first)`` builds an empty campaign that resumes from the output folder's store, its
    settings for the scene that the scan ``first`` sees (None: before any scan)."""

    def __init__(
        self,
        make: Callable[[Path | None], Campaign],
        watch: FolderWatch,
        publisher: Publisher,
        stations: bool = False,
    ) -> None:
        self.make, self.watch, self.publisher, self.stations = make, watch, publisher, stations
        self.campaign = make(None)
        self.entries: list[_Entry] = []
        self.waiting: dict[Path, str] = {}  # files to be read whole: why not yet
        self.told: dict[Path, str] = {}  # the last line told of a file that is not a scan
        self.said: dict[str, str] = {}  # the last verdict told of each scan (its label)
        self.result: ChainResult | None = None
        self.present, self.busy = True, False
        self.now: float | None = None  # the time of the look (None: now)
        self.landing: list[_Entry] = []  # landed, not registered yet
        self.unpublished = False  # the last result waits for its files to be as registered

    # ------------------------------------------------------------------ the entry points

    def step(self, now: float | None = None) -> Iterator[Event]:
        """One look at the folder and all that follows from it, as events (landing lines
        first, then each registration's)."""
        look = self.watch.look(now)
        self.now, self.busy = now, look.busy
        if look.present != self.present:
            self.present = look.present
            yield FolderNote(str(self.watch.folder), look.present)
        drop: set[Path] = set()
        renew: list[_Entry] = []
        fresh: list[_Entry] = []
        for path in look.gone:
            yield from self._gone(path, drop)
        for seen in look.settled:
            yield from self._settled(seen, drop, renew, fresh)
        self.landing = [*renew, *fresh]
        if drop or renew:
            yield from self._follow(drop, renew)
        for entry in fresh:
            yield from self._register(entry)
        if self.unpublished and not (drop or renew or fresh):
            yield from self._publish({}, time.perf_counter())

    def _follow(self, drop: set[Path], renew: list[_Entry]) -> Iterator[Event]:
        """The campaign without the files dropped, with the new content of those renewed."""
        t0 = time.perf_counter()
        self.entries = [e for e in self.entries if e.file not in drop]
        yield from self._rebuild()
        yield from self._publish({e.file: e for e in renew if e in self.entries}, t0)
        self.landing = [e for e in self.landing if e not in renew]

    def _register(self, entry: _Entry) -> Iterator[Event]:
        """A file that landed, registered into the campaign."""
        t0 = time.perf_counter()
        if not self.entries:  # the first scan: the settings for its scene
            self.campaign = self.make(entry.specs[0])
        self.entries.append(entry)
        try:
            self.campaign.add_scans(list(entry.specs))
        except DuplicateScanError as exc:  # registered once: the copy is left alone
            yield from self._copy(entry, exc.original)
            return
        yield from self._unreadable()
        yield from self._publish({entry.file: entry} if entry in self.entries else {}, t0)
        self.landing.remove(entry)

    def _copy(self, entry: _Entry, original: Path) -> Iterator[Event]:
        """A file holding a scan already registered: said once, left alone."""
        self.entries.remove(entry)
        self.landing.remove(entry)
        self.watch.leave_alone(entry.file)
        same = f"the same content as {original.name}"
        yield FileNote(EventKind.SKIPPED, entry.file.name, "copy", same)

    def tally(self) -> Tally:
        """The campaign so far (:class:`~ndt_cli.pipeline.field_events.Tally`)."""
        found = {} if self.result is None else verdicts(self.result, self.stations)
        return tally(found, len(self.waiting))

    def stopped(self, why: str, out: Path) -> Stopped:
        """The closing event (``why``: idle, interrupted, terminated): the tally, the scans
        not ok, the files still waited for (those being written too, unless a first look finds
        them no scan), and the exit code: 130 when stopped, 0 when idle with every scan ok in
        the anchor's cluster and no file waited for, else 1."""
        found = {} if self.result is None else verdicts(self.result, self.stations)
        not_ok = tuple((n, v.label) for n, v in found.items() if v.label != "ok")
        writing = {
            p: "not landed yet (changed within the settle time)"
            for p in self.watch.writing()
            if p not in self.waiting and probe(p).kind is not FileKind.NOT_A_SCAN
        }
        landed = {e.file: "landed, not registered yet" for e in self.landing}
        waiting = {**self.waiting, **writing, **landed}
        listed = tuple((p.name, w) for p, w in sorted(waiting.items()))
        ok = self.result is not None and self.result.ok and not waiting
        code = EXIT_INTERRUPTED if why != "idle" else EXIT_OK if ok else EXIT_REGISTRATION
        return Stopped(why, code, str(out), self.tally(), not_ok, listed)

    # ------------------------------------------------------------------ what a look found

    def _gone(self, path: Path, drop: set[Path]) -> Iterator[Event]:
        self.waiting.pop(path, None)
        self.told.pop(path, None)
        entry = self._entry(path)
        if entry is not None:
            drop.add(path)
            yield FileNote(
                EventKind.REMOVED, path.name, "", "gone from the folder", self._names(entry)
            )

    def _settled(
        self, seen: Settled, drop: set[Path], renew: list[_Entry], fresh: list[_Entry]
    ) -> Iterator[Event]:
        """A file settled: register it, again or anew, or say why not."""
        look, path = probe(seen.path), seen.path
        entry = self._entry(path)
        if look.kind is not FileKind.SCAN:
            yield from self._not_a_scan(seen, look, entry, drop)
            return
        self.waiting.pop(path, None)
        self.told.pop(path, None)
        if entry is not None and self._same_content(entry):
            entry.signature = seen.signature  # touched, or its permissions changed
            return
        new = _Entry(path, _specs(path, look), seen.signature, seen.seen)
        if entry is not None:
            yield FileNote(EventKind.REPLACED, path.name, "", "new content", self._names(entry))
            self.entries[self.entries.index(entry)] = new
            renew.append(new)
        else:
            fresh.append(new)
        yield Landed(path.name, tuple(s.name for s in new.specs), look.points)

    def _not_a_scan(
        self, seen: Settled, look: Probe, entry: _Entry | None, drop: set[Path]
    ) -> Iterator[Event]:
        """A file that is no whole scan (now): left alone, or waited for; a scan it was is
        dropped. One line per file and reason."""
        path = seen.path
        if look.kind is FileKind.NOT_A_SCAN:
            self.watch.leave_alone(path)
            self.waiting.pop(path, None)
            kind = EventKind.SKIPPED
        else:
            self.watch.again(path, self.now)
            self.waiting[path] = f"{look.kind.value}: {look.reason}"
            kind = EventKind.UNREADABLE
        dropped = () if entry is None else self._names(entry)
        if entry is not None:
            drop.add(path)
        text = f"{look.kind.value}: {look.reason}"
        if self.told.get(path) != text or dropped:
            self.told[path] = text
            yield FileNote(kind, path.name, look.kind.value, look.reason, dropped)

    # ------------------------------------------------------------------ the campaign

    def _rebuild(self) -> Iterator[Event]:
        """The campaign built again over the entries left (links and summaries reused)."""
        specs = [s for e in self.entries for s in e.specs]
        self.campaign = self.make(specs[0] if specs else None)
        if specs:
            self.campaign.add_scans(specs)
        yield from self._unreadable()

    def _unreadable(self) -> Iterator[Event]:
        """Scans whose points could not be read: dropped, their files waited for."""
        bad = {self._owner(i): why for i, why in sorted(self.campaign.unreadable.items())}
        if not bad:
            return
        for entry, failure in bad.items():
            why = str(failure).removeprefix(f"{entry.file}: ")
            self.watch.again(entry.file, self.now)
            self.waiting[entry.file] = f"{FileKind.UNREADABLE.value}: {why}"
            self.told[entry.file] = self.waiting[entry.file]
            unreadable = FileKind.UNREADABLE.value
            yield FileNote(
                EventKind.UNREADABLE, entry.file.name, unreadable, why, self._names(entry)
            )
        self.entries = [e for e in self.entries if e not in bad]
        yield from self._rebuild()

    def _publish(self, placed: dict[Path, _Entry], t0: float) -> Iterator[Event]:
        """Solve, publish (while every file is as registered), and tell the verdicts: of the
        scans just registered, and of earlier ones that changed."""
        if not self.entries:
            self.result = None
            return
        whole = all(signature(e.file) == e.signature for e in self.entries)
        self.unpublished = not whole
        if not (whole or placed):
            return  # nothing to tell, nothing to publish yet
        result = self.campaign.result()
        if whole:
            result = self.publisher.named(result)
            self.publisher.write(result)
        self.result = result
        found = verdicts(result, self.stations)
        now = time.monotonic()
        mine = {n: e for e in placed.values() for n in self._names(e)}
        took = time.perf_counter() - t0
        for name, entry in mine.items():
            since = now - entry.seen
            role = self.publisher.role(result)
            yield Placed(_kind(found[name]), found[name], took, since, self.tally(), role)
        for name, verdict in found.items():
            if name not in mine and self.said.get(name, verdict.label) != verdict.label:
                yield Revised(verdict, self.said[name], self.tally())
        self.said = {name: v.label for name, v in found.items()}

    # ------------------------------------------------------------------ helpers

    def _entry(self, path: Path) -> _Entry | None:
        return next((e for e in self.entries if e.file == path), None)

    def _owner(self, index: int) -> _Entry:
        """The entry of the campaign's scan ``index``."""
        for entry in self.entries:
            if index < len(entry.specs):
                return entry
            index -= len(entry.specs)
        raise IndexError(index)

    def _names(self, entry: _Entry) -> tuple[str, ...]:
        return tuple(s.name for s in entry.specs)

    def _same_content(self, entry: _Entry) -> bool:
        """Whether the entry's file still holds the content the campaign registered."""
        first = sum(len(e.specs) for e in self.entries[: self.entries.index(entry)])
        hashes = self.campaign.hashes
        return first < len(hashes) and file_hash(entry.specs[0]) == hashes[first]


def _specs(path: Path, look: Probe) -> tuple[Path, ...]:
    """The scans of a file: itself, or ``FILE#K`` for each scan of a file of many."""
    if look.scans > 1:
        return tuple(Path(f"{path}#{k}") for k in range(look.scans))
    return (path,)


def _kind(verdict: Verdict) -> EventKind:
    return EventKind.FITS_NOWHERE if verdict.fits_nowhere else EventKind.PLACED


__all__ = ["Event", "FieldCampaign", "Publisher"]
