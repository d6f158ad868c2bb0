"""A plan view of scans and links as a PNG: world metres to pixels at one scale in x and y
(y up), a grid in world metres counted from a stated origin (so that georeferenced coordinates
read ``120``, not ``5.8001e+06``), each scan's points in its colour, links drawn by their state
(checked ones coloured by their residual), scanner and control station markers, labels, a
colour bar and a legend.

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
UNCHECKED = "#3b5b82"  # a kept link that no cycle checks: dashed slate blue, never green
STATION = "#1b7a32"  # a control station used (a rejected one is red)


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
    """How a link is drawn: checked by a cycle (solid, coloured by its residual), kept but not
    checked (dashed slate blue), rejected (dashed red) or not used (thin grey)."""

    RESIDUAL = "residual"
    UNCHECKED = "unchecked"
    UNUSED = "unused"
    REJECTED = "rejected"


@dataclass(frozen=True)
class Edge:
    """One link between two posed scanners (world m), drawn in ``style``."""

    a: np.ndarray
    b: np.ndarray
    style: EdgeStyle
    residual_cm: float = 0.0


XY = tuple[float, float]  # world (x, y), m


@dataclass(frozen=True)
class Station:
    """A control station at its given coordinates (world m), used by the adjustment or not."""

    name: str
    xy: np.ndarray
    used: bool


@dataclass(frozen=True)
class Scene:
    """What the top view shows; ``top_cm``: the residual drawn yellow (None: no colour bar);
    ``origin``: world (x, y) m the axes count from."""

    scans: tuple[Scan, ...]
    edges: tuple[Edge, ...]
    top_cm: float | None
    title: tuple[str, ...]
    origin: XY = (0.0, 0.0)
    stations: tuple[Station, ...] = ()


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
    xy += [s.xy[None] for s in scene.stations]
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
    """A grid coordinate as text: ``-50``, ``0`` (never ``-0``), ``2.5``, ``12000`` (never
    in exponent notation)."""
    text = f"{float(metres) + 0.0:.3f}".rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


GEOREFERENCED_M = 10_000.0  # coordinates beyond this count from a round origin


def origin_of(xy: np.ndarray) -> XY:
    """The origin the axes count from: (0, 0), or the centre of the points rounded to 100 m
    when they lie farther than :data:`GEOREFERENCED_M` from it (map coordinates)."""
    if not len(xy) or np.abs(xy).max() < GEOREFERENCED_M:
        return 0.0, 0.0
    centre = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
    return float(np.round(centre[0], -2)), float(np.round(centre[1], -2))


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


def font(size: int) -> Any:
    """Pillow's default scalable font at ``size`` final pixels (drawn at :data:`SS` times)."""
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
    face = font(FONT_PX)
    _frame(pen, view, ticks, face, scene.origin)
    for edge in scene.edges:
        _edge(pen, view.px(edge.a), view.px(edge.b), edge.style, edge.residual_cm, scene.top_cm)
    for station in scene.stations:
        _station(pen, view.px(station.xy), station, face)
    for scan in scene.scans:
        if scan.position is not None:
            _scanner(pen, view.px(scan.position), scan, face)
    _axis_labels(image, pen, view, face, scene.origin)
    _title(pen, view, scene.title)
    y = view.area[1]
    if scene.top_cm is not None:
        y = _colour_bar(pen, view, scene.top_cm, face)
    y = _key(pen, view, scene, y + 24 * SS, face)
    _legend(pen, view, scene.scans, y + 10 * SS, face)


def _frame(
    pen: Any, view: View, ticks: tuple[np.ndarray, np.ndarray], face: Any, origin: XY
) -> None:
    left, top, right, bottom = view.area
    pen.rectangle([left, top, right, bottom], outline=INK, width=SS)
    xs, ys = ticks
    for x, (c, _) in zip(xs, view.px(np.column_stack([xs, np.zeros(len(xs))])), strict=True):
        label = tick_label(x - origin[0])
        pen.text((c, bottom + 5 * SS), label, fill=INK, font=face, anchor="mt")
    for y, (_, r) in zip(ys, view.px(np.column_stack([np.zeros(len(ys)), ys])), strict=True):
        pen.text((left - 5 * SS, r), tick_label(y - origin[1]), fill=INK, font=face, anchor="rm")


def _dashes(a: np.ndarray, b: np.ndarray, dash: float) -> list[tuple[np.ndarray, np.ndarray]]:
    n = max(1, int(np.linalg.norm(b - a) / dash))
    t = np.linspace(0.0, 1.0, n + 1)
    return [(a + (b - a) * t[k], a + (b - a) * t[k + 1]) for k in range(0, n, 2)]


def _edge(
    pen: Any, a: np.ndarray, b: np.ndarray, style: EdgeStyle, cm: float, top: float | None
) -> None:
    dashed = {EdgeStyle.REJECTED: REJECTED, EdgeStyle.UNCHECKED: UNCHECKED}
    if style in dashed:
        for p, q in _dashes(a, b, 6.0 * SS):
            pen.line([tuple(p), tuple(q)], fill=dashed[style], width=round(1.5 * SS))
        return
    if style is EdgeStyle.UNUSED:
        pen.line([tuple(a), tuple(b)], fill=UNUSED, width=SS)
        return
    pen.line([tuple(a), tuple(b)], fill=viridis(cm / (top or 1.0)), width=2 * SS)


