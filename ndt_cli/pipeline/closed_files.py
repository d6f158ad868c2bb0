"""Files of a folder that a writer has finished: closed after writing, or moved in whole (Linux
inotify, through the C library; no dependency).

Field mode waits until a file has not changed for the settle time before it reads it, since a
copy in progress looks like a file. A file the kernel reports closed after writing
(``IN_CLOSE_WRITE``: ``cp``, a scanner's export, a card reader's copy) or renamed into the
folder (``IN_MOVED_TO``: ``rsync``, a copy to a temporary name), and not written to since
(``IN_MODIFY``), is complete as it stands: it is read at the watch's next look instead of
after the settle time (0.5 s by default). A writer
that closes a file between pieces of it still has its file read early and then again when it
changes, as a writer that pauses does. Where inotify is missing (another system, a full watch
table) or does not see the writes (a network share written by another machine), nothing is
reported and the settle time decides.
"""

from __future__ import annotations

import ctypes
import os
import struct
import sys
from pathlib import Path

IN_MODIFY = 0x0000_0002
IN_CLOSE_WRITE = 0x0000_0008
IN_MOVED_TO = 0x0000_0080
IN_DELETE_SELF = 0x0000_0400
IN_MOVE_SELF = 0x0000_0800
IN_Q_OVERFLOW = 0x0000_4000
IN_IGNORED = 0x0000_8000
_FILE_EVENTS = IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO
_FOLDER_GONE = IN_DELETE_SELF | IN_MOVE_SELF | IN_IGNORED | IN_Q_OVERFLOW  # events lost
_EVENT = struct.Struct("iIII")  # wd, mask, cookie, length of the name that follows
READ_BYTES = 64 * 1024  # a read takes at least one event of the longest name (4 kB)


def _libc() -> ctypes.CDLL | None:
    """The C library of this process (Linux only; None elsewhere)."""
    if sys.platform != "linux":
        return None
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


class ClosedFiles:
    """What the writers of the files of ``folder`` did since the last :meth:`events` (see the
    module text); nothing, every time, where inotify is not available."""

    def __init__(self, folder: Path) -> None:
        self.fd = -1
        libc = _libc()
        flags = getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
        try:
            fd = -1 if libc is None else libc.inotify_init1(flags)
            if fd >= 0 and libc.inotify_add_watch(fd, os.fsencode(folder), _FILE_EVENTS) < 0:
                os.close(fd)
                fd = -1
        except AttributeError:  # a C library without inotify
            fd = -1
        self.fd = fd

    @property
    def active(self) -> bool:
        """Whether the system reports the folder's events (else the settle time decides)."""
        return self.fd >= 0

    def events(self) -> dict[str, bool]:
        """Per name written to, closed after writing or renamed in since the last call, in
        the order of their latest events: whether that latest event finished the file (closed
        or renamed in: True) or wrote to it (False; the kernel merges a file's writes in a row
        into one event). Nothing once events were lost (the queue overflowed, the folder was
        removed or moved): the watch stops, and the files settle by time."""
        last: dict[str, bool] = {}
        while self.fd >= 0:
            try:
                data = os.read(self.fd, READ_BYTES)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                data = b""
            if not data or _parse(data, last):
                self.close()
                return {}
        return last

    def close(self) -> None:
        """Stop watching (idempotent)."""
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def __del__(self) -> None:
        self.close()


def _parse(data: bytes, last: dict[str, bool]) -> bool:
    """Note in ``last`` whether each name's latest event in a buffer of inotify events
    finished it (True) or wrote to it (False); whether events were lost (see
    :meth:`ClosedFiles.events`)."""
    at = 0
    while at + _EVENT.size <= len(data):
        _, mask, _, length = _EVENT.unpack_from(data, at)
        raw = data[at + _EVENT.size : at + _EVENT.size + length]
        at += _EVENT.size + length
        if mask & _FOLDER_GONE:
            return True
        name = os.fsdecode(raw.rstrip(b"\0"))
        if name and mask & _FILE_EVENTS:
            last.pop(name, None)  # keeps the order of the latest events
            last[name] = not mask & IN_MODIFY
    return False
