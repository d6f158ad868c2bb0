"""Text files of transforms: one 4x4 per file, or one named 4x4 per line.

A 4x4 is written as four rows of four numbers with enough digits to round-trip float64 (the
format CloudCompare's ``-APPLY_TRANS`` and PDAL's ``filters.transformation`` read as it is).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError, read_user_text

_COMMENT = re.compile(r"(^|\s)#.*$")  # 'scans.e57#2' is a name, not a comment


def format_matrix(T: np.ndarray) -> str:
    """Text of a 4x4: four rows of four numbers, enough digits to round-trip float64."""
    return "\n".join(" ".join(f"{v:.17g}" for v in row) for row in np.asarray(T)) + "\n"


def format_pose_line(name: str, T: np.ndarray) -> str:
    """``name`` and the 16 numbers of a 4x4, row-major, on one line (no newline)."""
    return f"{name} " + " ".join(f"{v:.17g}" for v in np.asarray(T).ravel())


def read_matrix(path: str | Path) -> np.ndarray:
    """Read a 4x4 rigid transform from a text file (16 numbers, row-major; '#' comments)."""
    p = Path(path)
    text = read_user_text(p, "transform")
    try:
        values = [float(v) for line in text.splitlines() for v in line.split("#")[0].split()]
    except ValueError:
        raise InputError("transform file holds a non-numeric value", p) from None
    if len(values) != 16:
        raise InputError(f"expected 16 numbers (a 4x4 matrix), found {len(values)}", p)
    T = np.array(values).reshape(4, 4)
    if not np.all(np.isfinite(T)) or not np.allclose(T[3], [0, 0, 0, 1]):
        raise InputError("not a rigid 4x4 transform (last row must be 0 0 0 1)", p)
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise InputError("the rotation part is not a rotation matrix", p)
    return T


def named_rows(path: str | Path, what: str) -> Iterator[tuple[int, list[str]]]:
    """(line number, fields) of every non-empty line of a text file of named matrices.

    A ``#`` at the start of a line or after a space starts a comment (``scans.e57#2`` is a name).
    """
    for number, line in enumerate(read_user_text(path, what).splitlines(), 1):
        fields = _COMMENT.sub("", line).split()
        if fields:
            yield number, fields


def read_pose_list(path: str | Path) -> dict[str, np.ndarray]:
    """Read ``name m00 m01 ... m33`` lines (a 4x4 per scan, row-major) into a dict."""
    p = Path(path)
    poses = {}
    for number, fields in named_rows(p, "poses"):
        try:
            values = [float(v) for v in fields[1:]]
        except ValueError:
            values = []
        if len(values) != 16:
            raise InputError(f"line {number}: expected a name and 16 numbers", p)
        poses[fields[0]] = np.array(values).reshape(4, 4)
    return poses
