"""Point records with every attribute: chunked readers and header summaries of all formats,
each through its format's reader in the one table of :data:`ndt_cli.io.points.READERS`.

Where :mod:`ndt_cli.io.points` reads x, y, z only, this module keeps every per-point attribute a
file holds, for writing the registered cloud (:mod:`ndt_cli.io.export`):

- :func:`summary` describes a file from its header without reading the points: the point count,
  the bounding box (LAS/LAZ), the LAS point format and version, the CRS records (VLRs under
  ``LASF_Projection``: WKT 2112, GeoTIFF keys 34735/34736/34737) and the name and storage type of
  each attribute (:class:`Dimension`).
- :func:`iter_records` yields chunks of at most ``chunk_points`` points as ``dict`` of arrays:
  ``"x"``, ``"y"``, ``"z"`` (float64, the file's own coordinates, before any ``input.scale`` or
  ``input.axes``) plus one array per :class:`Dimension`, in its storage type (LAS extra bytes
  with a scale stay raw integers; ``Dimension.scales`` / ``offsets`` give their meaning).

Per format: LAS/LAZ every standard dimension (bit fields as uint8) and every extra-bytes
dimension, streamed with laspy's ``chunk_iterator``; PLY every scalar ``vertex`` property
(binary files are memory-mapped and sliced); PCD every field (a packed ``rgb``/``rgba`` field
becomes ``red``, ``green``, ``blue``); E57 (``FILE.e57#K`` names scan K, see
:mod:`ndt_cli.io.e57`) ``intensity``, ``red``/``green``/``blue``, ``row_index``/``column_index``
and ``time_stamp`` when present, streamed, points flagged invalid dropped, spherical coordinates
turned cartesian; PTX (``FILE.ptx#K``, see :mod:`ndt_cli.io.ptx`) ``intensity`` and
``red``/``green``/``blue`` when present; text files x, y, z only. No point is dropped here
otherwise.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from ndt_cli.io.multiscan import split_spec
from ndt_cli.io.points import checked_reader, file_errors, reader_for
from ndt_cli.io.record_types import (
    CHUNK_POINTS,
    CRS_RECORD_IDS,
    CRS_USER_ID,
    Chunk,
    Dimension,
    RawVlr,
    Summary,
    is_crs,
)
from ndt_cli.io.records_formats import raw_vlrs

__all__ = [
    "CHUNK_POINTS",
    "CRS_RECORD_IDS",
    "CRS_USER_ID",
    "Chunk",
    "Dimension",
    "RawVlr",
    "Summary",
    "format_of",
    "is_crs",
    "iter_records",
    "raw_vlrs",
    "summary",
]


def format_of(path: str | Path) -> str:
    """Format name of a path by its extension (``FILE.e57#K`` is e57); InputError if unknown."""
    f = split_spec(path)[0]
    return reader_for(f).format_name(f)


def summary(path: str | Path) -> Summary:
    """Header summary of a point file (see :class:`Summary`); InputError if unreadable."""
    p, reader = checked_reader(path)
    with file_errors(p):
        return reader.summary(p)


def iter_records(path: str | Path, chunk_points: int = CHUNK_POINTS) -> Iterator[Chunk]:
    """Chunks of at most ``chunk_points`` points, in file order, with every attribute (see the
    module docstring). A file that ends before its header's count is an InputError."""
    p, reader = checked_reader(path)
    with file_errors(p):
        yield from reader.records(p, max(1, int(chunk_points)))
