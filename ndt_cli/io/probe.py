"""A first look at a file that appeared where scans land: a whole scan, a scan still being
written (or cut short), a scan that cannot be read, or no scan at all.

Only the first bytes, the header and the file's size are read (milliseconds), never the points:
a LAS file must hold the bytes of every point its header announces, a LAZ file its chunk table,
an E57 file the length its header gives, a PTX file every point line of its scans. A file that
starts as its format starts but is shorter than that is *incomplete* (a copy in progress, or one
cut short); one that does not start so is *not a scan* (a ``poses.txt`` or ``control.csv`` on
the card, a file of another program). Formats without such a length (PLY, PCD, text) are whole
once their header (text: a first row of x y z numbers) is there; reading them tells the rest.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from ndt_cli.errors import InputError, one_line

HEAD_BYTES = 65_536  # bytes read for a first look at a header


class FileKind(StrEnum):
    """What a first look makes of a file."""

    SCAN = "scan"  # whole, as far as its header and size tell
    INCOMPLETE = "incomplete"  # a point file's start, but not all it announces (yet)
    UNREADABLE = "unreadable"  # cannot be opened or read (permissions, a broken header)
    NOT_A_SCAN = "not_a_scan"  # does not start as a point file of its suffix


@dataclass(frozen=True)
class Probe:
    """A file's :class:`FileKind`, why (when not a scan), the points its header announces
    (every scan it holds; None when the format says nothing) and the scans it holds."""

    kind: FileKind
    reason: str = ""
    points: int | None = None
    scans: int = 1


def probe(path: Path) -> Probe:
    """The first look at ``path`` (see the module docstring)."""
    if not path.is_file():
        return Probe(FileKind.NOT_A_SCAN, "a folder or special file, not a point file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(HEAD_BYTES)
        if not head:
            return Probe(FileKind.INCOMPLETE, "the file is empty")
        look = _LOOKS.get(path.suffix.lower(), _text)
        return look(path, head)
    except OSError as exc:
        return Probe(FileKind.UNREADABLE, exc.strerror or one_line(exc))
    except InputError as exc:
        return Probe(FileKind.UNREADABLE, exc.message)


def _starts(head: bytes, magic: bytes, name: str) -> Probe | None:
    """None when ``head`` starts with ``magic``; else the probe that says what it is."""
    if head.startswith(magic):
        return None
    if magic.startswith(head):
        return Probe(FileKind.INCOMPLETE, f"only {len(head)} bytes so far")
    return Probe(FileKind.NOT_A_SCAN, f"not a {name} file (it does not start with {magic!r})")


def _las(path: Path, head: bytes) -> Probe:
    """LAS/LAZ: the header, then the bytes of every point (LAS) or the chunk table (LAZ)."""
    import laspy

    if (found := _starts(head, b"LASF", "LAS")) is not None:
        return found
    try:
        with laspy.open(path) as reader:
            header = reader.header
    except OSError:
        raise
    except Exception:  # laspy's errors on a header cut short
        return Probe(FileKind.INCOMPLETE, f"the header is not whole ({len(head)} bytes so far)")
    n, size = int(header.point_count), path.stat().st_size
    if n == 0:
        return Probe(FileKind.INCOMPLETE, "its header announces no points (yet)")
    start = header.offset_to_point_data
    if not header.are_points_compressed:
        needed = start + n * header.point_format.size
        if size < needed:
            return Probe(FileKind.INCOMPLETE, _short(n, needed, size))
        return Probe(FileKind.SCAN, points=n)
    with open(path, "rb") as fh:
        fh.seek(start)
        raw = fh.read(8)
    table = struct.unpack("<q", raw)[0] if len(raw) == 8 else size
    if table != -1 and table + 8 > size:  # -1: a streamed file keeps it at its end
        return Probe(FileKind.INCOMPLETE, f"{n} points announced, the LAZ data ends early")
    return Probe(FileKind.SCAN, points=n)


def _short(n: int, needed: int, size: int) -> str:
    return f"its header announces {n} points ({needed} bytes), the file has {size} bytes"


def _e57(path: Path, head: bytes) -> Probe:
    """E57: the length in its header, then the scans libE57 finds."""
    from ndt_cli.io import e57

    if (found := _starts(head, b"ASTM-E57", "E57")) is not None:
        return found
    if len(head) < 24:
        return Probe(FileKind.INCOMPLETE, f"only {len(head)} bytes so far")
    length, size = struct.unpack("<Q", head[16:24])[0], path.stat().st_size
    if size < length:
        return Probe(FileKind.INCOMPLETE, _short_file(length, size))
    count = e57.scan_count(path)
    points = sum(e57.record_count(f"{path}#{k}") for k in range(count))
    if count == 0:
        return Probe(FileKind.UNREADABLE, "the E57 file holds no scan")
    return Probe(FileKind.SCAN, points=points, scans=count)


def _short_file(length: int, size: int) -> str:
    return f"its header announces {length} bytes, the file has {size}"


def _ply(path: Path, head: bytes) -> Probe:
    """PLY: a whole header (``end_header``); its vertex count."""
    if (found := _starts(head, b"ply", "PLY")) is not None:
        return found
    text = head.split(b"end_header", 1)
    if len(text) == 1:
        return Probe(FileKind.INCOMPLETE, "header not whole (no end_header yet)")
    return Probe(FileKind.SCAN, points=_announced(text[0], b"element vertex"))


def _pcd(path: Path, head: bytes) -> Probe:
    """PCD: a header with FIELDS and DATA; its POINTS count."""
    words = {line.split(maxsplit=1)[0].upper() for line in head.splitlines() if line.split()}
    if b"FIELDS" in words and b"DATA" in words:
        return Probe(FileKind.SCAN, points=_announced(head, b"POINTS"))
    if len(head) < 256 and all(w.isalpha() or w.startswith(b"#") for w in words):
        return Probe(FileKind.INCOMPLETE, "header not whole (no FIELDS and DATA yet)")
    return Probe(FileKind.NOT_A_SCAN, "not a PCD file (no FIELDS and DATA header)")


def _announced(header: bytes, key: bytes) -> int | None:
    """The count after ``key`` in a text header (``element vertex 1200``), or None."""
    for line in header.splitlines():
        if line.strip().startswith(key):
            tail = line.strip()[len(key) :].split()
            return int(tail[0]) if tail and tail[0].isdigit() else None
    return None


def _ptx(path: Path, head: bytes) -> Probe:
    """PTX: every scan's header and all its point lines."""
    from ndt_cli.io import ptx

    try:
        scans = ptx.scans(path)
    except InputError as exc:
        cut = "ends before" in exc.message or "cut short" in exc.message
        bad = FileKind.UNREADABLE if exc.message.startswith("cannot read") else FileKind.NOT_A_SCAN
        return Probe(FileKind.INCOMPLETE if cut else bad, exc.message)
    return Probe(FileKind.SCAN, points=sum(s.count for s in scans), scans=len(scans))


def _text(path: Path, head: bytes) -> Probe:
    """xyz/txt/csv/3d: a row of x y z numbers among the first lines (a header above it)."""
    from ndt_cli.io.text import TextReader

    try:
        TextReader().check(path)
    except InputError as exc:
        return Probe(FileKind.NOT_A_SCAN, exc.message)
    return Probe(FileKind.SCAN)


_LOOKS = {".las": _las, ".laz": _las, ".e57": _e57, ".ply": _ply, ".pcd": _pcd, ".ptx": _ptx}
