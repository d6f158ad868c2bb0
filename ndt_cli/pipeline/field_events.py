"""What field mode tells as it goes: one event per thing that happened.

A scan *landed* (read whole as far as its header tells), was *placed* or *fits nowhere*; an
earlier scan's verdict was *revised* by the scans that came after it; a file cannot be read
yet (*unreadable*: incomplete, or unreadable), is no scan (*skipped*), was *replaced* in place
or *removed*; the watched *folder* went or came back; the watch *started* and *stopped*. Each
event is a frozen dataclass; :func:`event_dict` is its ``ndt-watch --json`` line, whose fields
``docs/deliverables.md`` documents. Positions are world coordinates (m), times local ISO 8601.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from datetime import datetime
from enum import StrEnum
from typing import Any

from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.verify import EdgeState, NodeStatus


class EventKind(StrEnum):
    """The events of field mode, as ``--json`` names them."""

    STARTED = "started"
    LANDED = "landed"
    PLACED = "placed"
    FITS_NOWHERE = "fits_nowhere"
    REVISED = "revised"
    UNREADABLE = "unreadable"
    SKIPPED = "skipped"
    REPLACED = "replaced"
    REMOVED = "removed"
    FOLDER = "folder"
    STOPPED = "stopped"


def now_iso() -> str:
    """The local time now, ISO 8601 with its UTC offset, to the millisecond."""
    return datetime.now().astimezone().isoformat(timespec="milliseconds")


@dataclass(frozen=True)
class LinkNote:
    """One link of a scan: the other scan, what the network made of it (``checked``: on a
    cycle of kept links that agree), the registration's status and overlap (share of the
    source's slice points in target cells, 0..1), the residual (cm, checked links only) and
    why it is not kept (when it is not)."""

    scan: str
    state: EdgeState
    status: Status
    overlap: float | None
    residual_cm: float | None
    reason: str = ""

    @property
    def checked(self) -> bool:
        return self.state is EdgeState.CONFIRMED


@dataclass(frozen=True)
class Verdict:
    """What the network made of one scan: its status, cluster (0: the anchor's), position
    (world, m; None when unposed), links, why it is not ok, and whether it is the anchor."""

    scan: str
    status: NodeStatus
    cluster: int | None
    position: tuple[float, float, float] | None
    links: tuple[LinkNote, ...]
    reason: str
    anchor: bool = False

    @property
    def fits_nowhere(self) -> bool:
        """Read whole, and no link kept it anywhere."""
        kept = (EdgeState.CONFIRMED, EdgeState.USED)
        return self.status is NodeStatus.UNPOSED and not any(k.state in kept for k in self.links)

    @property
    def label(self) -> str:
        """The verdict in a word or three: ok, ok apart (another cluster), suspect, unposed,
        fits nowhere."""
        if self.fits_nowhere:
            return "fits nowhere"
        if self.status is NodeStatus.OK and self.cluster:
            return f"ok in cluster {self.cluster}"
        return self.status.value


@dataclass(frozen=True)
class Tally:
    """The campaign so far: scans, ok in the anchor's cluster, ok in another cluster,
    suspect, unposed, and files waiting to be read whole."""

    scans: int = 0
    ok: int = 0
    apart: int = 0
    suspect: int = 0
    unposed: int = 0
    waiting: int = 0


@dataclass(frozen=True)
class Started:
    """The watch began: the folder watched, the output folder, config, jobs, settle and idle
    times (s), the control file and its CRS."""

    folder: str
    out: str
    config: str
    jobs: int
    settle_s: float
    exit_when_idle_s: float | None
    control: str | None
    crs: str | None
    kind: EventKind = EventKind.STARTED
    time: str = field(default_factory=now_iso)


@dataclass(frozen=True)
class Landed:
    """A file landed whole: its name, the scans it brings (one, or ``FILE.e57#K`` each) and
    the points its header announces (None when its format says nothing)."""

    file: str
    scans: tuple[str, ...]
    points: int | None
    kind: EventKind = EventKind.LANDED
    time: str = field(default_factory=now_iso)


@dataclass(frozen=True)
class Placed:
    """A scan registered into the campaign (``kind``: placed or fits_nowhere): its verdict,
    the seconds from the start of its registration to its outputs published and from its
    landing (as the watch saw it) to then, and the tally."""

    kind: EventKind
    verdict: Verdict
    took_s: float
    since_landed_s: float
    tally: Tally
    role: str = "it defines the world frame"  # the first scan's, to the world frame
    time: str = field(default_factory=now_iso)


@dataclass(frozen=True)
class Revised:
    """An earlier scan's verdict changed (``was``: its earlier label)."""

    verdict: Verdict
    was: str
    tally: Tally
    kind: EventKind = EventKind.REVISED
    time: str = field(default_factory=now_iso)


@dataclass(frozen=True)
class FileNote:
    """A file that is not (or no longer) a scan of the campaign (``kind``: unreadable,
    skipped, replaced, removed), what a first look found (``state``: incomplete, unreadable,
    not_a_scan, copy (of a scan registered); empty for replaced and removed), why, and the
    scans whose earlier registration was dropped."""

    kind: EventKind
    file: str
    state: str
    reason: str
    dropped: tuple[str, ...] = ()
    time: str = field(default_factory=now_iso)


@dataclass(frozen=True)
class FolderNote:
    """The watched folder could not be read (``present`` False: a card pulled out) or can
    again."""

    folder: str
    present: bool
    kind: EventKind = EventKind.FOLDER
    time: str = field(default_factory=now_iso)


@dataclass(frozen=True)
class Stopped:
    """The watch ended (``why``: idle, interrupted, terminated), its exit code, the output
    folder, the tally, the scans that are not ok (name, verdict), the files still waiting
    to be read whole (name, why) and, when control was given, what it made of the world
    (the world frame, each station not used and why)."""

    why: str
    exit_code: int
    out: str
    tally: Tally
    not_ok: tuple[tuple[str, str], ...] = ()
    waiting: tuple[tuple[str, str], ...] = ()
    world: tuple[str, ...] = ()
    kind: EventKind = EventKind.STOPPED
    time: str = field(default_factory=now_iso)


Event = Started | Landed | Placed | Revised | FileNote | FolderNote | Stopped


def event_dict(event: Event) -> dict[str, Any]:
    """The ``--json`` object of an event: ``event`` (its kind), ``time``, then its fields
    (a verdict's fields inline; a link's ``checked`` added; NaN as null)."""
    out: dict[str, Any] = {"event": event.kind.value, "time": event.time}
    for f in fields(event):
        if f.name in ("kind", "time"):
            continue
        value = getattr(event, f.name)
        if isinstance(value, Verdict):
            out.update(_plain(value))
        elif f.name == "waiting":
            out["waiting"] = [{"file": name, "reason": why} for name, why in value]
        elif f.name == "not_ok":
            out["not_ok"] = [{"scan": name, "verdict": label} for name, label in value]
        else:
            out[f.name] = _plain(value)
    return out


def _plain(value: Any) -> Any:
    """Dataclasses, tuples and floats as JSON takes them."""
    if isinstance(value, LinkNote):
        return {
            **{f.name: _plain(getattr(value, f.name)) for f in fields(value)},
            "checked": value.checked,
        }
    if hasattr(value, "__dataclass_fields__"):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def verdicts(result: ChainResult, stations: bool = False) -> dict[str, Verdict]:
    """Every scan's :class:`Verdict` in ``result``, by name. ``stations``: control gives the
    world, so the anchor does not; the first scan is still marked, its role said apart."""
    notes: dict[int, list[LinkNote]] = {k: [] for k in range(len(result.scans))}
    for link, fit in zip(result.links, result.solution.links, strict=True):
        res = fit.residual if fit.state is EdgeState.CONFIRMED else None
        overlap = None if link.result is None else float(link.result.overlap)
        why = fit.reason if fit.state in (EdgeState.REJECTED, EdgeState.UNUSED) else ""
        why = link.reason if not link.ok and not why else why
        for me, other in ((link.target, link.source), (link.source, link.target)):
            cm = None if res is None else 100 * res.translation_m
            notes[me].append(
                LinkNote(result.names[other], fit.state, link.status, overlap, cm, why)
            )
    out = {}
    for k, scan in enumerate(result.solution.scans):
        T = scan.T_world_scan
        where = None if T is None else tuple(float(v) for v in T[:3, 3])
        anchor = k == result.anchor
        name = result.names[k]
        out[name] = Verdict(
            name, scan.status, scan.cluster, where, tuple(notes[k]), scan.reason, anchor
        )
    return out


def tally(found: dict[str, Verdict], waiting: int) -> Tally:
    """The counts of :class:`Tally` over the verdicts."""
    vs = list(found.values())
    ok = sum(v.status is NodeStatus.OK and v.cluster == 0 for v in vs)
    apart = sum(v.status is NodeStatus.OK and v.cluster != 0 for v in vs)
    suspect = sum(v.status is NodeStatus.SUSPECT for v in vs)
    return Tally(len(vs), ok, apart, suspect, len(vs) - ok - apart - suspect, waiting)
