"""Names of the files a run writes per scan and per link: portable, bounded and unique.

A scan's part of a file name is its name without folders and extension, ``#`` as ``_``
(:func:`file_stem`), with every character outside ``A-Z a-z 0-9 . _ -`` replaced by ``_``, at
most :data:`MAX_STEM` bytes (a longer one is cut and ends in a hash of the whole), never a name
Windows reserves, and unique among the run's scans case-insensitively (``_2``, ``_3``, ...
added in scan order). Such names can be created on Windows, SMB shares and case-insensitive
file systems, and no two outputs share one.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Sequence
from pathlib import Path

MAX_STEM = 100
"""Longest scan part of a file name (bytes): a link file ``T_<a>_<b>.txt`` stays under 255."""
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
_RESERVED = {"con", "prn", "aux", "nul", *(f"com{k}" for k in range(10))}
_RESERVED |= {f"lpt{k}" for k in range(10)}


def file_stem(name: str) -> str:
    """A scan name as part of a file name: no folders, no extension, ``#`` as ``_``.

    ``scan_00.laz`` -> ``scan_00``; ``campaign.e57#2`` -> ``campaign_2``;
    ``north/scan_1.laz`` -> ``north_scan_1``.
    """
    head, _, index = name.partition("#")
    stem = head.rsplit(".", 1)[0] if "." in Path(head).name else head
    stem = stem.replace("/", "_").replace("\\", "_")
    return f"{stem}_{index}" if index else stem


def portable(text: str, limit: int = MAX_STEM) -> str:
    """``text`` with only ``A-Z a-z 0-9 . _ -`` (other runs become ``_``), at most ``limit``
    characters (a longer text is cut and ends in 8 hex digits of its SHA-256), not empty and not
    a name Windows reserves."""
    safe = _UNSAFE.sub("_", text).strip("._") or "scan"
    if len(safe) > limit:
        digest = hashlib.sha256(text.encode("utf-8", "surrogateescape")).hexdigest()[:8]
        safe = f"{safe[: limit - 9]}-{digest}"
    return f"{safe}_" if safe.lower() in _RESERVED else safe


def _unique(candidates: Sequence[str], taken: set[str] | None = None) -> list[str]:
    """The candidates made unique case-insensitively (``_2``, ``_3``, ... in order)."""
    taken = set() if taken is None else taken
    out = []
    for base in candidates:
        candidate, k = base, 1
        while candidate.lower() in taken:
            k += 1
            candidate = f"{base}_{k}"
        taken.add(candidate.lower())
        out.append(candidate)
    return out


def scan_stems(names: Sequence[str]) -> list[str]:
    """One portable, unique stem per scan name (see the module docstring)."""
    return _unique([portable(file_stem(n)) for n in names])


def per_scan_file_names(names: Sequence[str], suffix: str) -> list[str]:
    """One file name per scan name, safe on every file system and unique (case-insensitively):
    ``north/scan_1.laz`` -> ``north_scan_1.laz``, ``campaign.e57#2`` -> ``campaign_2.laz``."""
    return [f"{stem}{suffix}" for stem in scan_stems(names)]


def pose_file_names(names: Sequence[str]) -> list[str]:
    """``poses/T_world_<scan>.txt`` of every scan."""
    return [f"poses/T_world_{stem}.txt" for stem in scan_stems(names)]


def link_file_names(names: Sequence[str], links: Sequence[tuple[int, int]]) -> list[str]:
    """``T_<target>_<source>.txt`` of every (target, source) link (scan indices into ``names``);
    where two links would share a name (``a`` + ``b_c`` and ``a_b`` + ``c``), each of them ends
    in its scan indices instead."""
    stems = scan_stems(names)
    bases = [f"T_{stems[t]}_{stems[s]}" for t, s in links]
    lower = [b.lower() for b in bases]
    bases = [
        b if lower.count(b.lower()) == 1 else f"{b}_{t}-{s}"
        for b, (t, s) in zip(bases, links, strict=True)
    ]
    return [f"{b}.txt" for b in _unique(bases)]


def old_link_file_name(target: str, source: str) -> str:
    """The link file name of results written before names were made unique (for reading them)."""
    return f"T_{file_stem(target)}_{file_stem(source)}.txt"
