"""The top view (a plan view drawn with Pillow): one scale in x and y, y up, every element where
the world puts it. Expected pixels come from the layout's own arithmetic checked against world
distances, and expected colours from the published colour tables."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from ndt_cli.pipeline.verify import NodeStatus
from ndt_cli.report.planview import (
    GRID,
    PLOT_MAX,
    PLOT_MIN,
    REJECTED,
    SS,
    STATION,
    TAB10,
    UNCHECKED,
    VIRIDIS,
    Edge,
    EdgeStyle,
    Scan,
    Scene,
    Station,
    nice_step,
    origin_of,
    render,
    rgb,
    tick_label,
    view_of,
    viridis,
)


def _block(centre: tuple[float, float], half: float = 1.5, step: float = 0.05) -> np.ndarray:
    """A filled square of points (m): its colour survives the reduction to the final size."""
    g = np.arange(-half, half + 1e-9, step)
    x, y = np.meshgrid(g, g)
    return np.column_stack([x.ravel() + centre[0], y.ravel() + centre[1]])


def _street(width: float, length: float) -> Scene:
    """Two scans: points along both sides of a street, and a block of points at known spots."""
    t = np.linspace(0.0, length, 400)
    sides = np.concatenate([np.column_stack([np.zeros_like(t), t]), [[width, 0.0]]])
    a = Scan(
        "a", 0, NodeStatus.OK, np.array([width / 2, 10.0]), np.vstack([sides, _block((8, 30))])
    )
    b = Scan("b", 1, NodeStatus.SUSPECT, np.array([width / 2, length - 10.0]), _block((8, 60)))
    edges = (
        Edge(a.position, b.position, EdgeStyle.RESIDUAL, 2.0),
        Edge(np.array([30.0, 40.0]), np.array([30.0, 80.0]), EdgeStyle.REJECTED),
    )
    return Scene((a, b), edges, 2.0, ("title",))


def _pixels(scene: Scene) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(render(scene))).convert("RGB")).astype(int)


def _at(pixels: np.ndarray, scene: Scene, xy: tuple[float, float]) -> np.ndarray:
    """The final image's pixel at world ``xy`` (m)."""
    c, r = view_of(scene, SS).px(np.array(xy)) / SS
    return pixels[int(r), int(c)]


@pytest.mark.parametrize(("width", "length"), [(40.0, 200.0), (300.0, 30.0), (60.0, 50.0)])
def test_one_scale_in_x_and_y_y_up_and_every_point_in_the_plot_area(width, length):
    scene = _street(width, length)
    view = view_of(scene)
    p0, px, py = view.px(np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]))
    assert px[0] - p0[0] == pytest.approx(p0[1] - py[1])  # 10 m east = 10 m north, in pixels
    assert px[1] == pytest.approx(p0[1]) and py[0] == pytest.approx(p0[0])
    assert py[1] < p0[1]  # north is up
    left, top, right, bottom = view.area
    assert PLOT_MIN[0] <= right - left <= PLOT_MAX[0] and PLOT_MIN[1] <= bottom - top <= PLOT_MAX[1]
    for scan in scene.scans:
        c, r = view.px(scan.points).T
        assert (c > left).all() and (c < right).all() and (r > top).all() and (r < bottom).all()
    assert view.world(*view.px(np.array([12.5, -3.0]))) == pytest.approx((12.5, -3.0))


def test_points_links_and_scanners_are_drawn_where_the_world_puts_them():
    scene = _street(40.0, 200.0)
    pixels = _pixels(scene)
    assert pixels.shape[:2] == (view_of(scene).size[1], view_of(scene).size[0])
    assert np.abs(_at(pixels, scene, (8.0, 30.0)) - rgb(TAB10[0])).max() <= 2  # scan a's block
    assert np.abs(_at(pixels, scene, (8.0, 60.0)) - rgb(TAB10[1])).max() <= 2  # scan b's block
    assert (_at(pixels, scene, (30.0, 150.0)) == 255).all()  # nothing there: white
    mid = (20.0, 100.0)  # the residual link at the top of the colour scale: yellow
    assert np.abs(_at(pixels, scene, mid) - rgb(VIRIDIS[-1])).max() <= 40
    red = [_at(pixels, scene, (30.0, y)) for y in np.arange(40.5, 80.0, 0.5)]
    assert sum(np.abs(p - rgb("d62728")).max() <= 60 for p in red) >= 10  # dashed, red
    assert sum((p == 255).all() for p in red) >= 10  # ... with gaps
    tri = _at(pixels, scene, (20.0, 10.0 - 0.5 * 200.0 / 860))  # inside the ok scanner's marker
    assert tri.max() <= 60  # black
    sq = _at(pixels, scene, (20.0, 190.0))  # the suspect scanner: an orange square
    assert np.abs(sq - rgb("ff8c00")).max() <= 40


