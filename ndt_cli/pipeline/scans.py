"""The scans of a campaign: their order, their identity (file hash) and the names of their files.

Scans are taken in natural order of their file names (``scan_2`` before ``scan_10``; ties broken
by the folder). A scan is named by its file name in every output, or, where two scans share a
file name, by as much of its path as tells them apart; the scans of a multi-scan E57 file are
``FILE.e57#K``. The files written per scan and per link are named in :mod:`ndt_cli.io.names`.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ndt_cli.errors import InputError

_HASH_CHUNK = 1 << 20
log = logging.getLogger(__name__)


class DuplicateScanError(InputError):
    """A scan whose content an earlier scan of the campaign has (a copy under another name):
    ``original`` is that scan's file."""

    def __init__(self, original: str | Path, copy: str | Path) -> None:
        same = Path(original).resolve() == Path(copy).resolve()
        what = "given twice" if same else f"the same content as {original} (a copy?)"
        super().__init__(f"{what}: give every scan once", copy)
        self.original = Path(original)


def natural_key(path: str | Path) -> list[Any]:
    """Sort key: digit runs compare as numbers, so scan_2 comes before scan_10."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", str(path))]


def natural_sort(paths: Sequence[str | Path]) -> list[Path]:
    """Paths in natural order of their file names, then folders (see :func:`natural_key`)."""
    return [
        Path(p) for p in sorted(paths, key=lambda p: (natural_key(Path(p).name), natural_key(p)))
    ]


_known: dict[tuple[Path, int | None], tuple[tuple[int, ...], str]] = {}  # hashes, by file


UNREADABLE = "unreadable "  # the identity of a file that cannot be hashed starts so


def identity(path: Path) -> str:
    """A scan's key in links: its file's SHA-256; a file that cannot be read, its path."""
    return file_hash(path) or f"{UNREADABLE}{path}"


def file_hash(path: Path, *, reuse: bool = True) -> str | None:
    """SHA-256 of a scan's file bytes (and its scan number in an E57); None if unreadable.

    With ``reuse``, a file hashed before whose size, times and inode have not changed since
    is not read again (a campaign's inputs are hashed when they are checked and when they
    are admitted); without it the file is always read (to tell whether it changed)."""
    from ndt_cli.io.multiscan import split_spec

    file, index = split_spec(path)
    try:
        st = file.stat()
    except OSError:
        return None
    stamp = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    key = (file.resolve(), index)
    known = _known.get(key)
    if reuse and known is not None and known[0] == stamp:
        return known[1]
    h = hashlib.sha256(b"" if index is None else f"#{index}".encode())
    try:
        with open(file, "rb") as fh:
            while chunk := fh.read(_HASH_CHUNK):
                h.update(chunk)
    except OSError:
        return None
    _known[key] = (stamp, h.hexdigest())
    return h.hexdigest()


def hash_ahead(paths: Sequence[Path]) -> threading.Thread:
    """Hash ``paths`` (:func:`file_hash`) in a helper thread, beside the work that reads them:
    SHA-256 releases the GIL, and a 17 M-point LAS pair (1 GB) takes about 0.65 s to hash.
    Join the thread before the hashes are needed; :func:`file_hash` then finds them (and
    hashes a file itself whose hash the thread could not make)."""

    def hash_all() -> None:
        for p in paths:
            try:
                file_hash(Path(p))
            except Exception:  # the caller's own call reports it
                continue

    thread = threading.Thread(target=hash_all, name="hash-ahead", daemon=True)
    thread.start()
    return thread


def scan_names(paths: Sequence[Path]) -> list[str]:
    """One name per scan, unique: the file name, or the shortest tail of the path that no
    other scan shares (``north/scan_1.laz`` and ``south/scan_1.laz``)."""
    names = [os.path.basename(p) for p in paths]  # called per link: linear, and cheap
    if len(set(names)) == len(names):
        return names
    parts = [Path(p).parts for p in paths]
    depth = 1
    while len(set(names)) < len(names):
        depth += 1
        clash = {n for n in names if names.count(n) > 1}
        names = [
            "/".join(parts[k][-depth:]) if names[k] in clash else names[k]
            for k in range(len(names))
        ]
        if depth > max(len(p) for p in parts):
            names = [str(p) for p in paths]
            break
    return names


def readable_anchor(anchor: int, unreadable: dict[int, str], names: Sequence[str]) -> int:
    """The scan whose frame is the world: ``anchor``, or, when that one could not be read,
    the first scan that could (an aborted copy never defines the world)."""
    if anchor not in unreadable:
        return anchor
    readable = [i for i in range(len(names)) if i not in unreadable]
    if not readable:
        return anchor
    log.warning(
        "the anchor %s could not be read (%s): the world is the frame of %s",
        names[anchor],
        unreadable[anchor],
        names[readable[0]],
    )
    return readable[0]
