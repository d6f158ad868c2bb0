"""JSON and CSV text of results (numpy values converted; a header line on every CSV), and
reading them back with one-line errors."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.errors import InputError, read_user_text


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def to_json(data: dict[str, Any]) -> str:
    """Pretty JSON text (numpy values converted)."""
    return json.dumps(data, indent=2, default=_json_default) + "\n"


def csv_text(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    """CSV text with a header line."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def read_table(path: Path, what: str, columns: Sequence[str]) -> list[dict[str, str]]:
    """The rows of a CSV file with a header line; InputError (one line naming the file) when it
    cannot be read, is not CSV, or lacks one of ``columns``."""
    text = read_user_text(path, what)
    try:
        reader = csv.DictReader(text.splitlines())
        rows = list(reader)
    except csv.Error as exc:
        raise InputError(f"not a valid CSV file ({exc})", path) from None
    missing = [c for c in columns if c not in (reader.fieldnames or ())]
    if missing:
        raise InputError(f"no {missing[0]!r} column", path)
    if any(None in row or None in row.values() for row in rows):
        raise InputError("a row has more or fewer cells than the header", path)
    return rows


def read_json_object(path: Path, what: str) -> dict[str, Any]:
    """The JSON object in a file; InputError (one line naming the file) when it cannot be
    read, is not JSON, or is not an object."""
    try:
        data = json.loads(read_user_text(path, what))
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON ({exc.msg}, line {exc.lineno})", path) from None
    if not isinstance(data, dict):
        raise InputError("not a JSON object", path)
    return data
