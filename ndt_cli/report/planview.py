"""A plan view of scans and links as a PNG: world metres to pixels at one scale in x and y
(y up), a grid in world metres, each scan's points in its colour, links coloured by a value,
scanner markers, labels, a colour bar and a legend.

Drawn with Pillow rather than a plotting library: loading matplotlib and drawing the points took
about a second at the end of a chain, this takes a tenth of that. Everything is drawn at
:data:`SS` times its size and reduced, so that lines and text are smooth.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from ndt_cli.core.arrays import column_bounds
from ndt_cli.pipeline.verify import NodeStatus

SS = 2  # drawn at this many times the size, then reduced
PLOT_MAX = (1100, 860)  # px: the largest plot area (width, height)
PLOT_MIN = (620, 420)  # px: room for the title
MARGIN = (78, 52, 250, 48)  # px: left, bottom, right, top (one title line)
TITLE_LINE = 20  # px per further title line
DOT = 1.6  # px: a slice point's size

TAB10 = ("1f77b4", "ff7f0e", "2ca02c", "d62728", "9467bd")  # matplotlib's tab10 colours
TAB10 += ("8c564b", "e377c2", "7f7f7f", "bcbd22", "17becf")
VIRIDIS = ("440154", "482878", "3e4989", "31688e", "26828e")  # viridis: 10 stops, 0 to 1
VIRIDIS += ("1f9e89", "35b779", "6ece58", "b5de2b", "fde725")
GRID, INK, REJECTED, UNUSED, SUSPECT = "#dddddd", "#000000", "#d62728", "#888888", "#ff8c00"
OK_LINK = "#2ca02c"


def rgb(hex6: str) -> tuple[int, int, int]:
    """'1f77b4' or '#1f77b4' as (r, g, b)."""
    h = hex6.lstrip("#")
    return int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16)


def viridis(t: float) -> tuple[int, int, int]:
    """The viridis colour at ``t`` in [0, 1] (clipped), linear between its 10 stops."""
    x = min(max(float(t), 0.0), 1.0) * (len(VIRIDIS) - 1)
    k = min(int(x), len(VIRIDIS) - 2)
    a, b = np.array(rgb(VIRIDIS[k])), np.array(rgb(VIRIDIS[k + 1]))
    r, g, b_ = (round(float(v)) for v in a + (x - k) * (b - a))
    return r, g, b_


@dataclass(frozen=True)
class Scan:
    """One scan in the view: name, colour index, status, scanner position and slice points
    (world frame, m; None when unposed)."""

    name: str
    index: int
    status: NodeStatus
    position: np.ndarray | None  # (2,) m
    points: np.ndarray | None  # (N,2) m


class EdgeStyle(StrEnum):
    """How a link is drawn: coloured by its residual, green (kept, no residual), grey (failed)
    or red and dashed (rejected)."""

    RESIDUAL = "residual"
    OK = "ok"
    FAILED = "failed"
    REJECTED = "rejected"


@dataclass(frozen=True)
class Edge:
    """One link between two posed scanners (world m), drawn in ``style``."""

    a: np.ndarray
    b: np.ndarray
    style: EdgeStyle
    residual_cm: float = 0.0


@dataclass(frozen=True)
class Scene:
    """What the top view shows; ``top_cm``: the residual drawn yellow (None: no colour bar)."""

    scans: tuple[Scan, ...]
    edges: tuple[Edge, ...]
    top_cm: float | None
    title: tuple[str, ...]


@dataclass(frozen=True)
class View:
    """World metres to image pixels (x right, y up, one scale for both axes) in the image
    of size ``size``; ``area``: the plot area (left, top, right, bottom) px; ``scale`` px/m."""

    size: tuple[int, int]
    area: tuple[int, int, int, int]
    scale: float
    x0: float  # m: world x at the area's left edge
    y1: float  # m: world y at the area's top edge

    def px(self, xy: np.ndarray) -> np.ndarray:
        """(N,2) or (2,) world m -> pixel (column, row), floats."""
        xy = np.asarray(xy, float)
        col = self.area[0] + (xy[..., 0] - self.x0) * self.scale
        row = self.area[1] + (self.y1 - xy[..., 1]) * self.scale
        return np.stack([col, row], axis=-1)

    def world(self, col: float, row: float) -> tuple[float, float]:
        """Pixel (column, row) -> world (x, y) m."""
        x = self.x0 + (col - self.area[0]) / self.scale
        return x, self.y1 - (row - self.area[1]) / self.scale


def view_of(scene: Scene, ss: int = 1) -> View:
    """The layout: the plot area takes the data's shape within :data:`PLOT_MIN` ..
    :data:`PLOT_MAX` and the data fills it at one scale; sizes times ``ss``."""
    xy = [s.points for s in scene.scans if s.points is not None]
    xy += [s.position[None] for s in scene.scans if s.position is not None]
    every = np.concatenate(xy) if xy else np.zeros((1, 2))
    lo, hi = column_bounds(every)
    span = np.maximum(hi - lo, 1.0) * 1.04  # 2 % free on every side
    w = float(np.clip(PLOT_MAX[1] * span[0] / span[1], PLOT_MIN[0], PLOT_MAX[0]))
    h = float(np.clip(w * span[1] / span[0], PLOT_MIN[1], PLOT_MAX[1]))
    scale = min(w / span[0], h / span[1])
    left, bottom, right, top = MARGIN
    top += TITLE_LINE * (len(scene.title) - 1)
    centre = 0.5 * (lo + hi)
    size = (round(left + w + right) * ss, round(top + h + bottom) * ss)
    area = (left * ss, top * ss, round(left + w) * ss, round(top + h) * ss)
    s = scale * ss
    return View(size, area, s, centre[0] - 0.5 * w * ss / s, centre[1] + 0.5 * h * ss / s)


def nice_step(span: float, ticks: int = 6) -> float:
    """A grid step of 1, 2 or 5 times a power of ten giving about ``ticks`` lines over
    ``span`` m."""
    raw = span / max(ticks, 1)
    power = 10.0 ** np.floor(np.log10(raw))
    return float(min((m * power for m in (1.0, 2.0, 5.0, 10.0)), key=lambda v: abs(v - raw)))


def tick_label(metres: float) -> str:
    """A grid coordinate as text: ``-50``, ``0`` (never ``-0``), ``2.5``."""
    return f"{float(metres) + 0.0:g}"


def render(scene: Scene) -> bytes:
    """The scene as PNG bytes."""
    from PIL import Image

    view = view_of(scene, SS)
    pixels = np.full((view.size[1], view.size[0], 3), 255, np.uint8)
    ticks = grid(pixels, view)
    points(pixels, view, scene.scans)
    image = Image.fromarray(pixels)
    vectors(image, view, scene, ticks)
    out = io.BytesIO()
    image.reduce(SS).save(out, format="PNG")
    return out.getvalue()


FONT_PX, TITLE_PX = 13, 15  # text sizes (final pixels)


def _font(size: int) -> Any:
    from PIL import ImageFont

    return ImageFont.load_default(size=size * SS)


def grid(pixels: np.ndarray, view: View) -> tuple[np.ndarray, np.ndarray]:
    """Grid lines every :func:`nice_step` metres in the plot area; returns their world x and y."""
    left, top, right, bottom = view.area
    (x0, y1), (x1, y0) = view.world(left, top), view.world(right, bottom)
    step = nice_step(max(x1 - x0, y1 - y0))
    xs = np.arange(np.ceil(x0 / step), np.floor(x1 / step) + 1) * step
    ys = np.arange(np.ceil(y0 / step), np.floor(y1 / step) + 1) * step
    colour = rgb(GRID)
    for c in view.px(np.column_stack([xs, np.full(len(xs), y0)]))[:, 0].round().astype(int):
        pixels[top:bottom, max(c - SS // 2, left) : c + SS - SS // 2] = colour
    for r in view.px(np.column_stack([np.full(len(ys), x0), ys]))[:, 1].round().astype(int):
        pixels[max(r - SS // 2, top) : r + SS - SS // 2, left:right] = colour
    return xs, ys


def points(pixels: np.ndarray, view: View, scans: tuple[Scan, ...]) -> None:
    """Every scan's slice points as small squares of its colour (later scans on top)."""
    left, top, right, bottom = view.area
    d = max(1, round(DOT * SS))
    for scan in scans:
        if scan.points is None or len(scan.points) == 0:
            continue
        c, r = (view.px(scan.points) - d / 2).round().astype(int).T
        inside = (c >= left) & (r >= top) & (c <= right - d) & (r <= bottom - d)
        c, r = c[inside], r[inside]
        colour = rgb(TAB10[scan.index % len(TAB10)])
        for dc in range(d):
            for dr in range(d):
                pixels[r + dr, c + dc] = colour


