"""The link inspector's picture: a link's slices side by side, the target's points blue and
the source's orange, in the target's frame, zoomed on where they overlap, with a scale bar.

Drawn with Pillow as :mod:`ndt_cli.report.planview` draws the top view (at twice the size,
then reduced), and stored with a palette of a few colours: a figure is a few tens of
kilobytes, so that a report holds one per link and stays one file.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from ndt_cli.report.inspect import LinkView, SliceView
from ndt_cli.report.planview import INK, SS, TAB10, font, nice_step, rgb

PANEL = 300  # px: the side of a slice's square
GAP = 14  # px between the panels and around them
HEAD = 24  # px: the panel's title row
FOOT = 26  # px: the scale bar's row
DOT = 2  # px: a point
TARGET, SOURCE = rgb(TAB10[0]), rgb(TAB10[1])  # blue, orange
COLOURS = 24  # the palette of the stored PNG


def _panel_origin(k: int) -> tuple[int, int]:
    """Top-left pixel of panel ``k``'s square (final pixels)."""
    return GAP + k * (PANEL + GAP), HEAD


Box = tuple[float, float, float]  # x0, y0, side (m, the target's frame)
RGB = tuple[int, int, int]


def _dots(pixels: np.ndarray, xy: np.ndarray, box: Box, k: int, colour: RGB) -> None:
    """Points of the target's frame (m) as squares in panel ``k`` (supersampled pixels)."""
    x0, y0, side = box
    left, top = _panel_origin(k)
    scale = PANEL * SS / side
    col = (left * SS + (xy[:, 0] - x0) * scale).astype(int)
    row = (top * SS + (y0 + side - xy[:, 1]) * scale).astype(int)
    d = DOT * SS
    inside = (col >= left * SS) & (row >= top * SS)
    inside &= (col < (left + PANEL) * SS - d) & (row < (top + PANEL) * SS - d)
    col, row = col[inside], row[inside]
    for dc in range(d):
        for dr in range(d):
            pixels[row + dr, col + dc] = colour


def _labels(pen: Any, view: LinkView) -> None:
    """Each panel's frame, title and scale bar."""
    small = font(12)
    side = view.box[2]
    step = nice_step(side, ticks=4)
    bar = step * PANEL / side
    for k, s in enumerate(view.slices):
        left, top = _panel_origin(k)
        box = [left * SS, top * SS, (left + PANEL) * SS, (top + PANEL) * SS]
        pen.rectangle(box, outline=INK, width=SS)
        title = f"slice {s.height:g} m above the ground"
        pen.text((left * SS, (top - 6) * SS), title, fill=INK, font=font(13), anchor="ld")
        y = (top + PANEL + 12) * SS
        pen.line([(left * SS, y), ((left + bar) * SS, y)], fill=INK, width=2 * SS)
        for x in (left, left + bar):
            pen.line([(x * SS, y - 4 * SS), (x * SS, y + 4 * SS)], fill=INK, width=SS)
        label = f"{step:g} m"
        pen.text(((left + bar + 6) * SS, y), label, fill=INK, font=small, anchor="lm")


def inspector_png(view: LinkView) -> bytes:
    """The picture of a link's slices (PNG bytes)."""
    from PIL import Image, ImageDraw

    n = max(1, len(view.slices))
    width, height = GAP + n * (PANEL + GAP), HEAD + PANEL + FOOT
    pixels = np.full((height * SS, width * SS, 3), 255, np.uint8)
    for k, s in enumerate(view.slices):
        _draw_slice(pixels, s, view.box, k)
    image = Image.fromarray(pixels)
    _labels(ImageDraw.Draw(image), view)
    small = image.reduce(SS).quantize(colors=COLOURS, method=Image.Quantize.FASTOCTREE)
    out = io.BytesIO()
    small.save(out, format="PNG")
    return out.getvalue()


def _draw_slice(pixels: np.ndarray, s: SliceView, box: Box, k: int) -> None:
    """The target's points, then the source's on top."""
    _dots(pixels, s.target, box, k, TARGET)
    _dots(pixels, s.source, box, k, SOURCE)
