"""Files of a folder that a writer has finished: closed after writing, or moved in whole (Linux
inotify, through the C library; no dependency).

Field mode waits until a file has not changed for the settle time before it reads it, since a
copy in progress looks like a file. A file the kernel reports closed after writing
(``IN_CLOSE_WRITE``: ``cp``, a scanner's export, a card reader's copy) or renamed into the
folder (``IN_MOVED_TO``: ``rsync``, a copy to a temporary name), and not written to since
(``IN_MODIFY``), is complete as it stands: it is read at once, half a second sooner. A writer
that closes a file between pieces of it still has its file read early and then again when it
changes, as a writer that pauses does. Where inotify is missing (another system, a full watch
table) or does not see the writes (a network share written by another machine), nothing is
reported and the settle time decides.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import struct
import sys
from pathlib import Path

IN_MODIFY = 0x0000_0002
IN_CLOSE_WRITE = 0x0000_0008
IN_MOVED_TO = 0x0000_0080
IN_Q_OVERFLOW = 0x0000_4000
_NONBLOCK_CLOEXEC = os.O_NONBLOCK | os.O_CLOEXEC  # inotify_init1 takes the open(2) flags
_EVENT = struct.Struct("iIII")  # wd, mask, cookie, length of the name that follows


def _libc() -> ctypes.CDLL | None:
    if sys.platform != "linux":
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    except OSError:
        return None


class ClosedFiles:
    """Names of the files of ``folder`` finished since the last :meth:`names` (see the module
    text); an empty set every time where inotify is not available."""

    def __init__(self, folder: Path) -> None:
        self.fd = -1
        libc = _libc()
        if libc is None:
            return
        fd = libc.inotify_init1(_NONBLOCK_CLOEXEC)
        if fd < 0:
            return
        mask = IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO
        if libc.inotify_add_watch(fd, os.fsencode(folder), mask) < 0:
            os.close(fd)
            return
        self.fd = fd

    @property
    def active(self) -> bool:
        return self.fd >= 0

    def names(self) -> set[str]:
        """The names whose last event since the last call finished them: closed after
        writing or renamed in, and not written again since (the kernel merges a file's
        writes in a row into one event). None after the kernel's queue overflowed: those
        files settle by time."""
        last: dict[str, bool] = {}
        while self.fd >= 0:
            try:
                data = os.read(self.fd, 64 * 1024)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self.close()
                break
            if _parse(data, last):
                last.clear()
                break
        return {name for name, done in last.items() if done}

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def __del__(self) -> None:
        self.close()


def _parse(data: bytes, last: dict[str, bool]) -> bool:
    """Note in ``last`` whether each name's latest event in a buffer of inotify events
    finished it (True) or wrote to it (False); whether the kernel's queue overflowed."""
    at = 0
    while at + _EVENT.size <= len(data):
        _, mask, _, length = _EVENT.unpack_from(data, at)
        raw = data[at + _EVENT.size : at + _EVENT.size + length]
        at += _EVENT.size + length
        if mask & IN_Q_OVERFLOW:
            return True
        name = os.fsdecode(raw.rstrip(b"\0"))
        if name and mask & (IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO):
            last.pop(name, None)  # keeps the order of the latest events
            last[name] = not mask & IN_MODIFY
    return False
