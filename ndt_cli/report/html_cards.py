"""The link inspector's cards of a campaign: per registration with a transform, its two scans'
slices overlaid (:mod:`ndt_cli.report.inspect`, drawn by :mod:`ndt_cli.report.inspect_png`)
and a caption with its state, residual, strength and the spread of its slices' residuals.

Kept links (confirmed or not checked) are shown; the others (rejected, not used, left out of
the network) are there on demand, the first :data:`MAX_ON_DEMAND` of them drawn. The pictures
are made from the scans' slice samples the run kept (:mod:`ndt_cli.pipeline.samples`): no scan
is read again.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass

from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.pipeline.samples import SliceSample
from ndt_cli.report.html import LinkCard, LinkRow
from ndt_cli.report.inspect import link_view
from ndt_cli.report.inspect_png import inspector_png

KEPT_WORDS = ("confirmed", "not checked")
MAX_ON_DEMAND = 100  # pictures of registrations not kept; beyond, their captions only (a
# picture costs about 60 ms and 7 kB: a campaign of thousands stays a file a browser opens)


CACHED = 4000  # pictures kept between reports (field mode publishes after every scan)


@dataclass(frozen=True)
class Picture:
    """A link's picture (PNG) and, per slice, its height (m), the source's points that match
    and all of them, and the spread of their residuals (cm: median, upper quartile)."""

    png: bytes
    slices: tuple[tuple[float, int, int, tuple[float, float] | None], ...]


_pictures: OrderedDict[str, Picture] = OrderedDict()


def picture(link: Link, target: SliceSample, source: SliceSample) -> Picture:
    """The link's :class:`Picture`. A link is known by its key (its scans' content and the
    configuration), so its picture is the same in every report of a process: it is drawn once
    (``ndt-watch`` publishes a report after every scan)."""
    if link.key and link.key in _pictures:
        _pictures.move_to_end(link.key)
        return _pictures[link.key]
    view = link_view(link.T_target_source, target, source)
    stats = tuple((s.height, s.matched, len(s.source), s.spread_cm()) for s in view.slices)
    found = Picture(inspector_png(view), stats)
    if link.key:
        _pictures[link.key] = found
        while len(_pictures) > CACHED:
            _pictures.popitem(last=False)
    return found


def _lines(row: LinkRow, view: Picture | None) -> tuple[str, ...]:
    """The caption: registration, residual, strength, and each slice's residual spread."""
    if row.residual_cm is not None:
        residual = f"residual {row.residual_cm:.2f} cm, {row.residual_deg:.4f}°"
    else:
        residual = "no residual (no cycle checks it)" if row.state == "not checked" else ""
    first = "; ".join(p for p in (f"{row.kind}, registration {row.status}", residual) if p)
    lines = [first, row.network] if row.network else [first]
    if row.strength_mm is not None:
        parts = [
            f"{name} {'free' if v > 1000 else f'{v:.0f} mm'}"
            for name, v in zip(("along", "across", "up"), row.strength_mm, strict=True)
        ]
        lines.append("strength (1σ): " + ", ".join(parts))
    if view is None:
        lines.append("slices: not kept by this run")
        return tuple(lines)
    for height, matched, points, spread in view.slices:
        how = (
            ""
            if spread is None
            else f"; residual median {spread[0]:.1f} cm, upper quartile {spread[1]:.1f} cm"
        )
        lines.append(f"{height:g} m: {matched} of {points} source points match{how}")
    return tuple(lines)


def _card(result: ChainResult, link: Link, row: LinkRow, draw: bool) -> LinkCard:
    samples = result.samples or {}
    t, s = samples.get(link.target), samples.get(link.source)
    view = None
    if draw and t is not None and s is not None and link.T_target_source is not None:
        view = picture(link, t, s)
    png = None if view is None else view.png
    title = f"{row.target} <- {row.source}"
    lines = _lines(row, view)
    if not draw:
        lines = (*lines[:-1], f"slices not drawn: more than {MAX_ON_DEMAND} links not kept")
    return LinkCard(row.figure, title, row.state, png, lines, row.state in KEPT_WORDS)


def link_cards(
    result: ChainResult, links: Iterable[LinkRow], tried: Iterable[LinkRow]
) -> tuple[LinkCard, ...]:
    """A card per registration with a transform: the network's links (rows in the order of
    ``result.links``), then those tried and left out (``result.tried``)."""
    every = [*result.links, *(t.link for t in result.tried)]
    cards, other = [], 0
    for link, row in zip(every, [*links, *tried], strict=True):
        if link.result is None:
            continue
        other += row.state not in KEPT_WORDS
        cards.append(_card(result, link, row, row.state in KEPT_WORDS or other <= MAX_ON_DEMAND))
    return tuple(cards)
