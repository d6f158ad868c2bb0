"""Which registrations of a campaign are links of its network, and how far the network may
use each.

A campaign registers more pairs than its plan asks for: placement probes scans against each
other before it knows where they are (:mod:`ndt_cli.pipeline.discovery`). Such a probe is
evidence too. One its gate passed argues against a placement built on wrong links; a firm one
(no rivals) that its gate doubted can still be confirmed by a cycle. So both are links of the
network (:func:`network_links`).

A probe with rivals (:func:`~ndt_cli.pipeline.link_use.contested`) is a link of the network
too, but only to be *checked*: the network may choose one of its poses where the firm links
already tie its two scans together (a cycle checks it), never let it join two groups. Two
groups join where two ambiguous links agree on one placement; the probes of a symmetric
corridor, tried between scans 30 m apart, agree turned by 180 degrees as well as the truth
does, and joined a closed corridor's far end, turned, to its anchor. On an office floor the
same probes closed the cycle that made three scans ok: a right link between corridor
neighbours, a rival 0.5 m along the corridor at 0.53 of its evidence, which the plan had not
paired.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field, replace

from ndt_cli.pipeline.link_use import (
    contested,
    determined,
    doubted_only_for_evidence,
    kept_share,
)
from ndt_cli.pipeline.links import Link
from ndt_cli.pipeline.network import LinkKind, Pair, classic_chain, kind_of
from ndt_cli.pipeline.walk import Walk


@dataclass(frozen=True)
class Members:
    """The links of a network, indexed 0, 1, ... in the order of their pairs, the indices of
    those the network may only check (never join groups by), and the pairs it took for
    neighbours along the walk, each with its kind (adjacent or past a scan)."""

    links: list[Link]
    checked_only: frozenset[int]
    walk: Mapping[Pair, LinkKind] = field(default_factory=dict)


def network_links(
    registered: Mapping[Pair, Link],
    plan: Collection[Pair],
    user: Collection[Pair],
    walk: Mapping[Pair, LinkKind],
    classic: tuple[int, Collection[int]] | None = None,
    weak: float = 0.0,
    vouch: tuple[float, float] = (0.0, 0.0),
) -> Members:
    """The links of the network among the ``registered`` ones (by pair): the ``plan``, the
    ``user``'s pairs, every link its gate passed, every firm link determined in every
    direction (:func:`~ndt_cli.pipeline.link_use.determined`), those tried for scans no ok
    link connects (so that the outputs say why), and, to be checked only, every other link
    with rivals. ``classic``: (number of scans, unreadable scans) for the classic chain, whose
    network is the chain in the order given and the user's pairs. ``walk``: neighbours
    along the walk and their kinds (:func:`walk_pairs`). A link kept with less than
    ``weak`` of the most evidence of its candidates (a pose the free space refuted had more)
    is only checked too (``quality.weak_links_join`` false: ``quality.min_kept_evidence``),
    unless it is *vouched*: a link between neighbours along the walk that its gate doubted
    only for that evidence, its free space clear (``vouch``: ``quality.min_kept_evidence`` and
    ``quality.walk_vouch_free_space``, the second 0 out of walking order; see
    :func:`~ndt_cli.pipeline.link_use.doubted_only_for_evidence`); the network trusts a
    vouched link as if its gate had passed it."""
    if classic is not None:
        pairs = {k.pair for k in classic_chain(*classic)} | set(user)
        checked: set[Pair] = set()
    else:
        linked = {i for p, k in registered.items() if k.ok for i in p}
        lonely = {p for p in registered if not set(p) & linked}
        sure = {p for p, k in registered.items() if k.ok or determined(k)}
        pairs = set(plan) | set(user) | lonely | sure
        checked = {p for p, k in registered.items() if contested(k)} - pairs
        pairs |= checked
        checked |= {p for p in pairs if p in registered and kept_share(registered[p]) < weak}
    chosen = sorted(p for p in pairs if p in registered)
    links = [_member(registered[p], n, kind_of(p, user, walk), vouch) for n, p in enumerate(chosen)]
    only = frozenset(n for n, p in enumerate(chosen) if p in checked and not links[n].vouched)
    return Members(links, only, dict(walk))


def _member(link: Link, index: int, kind: LinkKind, vouch: tuple[float, float]) -> Link:
    """The registered ``link`` as the network's ``index``-th, of ``kind``, vouched or not."""
    vouched = kind.walked and doubted_only_for_evidence(link, *vouch)
    return replace(link, index=index, kind=kind, vouched=vouched)


def walk_pairs(walk: Walk, registered: Mapping[Pair, Link], n_scans: int) -> dict[Pair, LinkKind]:
    """The pairs of scans that are neighbours along the ``walk`` and their kinds: adjacent,
    or past a scan that no ``registered`` link its gate passed touches (a room scan seen only
    through its door and tied to neither corridor scan beside it leaves those two neighbours,
    as taken one after the other; :meth:`~ndt_cli.pipeline.walk.Walk.neighbours`)."""
    tied = {s for pair, link in registered.items() if link.ok for s in pair}
    adjacent = walk.adjacent
    pairs = walk.neighbours(set(range(n_scans)) - tied)
    return {p: LinkKind.ADJACENT if p in adjacent else LinkKind.PAST for p in sorted(pairs)}
