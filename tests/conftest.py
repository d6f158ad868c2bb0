"""Shared test helpers: the real-data folder beside the project (``../shared/data``)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def shared_data(name: str) -> Path:
    """Folder ``name`` of the shared real data; skip the test if absent (fail if CI is "true")."""
    folder = SHARED_DATA / name
    if not folder.is_dir():
        message = f"shared data folder not found: {folder}"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)
    return folder


@pytest.fixture
def shared_data_dir() -> Path:
    """Root of the shared real data (may not exist; use :func:`shared_data` for a folder)."""
    return SHARED_DATA
