"""A run's output folder, replaced as a whole: all of a run's files appear together or not at all.

The files are written into a temporary folder beside the output folder, then the two folders
are swapped in one atomic step (``renameat2(RENAME_EXCHANGE)`` on Linux; where the file system
cannot exchange, two renames). Killed at any moment, a run leaves either the old folder or the
new one, never a mix; a temporary folder left behind by a killed run is removed by the next run
that writes the same output.

An output folder holds only what ndt-cli writes there: every file a run writes is listed in
the folder's manifest (``.ndt-cli-outputs``), and a folder with any other entry (at any depth)
is refused before any work starts, so that replacing it can never lose a user's file; so is an
output folder that is, holds or lies inside a file or folder the run reads. Folders of resume
state (``links/``) are carried over into the new folder.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import hashlib
import os
import re
import shutil
import uuid
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from ndt_cli.errors import InputError, OutputError
from ndt_cli.io.atomic import atomic_path, pid_alive

MANIFEST = ".ndt-cli-outputs"  # 'SHA-256  name' of every file a run wrote (sha256sum -c)
_DIGEST_LINE = re.compile(r"^([0-9a-f]{64})  (.+)$")
STATE = ("links",)  # folders a later run reuses (--resume): carried over, never dropped
# what ndt-cli versions without a manifest wrote into an output folder
KNOWN = re.compile(
    r"^(T_.+\.txt|poses/|links/|result\.json|report\.csv|report\.html|config_used\.yaml"
    r"|pairs\.csv|poses\.csv|poses\.txt|poses_chain\.txt|summary\.json|topview\.png"
    r"|e57_header_poses\.txt|eval\.csv|eval\.json"
    r"|(score_rotation|score_translation|basin|basin_success|optimizers)\.(csv|png))$"
)
MARKERS = (  # one of them marks an earlier result
    "result.json",
    "summary.json",
    "links/",
    "eval.json",
    "score_rotation.csv",
    "score_translation.csv",
    "basin.csv",
    "optimizers.csv",
)
Content = str | bytes | Callable[[Path], None]  # text, bytes, or a writer given the file's path


def _entries(folder: Path) -> list[str]:
    return sorted(e.name + ("/" if e.is_dir() else "") for e in folder.iterdir())


def output_digests(folder: Path) -> dict[str, str] | None:
    """Name (relative, ``/``-separated) -> SHA-256 of every file the manifest of ``folder``
    lists ('' in a manifest of an older ndt-cli, which lists names only), or None when the
    folder has no manifest (or it cannot be read)."""
    try:
        text = (folder / MANIFEST).read_text(encoding="utf-8", errors="surrogateescape")
    except (OSError, ValueError):
        return None
    out = {}
    for line in filter(None, text.splitlines()):
        m = _DIGEST_LINE.match(line)
        out[m[2] if m else line] = m[1] if m else ""
    return out


def listed_outputs(folder: Path) -> list[str] | None:
    """The names the manifest of ``folder`` lists, or None when it has no manifest."""
    digests = output_digests(folder)
    return None if digests is None else list(digests)


def sha256_of(path: Path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def check_unchanged(folder: Path, names: Iterable[str]) -> None:
    """Raise :class:`InputError` when one of the files ``names`` of a result folder is not
    what its run wrote: another SHA-256 than the manifest records, or not listed in it. A folder
    without a manifest (or a manifest without digests) is not checked."""
    digests = output_digests(folder)
    if digests is None:
        return
    for name in names:
        path = folder / name
        if not path.is_file():
            continue  # reported by the reader, naming what is missing
        if name not in digests:
            raise InputError(f"not listed in {MANIFEST}: not written by this result's run", path)
        try:
            same = not digests[name] or sha256_of(path) == digests[name]
        except OSError as exc:
            raise InputError(f"cannot read ({exc.strerror or exc})", path) from None
        if not same:
            raise InputError(
                f"changed since ndt-cli wrote it (its SHA-256 is not the one in {MANIFEST})",
                path,
            )


def _walk(folder: Path) -> tuple[list[str], list[str]]:
    """(files, folders) under ``folder``, relative and ``/``-separated (folders end in ``/``),
    without the manifest and the resume state."""
    files, folders = [], []
    for root, subdirs, names in os.walk(folder):
        rel = Path(root).relative_to(folder).as_posix()
        prefix = "" if rel == "." else rel + "/"
        if not prefix:
            subdirs[:] = [d for d in subdirs if d not in STATE]
        folders += [prefix + d + "/" for d in subdirs]
        files += [prefix + n for n in names if prefix + n != MANIFEST]
    return files, folders


def foreign_entries(folder: Path, listed: Iterable[str]) -> list[str]:
    """Entries under ``folder`` that are neither in ``listed`` nor hold a listed file (nor the
    manifest, nor resume state): what a run did not write."""
    names = set(listed)
    files, folders = _walk(folder)
    foreign = [f for f in files if f not in names]
    foreign += [d for d in folders if not any(n.startswith(d) for n in names)]
    return sorted(foreign)


def _foreign(real: Path) -> list[str]:
    """What ``real`` holds that ndt-cli did not write (empty: an earlier result, or new)."""
    listed = listed_outputs(real)
    if listed is not None:
        return foreign_entries(real, listed)
    entries = _entries(real)
    foreign = [e for e in entries if not KNOWN.match(e)]
    return foreign or ([] if not entries or set(MARKERS) & set(entries) else entries)


def _check_inputs(real: Path, out: Path, inputs: Iterable[str | Path]) -> None:
    """Refuse an output folder that is, holds, or lies inside a file or folder the run reads."""
    from ndt_cli.io.multiscan import split_spec

    for given in inputs:
        path = split_spec(given)[0].resolve()
        try:
            inside = path == real or real in path.parents
            holds = path.is_dir() and path in real.parents
        except OSError:  # not to be seen here: its own check reports it
            continue
        if inside or holds:
            raise OutputError(
                f"the output folder must not be, hold or lie inside an input ({given}): "
                "choose another folder",
                out,
            )


def check_output_folder(out: Path, inputs: Iterable[str | Path] = ()) -> Path:
    """The folder a run may write (symlinks resolved): new, empty, or an earlier result.

    Raises :class:`OutputError` (checked before any work) when ``out`` is a file, the current
    folder or one of its parents, cannot be written, holds files ndt-cli did not write (an
    entry its manifest does not list), or is, holds or lies inside one of the run's ``inputs``.
    """
    if str(out) == "":
        raise OutputError("the output folder name is empty")
    real = out.resolve()
    try:
        exists = real.exists()
        if exists and not real.is_dir():
            raise OutputError("the output path exists and is not a folder", out)
        if real == real.parent or Path.cwd().resolve().is_relative_to(real):
            raise OutputError("the output must be a folder of its own, not this folder", out)
        _check_inputs(real, out, inputs)
        foreign = _foreign(real) if exists else []
        if foreign:
            raise OutputError(
                f"the folder holds files that ndt-cli did not write ({foreign[0]}, ...): "
                "choose a new or empty folder",
                out,
            )
        parent = real.parent  # the new content is staged in a folder beside the output
        while not parent.exists():
            parent = parent.parent
        writable = os.access(parent, os.W_OK | os.X_OK)
        if not writable or (exists and not os.access(real, os.W_OK | os.X_OK)):
            read_only = os.statvfs(real if exists else parent).f_flag & os.ST_RDONLY
            why = "read-only file system" if read_only else "permission denied"
            raise OutputError(f"cannot write here ({why})", out)
    except PermissionError as exc:
        raise OutputError(f"cannot write here ({exc.strerror})", out) from None
    return real


def clean_stale(out: Path) -> None:
    """Remove temporary folders of ``out`` left by runs that were killed."""
    pattern = re.compile(rf"^\.{re.escape(out.name)}\.(tmp|old)-(\d+)-[0-9a-f]+$")
    if not out.parent.is_dir():
        return
    for entry in out.parent.iterdir():
        m = pattern.match(entry.name)
        if m and not pid_alive(int(m.group(2))):
            shutil.rmtree(entry, ignore_errors=True)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two folders atomically; False when this system or file system cannot."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _carry(old: Path, new: Path, names: Iterable[str]) -> None:
    """Hard-link (or copy) the entries ``names`` of ``old`` into ``new`` (if not there yet)."""
    for name in names:
        src, dst = old / name, new / name
        if dst.exists() or not (src.exists() or src.is_symlink()):
            continue
        if src.is_dir():
            shutil.copytree(src, dst, copy_function=_link_or_copy)
        else:
            _link_or_copy(str(src), str(dst))


def _link_or_copy(src: str, dst: str) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _write(folder: Path, files: Mapping[str, Content]) -> None:
    for name, content in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if callable(content):
            content(path)
        else:
            # a name that is not valid UTF-8 (a Latin-1 file name) is shown escaped
            data = (
                content.encode("utf-8", "backslashreplace") if isinstance(content, str) else content
            )
            with open(path, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())


def _write_manifest(folder: Path) -> None:
    """List every file of ``folder`` but the resume state in its manifest, with its SHA-256."""
    text = "".join(f"{sha256_of(folder / n)}  {n}\n" for n in sorted(_walk(folder)[0]))
    (folder / MANIFEST).write_text(text, encoding="utf-8", errors="surrogateescape")


def _sync_folder(folder: Path) -> None:
    """Make the folder's entries durable before it is swapped in."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _swap_in(tmp: Path, real: Path) -> Path:
    """Put ``tmp`` in place of ``real``; returns where the old content went (or tmp if none)."""
    if not real.exists():
        os.rename(tmp, real)
        return tmp
    if _exchange(tmp, real):
        return tmp
    old = real.parent / f".{real.name}.old-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    os.rename(real, old)
    os.rename(tmp, real)
    return old


