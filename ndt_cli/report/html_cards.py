"""The link inspector's cards of a campaign: per registration with a transform, its two scans'
slices overlaid (:mod:`ndt_cli.report.inspect`, drawn by :mod:`ndt_cli.report.inspect_png`)
and a caption with its state, residual, strength and the spread of its slices' residuals.

Kept links (confirmed or not checked) are shown; the others (rejected, not used, left out of
the network) are there on demand, the first :data:`MAX_ON_DEMAND` of them drawn. The pictures
are made from the scans' slice samples the run kept (:mod:`ndt_cli.pipeline.samples`): no scan
is read again.
"""

from __future__ import annotations

from collections.abc import Iterable

from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.result import ChainResult
from ndt_cli.report.html import LinkCard, LinkRow
from ndt_cli.report.inspect import LinkView, link_view
from ndt_cli.report.inspect_png import inspector_png

KEPT_WORDS = ("confirmed", "not checked")
MAX_ON_DEMAND = 100  # pictures of registrations not kept; beyond, their captions only (a
# picture costs about 60 ms and 7 kB: a campaign of thousands stays a file a browser opens)


def _lines(row: LinkRow, view: LinkView | None) -> tuple[str, ...]:
    """The caption: registration, residual, strength, and each slice's residual spread."""
    if row.residual_cm is not None:
        residual = f"residual {row.residual_cm:.2f} cm, {row.residual_deg:.4f}°"
    else:
        residual = "no residual (no cycle checks it)" if row.state == "not checked" else ""
    first = "; ".join(p for p in (f"{row.kind}, registration {row.status}", residual) if p)
    lines = [first]
    if row.strength_mm is not None:
        parts = [
            f"{name} {'free' if v > 1000 else f'{v:.0f} mm'}"
            for name, v in zip(("along", "across", "up"), row.strength_mm, strict=True)
        ]
        lines.append("strength (1σ): " + ", ".join(parts))
    if view is None:
        lines.append("slices: not kept by this run")
        return tuple(lines)
    for s in view.slices:
        spread = s.spread_cm()
        matched = f"{s.matched} of {len(s.source)} source points match"
        how = (
            ""
            if spread is None
            else f"; residual median {spread[0]:.1f} cm, upper quartile {spread[1]:.1f} cm"
        )
        lines.append(f"{s.height:g} m: {matched}{how}")
    return tuple(lines)


def _card(result: ChainResult, link: Link, row: LinkRow, draw: bool) -> LinkCard:
    samples = result.samples or {}
    t, s = samples.get(link.target), samples.get(link.source)
    view = None
    if draw and t is not None and s is not None and link.T_target_source is not None:
        view = link_view(link.T_target_source, t, s)
    png = None if view is None else inspector_png(view)
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