def vectors(image: Any, view: View, scene: Scene, ticks: tuple[np.ndarray, np.ndarray]) -> None:
    """Everything drawn with lines and text on top of the points."""
    from PIL import ImageDraw

    pen = ImageDraw.Draw(image)
    font = _font(FONT_PX)
    _frame(pen, view, ticks, font)
    for edge in scene.edges:
        _edge(pen, view.px(edge.a), view.px(edge.b), edge.style, edge.residual_cm, scene.top_cm)
    for scan in scene.scans:
        if scan.position is not None:
            _scanner(pen, view.px(scan.position), scan, font)
    _axis_labels(image, pen, view, font)
    _title(pen, view, scene.title)
    y = view.area[1]
    if scene.top_cm is not None:
        y = _colour_bar(pen, view, scene.top_cm, font)
    _legend(pen, view, scene.scans, y + 24 * SS, font)


def _frame(pen: Any, view: View, ticks: tuple[np.ndarray, np.ndarray], font: Any) -> None:
    left, top, right, bottom = view.area
    pen.rectangle([left, top, right, bottom], outline=INK, width=SS)
    xs, ys = ticks
    for x, (c, _) in zip(xs, view.px(np.column_stack([xs, np.zeros(len(xs))])), strict=True):
        pen.text((c, bottom + 5 * SS), tick_label(x), fill=INK, font=font, anchor="mt")
    for y, (_, r) in zip(ys, view.px(np.column_stack([np.zeros(len(ys)), ys])), strict=True):
        pen.text((left - 5 * SS, r), tick_label(y), fill=INK, font=font, anchor="rm")


