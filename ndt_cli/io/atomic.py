"""Atomic file writing: write to a temporary file in the same folder, then rename.

A reader never sees a half-written file and a failed run leaves older results untouched. The
temporary file is ``.<name>.<pid>-<random>.tmp<suffix>``: one that a killed process left
(its process is gone) is removed by the next write of the same file.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from ndt_cli.errors import OutputError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _prefix(target: Path) -> str:
    """Start of the temporary files of ``target`` (its name cut short: a legal long name must
    not make an illegal temporary one)."""
    return f".{target.name[:100]}."


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (on this machine)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def clean_stale(target: Path) -> None:
    """Remove the temporary files of ``target`` left by processes that are gone."""
    pattern = re.compile(rf"^{re.escape(_prefix(target))}(\d+)-[^/]*\.tmp")
    with contextlib.suppress(OSError):
        for entry in target.parent.iterdir():
            m = pattern.match(entry.name)
            if m and int(m[1]) != os.getpid() and not pid_alive(int(m[1])):
                entry.unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds."""
    target = Path(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(target)
        fd, tmp_name = tempfile.mkstemp(
            prefix=f"{_prefix(target)}{os.getpid()}-",
            suffix=".tmp" + target.suffix,
            dir=target.parent,
        )
        os.close(fd)
        os.chmod(tmp_name, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual file mode
    except OSError as exc:
        raise OutputError(f"cannot write here ({exc.strerror or exc})", target) from exc
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.replace(tmp, target)
    except OSError as exc:
        raise OutputError(f"cannot write ({exc.strerror or exc})", target) from exc
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", **kwargs: object) -> Iterator[IO]:
    """Open a temporary file for writing; it replaces ``path`` only when the block succeeds."""
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as fh:  # type: ignore[call-overload]
        yield fh
        fh.flush()
        os.fsync(fh.fileno())


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)
