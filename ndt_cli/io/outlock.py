"""One run at a time per output folder: a lock beside the folder, held for the whole run.

Two runs writing one output folder at once would each publish in turn, the later one silently
replacing the other's result. A run that writes a folder (``ndt-chain``, ``ndt-watch``) holds
an exclusive lock (``flock``) on ``.<name>.lock`` beside it from its first check to its last
publish; a second run into the same folder is refused at once (exit 2, one line naming the
process that holds it). The lock sits beside the folder, not in it, because publishing
replaces the folder as a whole. The kernel releases the lock of a process that dies, however
it dies (a lock file left by a killed run is no obstacle: the next run takes it), and a run
that ends removes its lock file. A run killed with its worker processes (``kill`` of the
process group) has the lock released only when the last of them is gone: while the process
the lock names is gone, the next run waits for it, up to :data:`SETTLE_S`.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Iterator
from pathlib import Path

from ndt_cli.errors import OutputError

SETTLE_S = 10.0  # s: how long a lock whose run is gone may still be held by its last processes


def lock_path(out: Path) -> Path:
    """The lock file of the output folder ``out``."""
    real = out.resolve()
    return real.parent / f".{real.name}.lock"


@contextlib.contextmanager
def output_lock(out: Path, command: str) -> Iterator[None]:
    """Hold the lock of the output folder ``out`` while the block runs (``command``: who
    holds it, for the message of a run refused).

    Raises :class:`OutputError` when another process holds it, or when it cannot be made."""
    path = lock_path(out)
    fd = _acquire(path, out, command)
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            path.unlink()  # while holding it: a run waiting on this file sees it is gone
        os.close(fd)


def _acquire(path: Path, out: Path, command: str) -> int:
    """An open descriptor of ``path`` holding its exclusive lock, the file still linked."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            flags = os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW  # never another file
            fd = os.open(path, flags, 0o644)
            if not _lock(fd):
                holder = _holder(fd)
                os.close(fd)
                raise OutputError(
                    f"another run is writing this folder ({holder}): wait for it to end or "
                    "choose another --out",
                    out,
                ) from None
            if _still_linked(fd, path):
                break
            os.close(fd)  # the run before removed it as we opened it: take the new one
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {command}\n".encode())
    except OSError as exc:
        if path.is_symlink() or path.is_dir():
            raise OutputError(
                f"{path.name} beside it is a link or a folder, not the lock ndt-cli keeps "
                "there: remove it",
                out,
            ) from None
        raise OutputError(f"cannot lock the folder ({exc.strerror or exc})", out) from None
    return fd


def _lock(fd: int) -> bool:
    """Take the exclusive lock of ``fd``; while the process its file names is gone (its last
    worker processes still exiting), wait for them, up to :data:`SETTLE_S`. Whether it was
    taken."""
    deadline = time.monotonic() + SETTLE_S
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if _alive(fd) or time.monotonic() > deadline:
                return False
            time.sleep(0.05)


def _alive(fd: int) -> bool:
    """Whether the process the lock file names exists (True when it names none)."""
    try:
        pid = int(os.pread(fd, 200, 0).split()[0])
        os.kill(pid, 0)
    except (ValueError, IndexError, OSError) as exc:
        return not isinstance(exc, ProcessLookupError)
    return True


def _still_linked(fd: int, path: Path) -> bool:
    try:
        st = path.stat()
    except FileNotFoundError:
        return False
    mine = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (mine.st_dev, mine.st_ino)


def _holder(fd: int) -> str:
    """Who holds the lock, as its file says: 'process PID, COMMAND'."""
    try:
        text = os.pread(fd, 200, 0).decode(errors="replace").split()
    except OSError:
        text = []
    if not text:
        return "a process of this machine"
    return f"process {text[0]}, {' '.join(text[1:]) or 'ndt-cli'}"