def _dashes(a: np.ndarray, b: np.ndarray, dash: float) -> list[tuple[np.ndarray, np.ndarray]]:
    n = max(1, int(np.linalg.norm(b - a) / dash))
    t = np.linspace(0.0, 1.0, n + 1)
    return [(a + (b - a) * t[k], a + (b - a) * t[k + 1]) for k in range(0, n, 2)]


def _edge(pen: Any, a: np.ndarray, b: np.ndarray, style: EdgeStyle, cm: float, top: float | None):
    if style is EdgeStyle.REJECTED:
        for p, q in _dashes(a, b, 6.0 * SS):
            pen.line([tuple(p), tuple(q)], fill=REJECTED, width=round(1.5 * SS))
        return
    colour = {EdgeStyle.OK: OK_LINK, EdgeStyle.FAILED: UNUSED}.get(style)
    fill = colour if colour is not None else viridis(cm / (top or 1.0))
    pen.line([tuple(a), tuple(b)], fill=fill, width=(2 if colour is None else 1) * SS)


def _scanner(pen: Any, p: np.ndarray, scan: Scan, font: Any) -> None:
    c, r, s = float(p[0]), float(p[1]), 6.0 * SS
    if scan.status is NodeStatus.OK:
        pen.polygon([(c, r - s), (c - s, r + 0.7 * s), (c + s, r + 0.7 * s)], fill=INK)
    elif scan.status is NodeStatus.SUSPECT:
        pen.rectangle([c - 0.8 * s, r - 0.8 * s, c + 0.8 * s, r + 0.8 * s], fill=SUSPECT)
    else:
        pen.line([(c - s, r - s), (c + s, r + s)], fill=REJECTED, width=SS * 2)
        pen.line([(c - s, r + s), (c + s, r - s)], fill=REJECTED, width=SS * 2)
    label = str(scan.index) if scan.status is NodeStatus.OK else f"{scan.index} {scan.status}"
    pen.text((c + s, r - s), label, fill=INK, font=font, anchor="ld")


