"""A scan's points in the scanner frame, as the preparation reads them: chunks of coordinates
(:class:`~ndt_cli.io.blocks.Block`), read from the file once and held while the scan is
prepared, or, for a file too large to hold, streamed twice.

The scanner frame is the file's frame after ``input.axes``, ``input.scale`` and the range
limits (metres, z up); unusable points (non-finite, exactly (0,0,0)) are dropped on reading.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ndt_cli.config.rules import axes_matrix
from ndt_cli.config.schema import InputConfig
from ndt_cli.errors import InputError
from ndt_cli.io.blocks import Block

log = logging.getLogger(__name__)

INT_BYTES, FLOAT_BYTES = 12, 24  # held per point: a LAS file's integers, float64 coordinates
HELD_SUFFIXES = (".las", ".laz")  # formats whose blocks keep their integers
MAPPED_SUFFIXES = (".las",)  # read again from the page cache with no decoding: streamed twice


def budget(inp: InputConfig) -> int:
    """Bytes of coordinates a scan may hold (``input.memory_mb``)."""
    return inp.memory_mb * 2**20


def _plain(inp: InputConfig) -> bool:
    """Whether the scanner frame is the file's frame (no axes, scale or range limits)."""
    return (
        inp.axes.replace(" ", "") == "x,y,z"
        and inp.scale == 1.0
        and inp.max_range is None
        and inp.min_range <= 0
    )


def _in_frame(points: np.ndarray, inp: InputConfig) -> np.ndarray:
    """``input.axes``, ``input.scale`` and the range limits applied to (N,3) file points."""
    if inp.axes.replace(" ", "") != "x,y,z" or inp.scale != 1.0:
        points = points @ (inp.scale * axes_matrix(inp.axes)).T
    if inp.max_range is not None or inp.min_range > 0:
        r2 = np.einsum("ij,ij->i", points, points)
        keep = r2 >= inp.min_range**2
        if inp.max_range is not None:
            keep &= r2 <= inp.max_range**2
        points = points[keep]
    return np.ascontiguousarray(points)


def block_in_frame(block: Block, inp: InputConfig) -> Block:
    """A block of file points in the scanner frame (the block itself when the frames agree)."""
    return block if _plain(inp) else Block(_in_frame(block.xyz(), inp))


def no_points_in_range(inp: InputConfig, path: Path | None) -> InputError:
    return InputError(
        f"no point between input.min_range and input.max_range "
        f"({inp.min_range} to {inp.max_range} m from the scanner)",
        path,
    )


def to_scanner_frame(points: np.ndarray, inp: InputConfig, path: Path | None = None) -> np.ndarray:
    """Apply ``input.axes``, ``input.scale`` and the range limits to (N,3) file points."""
    out = _in_frame(points, inp)
    if len(out) == 0:
        raise no_points_in_range(inp, path)
    return out


def usable_array(scan: object) -> np.ndarray:
    """The finite, non-(0,0,0) rows of an (N,3) array the user passed (see ``io.as_points``)."""
    from ndt_cli.io import as_points, unusable

    pts = as_points(scan)
    nonfinite, zero = unusable(pts)
    drop = nonfinite | zero
    if drop.all():
        raise InputError("the array holds no usable points")
    if drop.any():
        log.info("dropped %d non-finite or (0,0,0) points", int(drop.sum()))
        pts = pts[~drop]
    return pts


def load_points(
    scan: str | Path | np.ndarray, inp: InputConfig | None = None
) -> tuple[np.ndarray, Path | None]:
    """(N,3) float64 points of a file path or an array in the scanner frame (metres, z up; see
    :class:`~ndt_cli.config.InputConfig`). Non-finite and (0,0,0) points are dropped."""
    inp = inp or InputConfig()
    if isinstance(scan, str | Path):
        from ndt_cli import io

        cloud = io.read(scan)
        return to_scanner_frame(cloud.points, inp, cloud.path), cloud.path
    return to_scanner_frame(usable_array(scan), inp), None


def _held_bytes(path: Path, records: int, inp: InputConfig) -> int:
    """Bytes the coordinates of ``records`` points of ``path`` take when held."""
    ints = path.suffix.lower() in HELD_SUFFIXES and _plain(inp)
    return records * (INT_BYTES if ints else FLOAT_BYTES)


@dataclass(frozen=True)
class ScanChunks:
    """A scan as a re-iterable sequence of blocks of points in the scanner frame.

    A file is read once and its blocks held (a LAZ file's integers: 12 bytes a point), unless
    its coordinates would take more than ``input.memory_mb``: then it is streamed twice,
    ``input.chunk_points`` at a time, and memory grows with the chunk and the points kept, not
    with the file. An uncompressed LAS file of more than ``input.chunk_points`` points is
    streamed twice too: it is mapped from the file, and read again from the page cache without
    decoding. Arrays are one block. ``n_points`` is the count the ground sample's stride is
    taken from: the count the file's header announces when the file is streamed or holds more
    than ``input.chunk_points`` points, else the usable points.
    """

    chunks: Callable[[], Iterable[Block]]
    n_points: int
    path: Path | None
    held: bool = True  # the blocks are in memory: going over them again reads nothing

    @classmethod
    def of(cls, scan: str | Path | np.ndarray, inp: InputConfig) -> ScanChunks:
        if not isinstance(scan, str | Path):
            pts = to_scanner_frame(usable_array(scan), inp)
            return cls.held_points(pts)
        from ndt_cli import io

        path = Path(scan)
        announced = io.count(path)  # LAS/LAZ
        large = announced is not None and announced > inp.chunk_points
        records = announced if announced is not None else io.record_count(path)  # E57 too
        mapped = large and path.suffix.lower() in MAPPED_SUFFIXES
        if mapped or (records is not None and _held_bytes(path, records, inp) > budget(inp)):
            return cls(lambda: _streamed(path, inp), records, path, held=False)  # type: ignore[arg-type]
        blocks = list(_streamed(path, inp))
        n = sum(len(b) for b in blocks)
        if n == 0:
            raise no_points_in_range(inp, path)
        return cls(lambda: blocks, announced if large else n, path)  # type: ignore[arg-type]

    @classmethod
    def held_points(cls, points: np.ndarray, path: Path | None = None) -> ScanChunks:
        """(N,3) float64 points in the scanner frame as one held block."""
        block = Block(points)
        return cls(lambda: (block,), len(points), path)


def _streamed(path: Path, inp: InputConfig) -> Iterator[Block]:
    """The file's usable points in the scanner frame, ``input.chunk_points`` at a time."""
    from ndt_cli import io

    for block in io.read_blocks(path, inp.chunk_points):
        out = block_in_frame(block, inp)
        if len(out):
            yield out
