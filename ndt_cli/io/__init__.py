"""Point files in and out, transform files, atomic writing.

``read`` / ``read_chunks`` / ``read_blocks`` / ``count`` read PLY, LAS/LAZ, PCD, E57 and
xyz/txt/csv/3d through one reader interface (:mod:`ndt_cli.io.formats`); ``write`` writes
(N,3) arrays.
"""

from ndt_cli.io.blocks import Block
from ndt_cli.io.points import (
    SUPPORTED_SUFFIXES,
    PointCloud,
    acquired,
    as_points,
    count,
    read,
    read_blocks,
    read_chunks,
    record_count,
    unusable,
)
from ndt_cli.io.writers import WRITE_SUFFIXES, write

__all__ = [
    "SUPPORTED_SUFFIXES",
    "WRITE_SUFFIXES",
    "Block",
    "PointCloud",
    "acquired",
    "as_points",
    "count",
    "read",
    "read_blocks",
    "read_chunks",
    "record_count",
    "unusable",
    "write",
]
