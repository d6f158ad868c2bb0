"""The link inspector's numbers and picture: two scans' slices overlaid in the target's frame,
the residuals' spread (a point's distance from the target's outline nearby), the zoom, the
slice samples it is drawn from, and a link's strength.

Expected values come from the geometry the tests build (walls at known places, shifts of
known size), not from the code under test.
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from ndt_cli.pipeline.samples import MAX_POINTS, SliceSample, chosen, thinned
from ndt_cli.report.inspect import LinkView, link_view, residuals
from ndt_cli.report.inspect_png import PANEL, SOURCE, TARGET, inspector_png

RNG = np.random.default_rng(3)


def _walls(noise: float = 0.005) -> np.ndarray:
    """A corner of a block seen from the street: a facade 30 m along x at y = 6, a cross wall
    12 m along y at x = 10, 3 cm apart, with ``noise`` m across each wall (a plan, m)."""
    x = np.arange(-15.0, 15.0, 0.03)
    y = np.arange(-6.0, 6.0, 0.03)
    facade = np.column_stack([x, 6.0 + RNG.normal(0.0, noise, len(x))])
    cross = np.column_stack([10.0 + RNG.normal(0.0, noise, len(y)), y])
    return np.vstack([facade, cross])


def _turn(yaw_deg: float, shift: tuple[float, float]) -> np.ndarray:
    """4x4: a turn about z and a shift (m)."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = shift
    return T


def _pair(T_target_source: np.ndarray) -> tuple[SliceSample, SliceSample]:
    """The same walls seen by two scanners: the target's points in its frame, the source's
    in its own (``p_target = T_target_source @ p_source``); two slices alike."""
    wall = _walls()
    inv = np.linalg.inv(T_target_source)
    src = wall @ inv[:2, :2].T + inv[:2, 3]
    src += RNG.normal(0.0, 0.002, src.shape)
    target = SliceSample(np.eye(4), (1.0, 4.0), (wall.astype(np.float32),) * 2)
    source = SliceSample(np.eye(4), (1.0, 4.0), (src.astype(np.float32),) * 2)
    return target, source


def test_a_right_link_has_a_millimetre_spread_and_a_shift_shows_as_its_size():
    T = _turn(37.0, (4.0, -2.5))
    target, source = _pair(T)
    right = link_view(T, target, source)
    median, quartile = right.spread_cm()
    assert median < 1.0 and quartile < 1.5  # the walls' noise, 5 mm
    assert all(s.matched > 0.9 * len(s.source) for s in right.slices)  # every point on a wall
    for shift in (0.02, 0.05, 0.10):  # diagonal: both walls see it, by shift each
        wrong = link_view(_turn(0.0, (shift, shift)) @ T, target, source)
        assert wrong.spread_cm()[0] == pytest.approx(100 * shift, abs=0.5), shift
    far = link_view(_turn(0.0, (0.5, 0.5)) @ T, target, source)
    assert all(s.matched < 0.1 * len(s.source) for s in far.slices)  # off by 70 cm: no match


def test_a_corner_does_not_count_only_points_on_a_line_do():
    target = _walls()
    corner = np.array([[10.0, 6.0], [10.05, 5.95]])  # where the two walls meet
    on_facade = np.array([[0.0, 6.03], [-5.0, 5.98]])  # 3 cm and 2 cm off the facade
    ok, off = residuals(target, np.vstack([corner, on_facade]))
    assert ok.tolist() == [False, False, True, True]
    assert off == pytest.approx([0.03, 0.02], abs=0.006)


def test_the_view_is_zoomed_on_where_the_scans_overlap():
    T = _turn(0.0, (0.0, 0.0))
    target, source = _pair(T)
    far_away = np.column_stack([np.full(50, 400.0), np.linspace(0, 5, 50)]).astype(np.float32)
    target = SliceSample(
        np.eye(4), target.heights, tuple(np.vstack([s, far_away]) for s in target.slices)
    )
    view = link_view(T, target, source)
    x0, y0, side = view.box
    assert x0 < -15.0 and x0 + side > 10.0 and y0 < -6.0 and y0 + side > 6.0  # both walls
    assert side < 40.0  # not the target's stray points 400 m away


def test_the_picture_draws_the_target_blue_the_source_orange_where_they_are():
    T = _turn(20.0, (1.0, 2.0))
    target, source = _pair(T)
    view = link_view(T, target, source)
    png = inspector_png(view)
    assert png.startswith(b"\x89PNG") and len(png) < 60_000
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    assert image.shape[1] > 2 * PANEL and image.shape[0] > PANEL

    def near(colour) -> int:
        return int((np.abs(image - np.array(colour)).max(axis=-1) <= 40).sum())

    assert near(SOURCE) > 500  # the source on top of the target
    shifted = inspector_png(link_view(_turn(0.0, (1.5, 1.5)) @ T, target, source))
    moved = np.asarray(Image.open(io.BytesIO(shifted)).convert("RGB")).astype(int)
    blue = int((np.abs(moved - np.array(TARGET)).max(axis=-1) <= 40).sum())
    assert blue > 2 * max(near(TARGET), 1)  # two outlines: the target's shows beside the other


def test_a_slice_sample_keeps_the_lowest_and_the_middle_slice_thinned_and_capped():
    assert chosen(5) == (0, 2) and chosen(1) == (0,) and chosen(0) == ()
    line = np.column_stack([np.linspace(0.0, 50.0, 200_000), np.zeros(200_000)])
    thin = thinned(line, voxel=0.04)
    assert thin.dtype == np.float32 and len(thin) <= MAX_POINTS
    assert np.ptp(thin[:, 0]) > 49.0  # the whole wall, coarser
    few = thinned(line[:1000], voxel=0.04)  # 0.25 m of wall: 4 cm squares
    assert 6 <= len(few) <= 8


def test_a_link_view_of_a_single_slice_and_of_empty_slices():
    T = np.eye(4)
    empty = SliceSample(np.eye(4), (1.0,), (np.empty((0, 2), np.float32),))
    view = link_view(T, empty, empty)
    assert isinstance(view, LinkView) and view.spread_cm() is None
    assert inspector_png(view).startswith(b"\x89PNG")