def publish(out: Path, files: Mapping[str, Content], keep_others: bool = False) -> None:
    """Write ``files`` (name -> content) as the new content of the output folder ``out``, all
    together. The resume state of the old folder is carried over, and with ``keep_others``
    every other entry this run does not write too (outputs of other ``ndt-analyze`` commands)."""
    real = check_output_folder(out)
    clean_stale(real)
    tmp = real.parent / f".{real.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        tmp.mkdir(parents=True)
        _write(tmp, files)
        if real.is_dir():
            others = [e.name for e in real.iterdir() if e.name not in files and e.name != MANIFEST]
            _carry(real, tmp, others if keep_others else STATE)
        _write_manifest(tmp)
        _sync_folder(tmp)
        old = _swap_in(tmp, real)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(f"cannot write the outputs ({exc.strerror or exc})", out) from None
    except BaseException:  # a bug or Ctrl-C: no staging folder is left beside the output
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    with contextlib.suppress(OSError):
        shutil.rmtree(old, ignore_errors=True)


def check_shared_folder(folder: Path, names: Iterable[str]) -> None:
    """Raise :class:`OutputError` before files ``names`` are written into ``folder``, a folder
    that may hold other files (``ndt-export --per-scan``), when one of them would replace a file
    no earlier such export wrote (its manifest does not list it), or when ``folder`` is the
    output folder of a run."""
    listed = output_digests(folder) or {}
    if set(listed) & {m.rstrip("/") for m in MARKERS}:
        raise OutputError("is the output folder of a run: choose another folder", folder)
    for name in names:
        path = folder / name
        if (path.exists() or path.is_symlink()) and name not in listed:
            raise OutputError(
                "exists and no earlier export wrote it: remove it or choose another folder", path
            )


def record_shared_folder(folder: Path, names: Iterable[str]) -> None:
    """After files ``names`` were written into ``folder``: remove the files an earlier export
    wrote there that this one did not, and list this one's files in the folder's manifest."""
    names = sorted(names)
    for stale in set(output_digests(folder) or {}) - set(names):
        with contextlib.suppress(OSError):
            (folder / stale).unlink()
    text = "".join(f"{sha256_of(folder / n)}  {n}\n" for n in names)
    with atomic_path(folder / MANIFEST) as tmp:
        tmp.write_text(text, encoding="utf-8")