def test_colour_tables_and_grid_steps():
    assert viridis(0.0) == rgb(VIRIDIS[0]) and viridis(1.0) == rgb(VIRIDIS[-1])
    assert viridis(-1.0) == rgb(VIRIDIS[0]) and viridis(2.0) == rgb(VIRIDIS[-1])
    half = (np.array(rgb(VIRIDIS[4])) + np.array(rgb(VIRIDIS[5]))) / 2  # 0.5 lies between stops
    assert np.abs(np.array(viridis(0.5)) - half).max() <= 0.5
    assert nice_step(230.0) == 50.0  # 38 m wanted: 50 is nearer than 20
    assert nice_step(60.0) == 10.0
    assert nice_step(1.3) == 0.2
    assert nice_step(7000.0) == 1000.0
    zero = np.ceil(-10.0 / 20.0) * 20.0  # the first grid line of a view from x = -10 m
    assert f"{zero:g}" == "-0"  # negative zero: plain formatting would print it
    assert [tick_label(v) for v in (zero, -40.0, 2.5, 1e4)] == ["0", "-40", "2.5", "10000"]


def test_grid_lines_at_round_world_coordinates():
    scene = _street(40.0, 200.0)
    view = view_of(scene, SS)
    (x0, y1), (x1, y0) = view.world(*view.area[:2]), view.world(*view.area[2:])
    step = nice_step(max(x1 - x0, y1 - y0))
    lines = np.arange(np.ceil(x0 / step), np.floor(x1 / step) + 1) * step
    free = [x for x in lines if abs(x) > 5.0 and abs(x - 20.0) > 5.0 and abs(x - 30.0) > 5.0]
    assert free  # lines away from the street's points, scanners and links
    pixels = _pixels(scene)
    for x in free:
        assert np.abs(_at(pixels, scene, (x, 170.0)) - rgb(GRID)).max() <= 24
        assert (_at(pixels, scene, (x + step / 2, 170.0)) == 255).all()  # between lines: white


def test_map_coordinates_count_from_a_round_origin_and_never_read_in_exponents():
    utm = np.array([[500_123.4, 5_800_117.0], [500_268.0, 5_800_402.5]])
    assert origin_of(utm) == (500_200.0, 5_800_300.0)  # the centre, rounded to 100 m
    assert origin_of(np.array([[-40.0, 3.0], [120.0, 80.0]])) == (0.0, 0.0)  # a local frame
    assert [tick_label(v) for v in (5_800_100.0, 12_000.0, -0.0001)] == ["5800100", "12000", "0"]
    assert "e+" not in tick_label(5.8001e6)


def _w(dx: float, dy: float) -> np.ndarray:
    """World (x, y) m of a point ``dx``, ``dy`` m from 500000, 5800000 (map coordinates)."""
    return np.array([500_000.0 + dx, 5_800_000.0 + dy])


def _georeferenced() -> Scene:
    """A street in UTM-like numbers: two scans, an unchecked link, two control stations (the
    second rejected)."""
    o = np.array([500_000.0, 5_800_000.0])
    a = Scan("a", 0, NodeStatus.OK, _w(10.0, 10.0), _block(tuple(_w(30.0, 10.0))))
    b = Scan("b", 1, NodeStatus.OK, _w(10.0, 90.0), _block(tuple(_w(30.0, 90.0))))
    edges = (Edge(a.position, b.position, EdgeStyle.UNCHECKED),)
    stations = (Station("a", _w(10.0, 10.0), True), Station("b", _w(60.0, 90.0), False))
    return Scene((a, b), edges, None, ("title",), origin_of(o + np.array([[0, 0], [60, 90]])),
                 stations)  # fmt: skip


def _near(pixels: np.ndarray, scene: Scene, xy, colour: str, reach: int = 2) -> bool:
    """A pixel of ``colour`` within ``reach`` px of world ``xy`` (lines are 1-2 px wide)."""
    c, r = (view_of(scene, SS).px(np.array(xy)) / SS).astype(int)
    patch = pixels[r - reach : r + reach + 1, c - reach : c + reach + 1]
    return bool((np.abs(patch - rgb(colour)).max(axis=-1) <= 40).any())


def test_stations_and_unchecked_links_are_drawn_where_the_world_puts_them():
    scene = _georeferenced()
    pixels = _pixels(scene)
    s = 10.0 / view_of(scene).scale  # m: the diamond's half-diagonal (10 px)
    assert _near(pixels, scene, _w(60.0 + s / 2, 90.0 - s / 2), REJECTED)  # its outline
    assert not _near(pixels, scene, _w(60.0, 90.0), REJECTED)  # a diamond: hollow
    assert _near(pixels, scene, _w(10.0 - s / 2, 10.0 - s / 2), STATION)  # the used one
    dashes = [_at(pixels, scene, tuple(_w(10.0, y))) for y in np.arange(25.0, 75.0, 0.25)]
    blue = sum(np.abs(p - rgb(UNCHECKED)).max() <= 60 for p in dashes)
    light = sum(p.min() > 200 for p in dashes)  # the gaps (and their soft edges)
    assert blue >= 10 and light >= 10  # dashed slate blue, never a solid green line