def _scanner(pen: Any, p: np.ndarray, scan: Scan, face: Any) -> None:
    c, r, s = float(p[0]), float(p[1]), 6.0 * SS
    if scan.status is NodeStatus.OK:
        pen.polygon([(c, r - s), (c - s, r + 0.7 * s), (c + s, r + 0.7 * s)], fill=INK)
    elif scan.status is NodeStatus.SUSPECT:
        pen.rectangle([c - 0.8 * s, r - 0.8 * s, c + 0.8 * s, r + 0.8 * s], fill=SUSPECT)
    else:
        pen.line([(c - s, r - s), (c + s, r + s)], fill=REJECTED, width=SS * 2)
        pen.line([(c - s, r + s), (c + s, r - s)], fill=REJECTED, width=SS * 2)
    label = str(scan.index) if scan.status is NodeStatus.OK else f"{scan.index} {scan.status}"
    pen.text((c + s, r - s), label, fill=INK, font=face, anchor="ld")


def _diamond(pen: Any, c: float, r: float, s: float, colour: str) -> None:
    pen.polygon([(c, r - s), (c + s, r), (c, r + s), (c - s, r)], outline=colour, width=2 * SS)


def _station(pen: Any, p: np.ndarray, station: Station, face: Any) -> None:
    """A control station: a diamond around its given position, green when used, red when not,
    with its name below."""
    c, r, s = float(p[0]), float(p[1]), 10.0 * SS
    colour = STATION if station.used else REJECTED
    _diamond(pen, c, r, s, colour)
    label = station.name if station.used else f"{station.name} rejected"
    pen.text((c, r + s + 2 * SS), label, fill=colour, font=face, anchor="mt")


def _axis_labels(image: Any, pen: Any, view: View, face: Any, origin: XY) -> None:
    from PIL import Image, ImageDraw

    left, top, right, bottom = view.area
    x_text, y_text = (
        (f"x - {tick_label(origin[0])} (m)", f"y - {tick_label(origin[1])} (m)")
        if origin != (0.0, 0.0)
        else ("x world (m)", "y world (m)")
    )
    pen.text(((left + right) / 2, view.size[1] - 8 * SS), x_text, fill=INK, font=face,
             anchor="md")  # fmt: skip
    box = pen.textbbox((0, 0), y_text, font=face)
    label = Image.new("L", (box[2] + 2 * SS, box[3] + 2 * SS), 255)
    ImageDraw.Draw(label).text((SS, SS), y_text, fill=0, font=face)
    label = label.rotate(90, expand=True)
    y = (top + bottom - label.height) // 2
    image.paste((0, 0, 0), (4 * SS, y), label.point(lambda v: 255 - v))


def _title(pen: Any, view: View, lines: tuple[str, ...]) -> None:
    face = font(TITLE_PX)
    left, top, right, _ = view.area
    for k, line in enumerate(reversed(lines)):
        y = top - (8 + TITLE_LINE * k) * SS
        pen.text(((left + right) / 2, y), line, fill=INK, font=face, anchor="md")


def _colour_bar(pen: Any, view: View, top_cm: float, face: Any) -> int:
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
        pen.text((left + width + 7 * SS, y), f"{frac * top_cm:.2g}", fill=INK, font=face,
                 anchor="lm")  # fmt: skip
    pen.text((left, y0 - 30 * SS), "residual of a checked", fill=INK, font=face, anchor="ls")
    pen.text((left, y0 - 14 * SS), "link (cm)", fill=INK, font=face, anchor="ls")
    return y0 + height


def _key(pen: Any, view: View, scene: Scene, y: int, face: Any) -> int:
    """The link styles (those drawn) and the station marker, from row ``y``; returns the
    row below them."""
    left = view.area[2] + 26 * SS
    drawn = {e.style for e in scene.edges}
    words = {
        EdgeStyle.UNCHECKED: "not checked",
        EdgeStyle.REJECTED: "rejected",
        EdgeStyle.UNUSED: "not used",
    }
    for style, word in words.items():
        if style in drawn:
            a, b = np.array([left, y]), np.array([left + 28 * SS, y])
            _edge(pen, a, b, style, 0.0, None)
            pen.text((left + 34 * SS, y), word, fill=INK, font=face, anchor="lm")
            y += 18 * SS
    if scene.stations:
        _diamond(pen, left + 8 * SS, y, 7 * SS, STATION)
        pen.text((left + 34 * SS, y), "control station", fill=INK, font=face, anchor="lm")
        y += 18 * SS
    return y


def _legend(pen: Any, view: View, scans: tuple[Scan, ...], y: int, face: Any) -> None:
    """One coloured dot and name per scan with points, in the right margin from row ``y``."""
    left = view.area[2] + 26 * SS
    for scan in scans:
        if scan.points is None or y > view.size[1] - 20 * SS:
            continue
        r = 4 * SS
        pen.ellipse([left, y - r, left + 2 * r, y + r], fill=rgb(TAB10[scan.index % len(TAB10)]))
        pen.text((left + 3 * r, y), scan.name, fill=INK, font=face, anchor="lm")
        y += 18 * SS
