"""Text files of transforms: one 4x4 per file, or one named 4x4 per line.

A 4x4 is written as four rows of four numbers with enough digits to round-trip float64 (the
format CloudCompare's ``-APPLY_TRANS`` and PDAL's ``filters.transformation`` read as it is).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ndt_cli.errors import InputError, read_user_text

# a field: a quoted name (JSON string syntax), a comment ('#' at the start or after a space:
# 'scans.e57#2' is a name) up to the end of the line, or a run of other characters
_FIELD = re.compile(r'\s*(?:("(?:[^"\\]|\\.)*")|(#.*)|(\S+))')


def quote_name(name: str) -> str:
    """A scan name as a field of a pose line: as it is, or quoted (JSON string syntax, every
    character that is not printable escaped) when it is empty, holds white space, starts with a
    quote or a ``#``, or holds a character that is not printable (a control, a bidi override,
    a byte of a name that is not UTF-8)."""
    plain = name.isprintable() and not any(c.isspace() for c in name)
    if name and plain and name[0] not in '"#':
        return name
    body = json.dumps(name, ensure_ascii=False)[1:-1]
    return '"' + "".join(c if c.isprintable() else _escape(c) for c in body) + '"'


def _escape(char: str) -> str:
    """``\\uXXXX`` (a surrogate pair above U+FFFF), as JSON writes a character."""
    code = ord(char)
    if code > 0xFFFF:
        code -= 0x10000
        return f"\\u{0xD800 + (code >> 10):04x}\\u{0xDC00 + (code & 0x3FF):04x}"
    return f"\\u{code:04x}"


def split_fields(line: str) -> list[str]:
    """The fields of a line of a pose file: white-space separated, a quoted name unquoted (see
    :func:`quote_name`), a comment dropped; ValueError for a quote that does not close."""
    fields, pos = [], 0
    while pos < len(line.rstrip()):
        m = _FIELD.match(line, pos)
        if m is None or m.end() == pos or (m.group(3) or "").startswith('"'):
            raise ValueError("a quoted name does not end")
        if m.group(2):
            break
        fields.append(json.loads(m.group(1)) if m.group(1) else m.group(3))
        pos = m.end()
    return fields


def format_matrix(T: np.ndarray) -> str:
    """Text of a 4x4: four rows of four numbers, enough digits to round-trip float64."""
    return "\n".join(" ".join(f"{v:.17g}" for v in row) for row in np.asarray(T)) + "\n"


def format_pose_line(name: str, T: np.ndarray) -> str:
    """``name`` (quoted if need be, see :func:`quote_name`) and the 16 numbers of a 4x4,
    row-major, on one line (no newline)."""
    return f"{quote_name(name)} " + " ".join(f"{v:.17g}" for v in np.asarray(T).ravel())


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
    problem = rigid_problem(T)
    if problem:
        raise InputError(problem, p)
    return T


def rigid_problem(T: np.ndarray, tol: float = 1e-4) -> str:
    """What keeps a 4x4 from being a rigid transform ('' when it is one): a value that is not
    finite, a last row other than 0 0 0 1, or a rotation part that is not a rotation (``R R^T``
    off the identity by more than ``tol``, or a reflection)."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        return f"not a 4x4 matrix (shape {T.shape})"
    if not np.all(np.isfinite(T)):
        return "not a rigid 4x4 transform (a value is not finite)"
    if not np.allclose(T[3], [0, 0, 0, 1]):
        return "not a rigid 4x4 transform (last row must be 0 0 0 1)"
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > tol or np.linalg.det(R) < 0:
        return "the rotation part is not a rotation matrix"
    return ""


def named_rows(path: str | Path, what: str) -> Iterator[tuple[int, list[str]]]:
    """(line number, fields) of every non-empty line of a text file of named matrices.

    A ``#`` at the start of a line or after a space starts a comment (``scans.e57#2`` is a name);
    a name in double quotes may hold spaces and escapes (see :func:`quote_name`).
    """
    for number, line in enumerate(read_user_text(path, what).splitlines(), 1):
        try:
            fields = split_fields(line)
        except ValueError as exc:
            raise InputError(f"line {number}: {exc}", path) from None
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
