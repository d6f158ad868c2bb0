"""Files that hold many scans (E57, PTX): ``FILE#K`` names scan K (from 0) of such a file, a
plain ``FILE`` its only scan. Here: splitting such names and finding the scan K a name means
(what every reader needs); listing the scans of such files and their header poses is
:mod:`ndt_cli.io.multiscan_files`."""

from __future__ import annotations

import re
from pathlib import Path

from ndt_cli.errors import InputError

MULTI_SCAN = (".e57", ".ptx")  # the suffixes of formats whose reader has ``scan_count``
_SUFFIXES = "|".join(s.lstrip(".") for s in MULTI_SCAN)
_SPEC = re.compile(rf"^(?P<file>.+\.({_SUFFIXES}))#(?P<index>\d+)$", re.IGNORECASE)


def split_spec(spec: str | Path) -> tuple[Path, int | None]:
    """``'a.e57#3'`` -> (Path('a.e57'), 3); anything else -> (Path(spec), None)."""
    m = _SPEC.match(str(spec))
    return (Path(m["file"]), int(m["index"])) if m else (Path(spec), None)


def which_scan(path: Path, index: int | None, count: int, spec: str) -> int:
    """The index of the scan ``spec`` names among the ``count`` scans of ``path``."""
    if count == 0:
        raise InputError(f"the {path.suffix.lstrip('.').upper()} file holds no scan", spec)
    if index is None:
        if count > 1:
            raise InputError(
                f"holds {count} scans: name one as {path.name}#K (K = 0..{count - 1}) "
                "or register them all with ndt-chain",
                spec,
            )
        return 0
    if index >= count:
        raise InputError(f"no scan #{index} (the file holds {count})", spec)
    return index