def _axis_labels(image: Any, pen: Any, view: View, font: Any) -> None:
    from PIL import Image, ImageDraw

    left, top, right, bottom = view.area
    pen.text(((left + right) / 2, view.size[1] - 8 * SS), "x world (m)", fill=INK, font=font,
             anchor="md")  # fmt: skip
    text = "y world (m)"
    box = pen.textbbox((0, 0), text, font=font)
    label = Image.new("L", (box[2] + 2 * SS, box[3] + 2 * SS), 255)
    ImageDraw.Draw(label).text((SS, SS), text, fill=0, font=font)
    label = label.rotate(90, expand=True)
    y = (top + bottom - label.height) // 2
    image.paste((0, 0, 0), (4 * SS, y), label.point(lambda v: 255 - v))


def _title(pen: Any, view: View, lines: tuple[str, ...]) -> None:
    font = _font(TITLE_PX)
    left, top, right, _ = view.area
    for k, line in enumerate(reversed(lines)):
        y = top - (8 + TITLE_LINE * k) * SS
        pen.text(((left + right) / 2, y), line, fill=INK, font=font, anchor="md")


def _colour_bar(pen: Any, view: View, top_cm: float, font: Any) -> int:
    """The residual colour bar in the right margin; returns its bottom row."""
    left = view.area[2] + 26 * SS
    y0 = view.area[1] + 48 * SS
    height, width = max(120 * SS, (view.area[3] - view.area[1]) // 3), 16 * SS
    for k in range(height):  # top row yellow (top_cm), bottom row dark (0)
        pen.line([(left, y0 + k), (left + width, y0 + k)], fill=viridis(1.0 - k / (height - 1)))
    pen.rectangle([left, y0, left + width, y0 + height], outline=INK, width=max(1, SS // 2))
    for frac in (0.0, 0.5, 1.0):
        y = y0 + (1.0 - frac) * (height - 1)
        pen.line([(left + width, y), (left + width + 4 * SS, y)], fill=INK, width=SS)
        pen.text((left + width + 7 * SS, y), f"{frac * top_cm:.2g}", fill=INK, font=font,
                 anchor="lm")  # fmt: skip
    pen.text((left, y0 - 30 * SS), "link residual after", fill=INK, font=font, anchor="ls")
    pen.text((left, y0 - 14 * SS), "adjustment (cm)", fill=INK, font=font, anchor="ls")
    return y0 + height


def _legend(pen: Any, view: View, scans: tuple[Scan, ...], y: int, font: Any) -> None:
    """One coloured dot and name per scan with points, in the right margin from row ``y``."""
    left = view.area[2] + 26 * SS
    for scan in scans:
        if scan.points is None or y > view.size[1] - 20 * SS:
            continue
        r = 4 * SS
        pen.ellipse([left, y - r, left + 2 * r, y + r], fill=rgb(TAB10[scan.index % len(TAB10)]))
        pen.text((left + 3 * r, y), scan.name, fill=INK, font=font, anchor="lm")
        y += 18 * SS
