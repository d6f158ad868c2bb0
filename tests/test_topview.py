"""The top view's layout: the figure takes the data's shape, with fixed margins in inches."""

from __future__ import annotations

import numpy as np
import pytest

from ndt_cli.report import topview
from ndt_cli.report.figures import png_bytes

plt = pytest.importorskip("matplotlib.pyplot")


def _drawn(width_m: float, height_m: float, bar: bool) -> tuple:
    """A street of width_m x height_m laid out by the top view; (figure, axes, colour bar, points)."""
    fig = plt.figure(dpi=100)
    ax = fig.add_axes([0.0, 0.0, 1.0, 1.0])
    rng = np.random.default_rng(0)
    xy = rng.uniform([0.0, 0.0], [width_m, height_m], (2000, 2))
    ax.plot(xy[:, 0], xy[:, 1], ".")
    cax = topview._layout(fig, ax, bar, title_lines=1)
    fig.canvas.draw()
    return fig, ax, cax, xy


@pytest.mark.parametrize(("width", "height"), [(40.0, 200.0), (300.0, 30.0), (60.0, 50.0)])
def test_the_plot_area_has_the_data_aspect_and_holds_every_point(width, height):
    fig, ax, cax, xy = _drawn(width, height, bar=True)
    box = ax.get_position()  # figure fractions
    fw, fh = fig.get_size_inches()
    w_in, h_in = box.width * fw, box.height * fh
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    assert (y1 - y0) / (x1 - x0) == pytest.approx(h_in / w_in, rel=1e-6)  # 1 m = 1 m
    assert x0 <= xy[:, 0].min() and xy[:, 0].max() <= x1
    assert y0 <= xy[:, 1].min() and xy[:, 1].max() <= y1
    assert topview._MIN_IN[0] - 1e-9 <= w_in <= topview._MAX_IN[0] + 1e-9
    assert topview._MIN_IN[1] - 1e-9 <= h_in <= topview._MAX_IN[1] + 1e-9
    bar = cax.get_position()
    assert box.x1 < bar.x0 and bar.x1 < 1.0  # the colour bar right of the plot, in the figure
    assert box.x0 > 0.0 and box.y0 > 0.0 and box.y1 < 1.0
    plt.close(fig)


def test_the_image_has_the_figure_size_and_no_colour_bar_without_residuals():
    fig, _, cax, _ = _drawn(40.0, 200.0, bar=False)
    assert cax is None and len(fig.axes) == 1
    fw, fh = fig.get_size_inches()
    png = png_bytes(fig, tight=False)  # not cropped: the whole laid-out figure
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert (width, height) == (round(fw * 100), round(fh * 100))
