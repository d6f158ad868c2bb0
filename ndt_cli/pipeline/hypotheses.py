"""Links with rivals: the network chooses among the poses of its ambiguous links jointly.

A link is *ambiguous* when its registration found rivals: other poses the data cannot tell
from the kept one (:mod:`ndt_cli.ndt.rivals`; a corridor turned by 180 degrees, a pose slid by
a room's width). Such a link confirms nothing by agreeing with others: in a building of right
angles and repeated rooms, wrong poses of several links agree around a cycle as well as right
ones do (a turn by 180 degrees composed around a loop of symmetric rooms is still the
identity). So ambiguous links stay out of the network's consensus
(:func:`~ndt_cli.pipeline.verify.verify`), and every pose of each (the kept one and its
rivals) is a hypothesis judged against the *firm* links, those without rivals:

- **Within a rigid group** (scans the firm links tie together): the one hypothesis whose
  misfit with the group's adjusted poses passes the chi-square test is chosen; none: the link
  is rejected; several: it stays ambiguous.
- **Between two groups**: each hypothesis of each link between them proposes where one group
  lies in the other's frame. A placement is chosen when at least two links agree on it (each
  with one of its poses) and no other placement has as many links, unless the agreeing poses
  have clearly more evidence (the sum of their shares of their links' evidence; clearly: the
  other has less than ``ambiguity`` of it). The groups then join and the search starts over.
- **Around three groups**, each pair joined by one link: a choice of one pose per link that
  closes the triangle joins the three, when no other choice closes it with as much evidence.
- A lone link between two groups on no such cycle is never enough: it leaves the scans beyond
  it suspect, its rivals named.
- A link *only checked* (a probe the plan did not ask for, :mod:`ndt_cli.pipeline.members`)
  is chosen within a group only, never to join groups.

The chosen poses become links of the network like any other; the links left ambiguous do not.
Frames as in :mod:`ndt_cli.pipeline.graph`: nodes' poses in their group's frame.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Iterator, Sequence
from dataclasses import dataclass
from itertools import product

import numpy as np

from ndt_cli.pipeline.graph import Edge, residuals


@dataclass(frozen=True)
class Hypothesis:
    """One pose of an ambiguous link: ``choice`` 0 is the kept pose, k its k-th rival;
    ``edge`` the pose as an edge (target, source, transform, covariance); ``evidence`` its share
    of the kept pose's evidence (1 for the kept pose)."""

    link: int
    choice: int
    edge: Edge
    evidence: float


@dataclass(frozen=True)
class Choice:
    """What the network made of an ambiguous link: the hypothesis chosen (None: none) and
    why; ``rejected``: none of its poses agrees with the links kept."""

    link: int
    chosen: Hypothesis | None
    reason: str
    rejected: bool = False


@dataclass
class _Groups:
    """Rigid groups of nodes and each node's pose in its group's frame."""

    group: list[int]
    pose: list[np.ndarray]

    def members(self, g: int) -> list[int]:
        return [v for v, h in enumerate(self.group) if h == g]

    def join(self, keep: int, other: int, T_keep_other: np.ndarray) -> None:
        for v in self.members(other):
            self.group[v], self.pose[v] = keep, T_keep_other @ self.pose[v]


def _chi2(edge: Edge, pose: Sequence[np.ndarray]) -> float:
    """The edge's misfit against node poses (a list indexed by node)."""
    both: list[np.ndarray | None] = [None] * (max(edge.target, edge.source) + 1)
    both[edge.target], both[edge.source] = pose[edge.target], pose[edge.source]
    return residuals([edge], [0], both)[0].chi2


def choose(
    groups: Sequence[int | None],
    poses: Sequence[np.ndarray | None],
    hypotheses: dict[int, list[Hypothesis]],
    threshold: float,
    ambiguity: float,
    checked_only: Collection[int] = (),
) -> dict[int, Choice]:
    """A :class:`Choice` for every ambiguous link (keys of ``hypotheses``), given the rigid
    group of every node under the firm links (None: on no firm link) and its pose in its
    group's frame (see the module docstring). The links ``checked_only`` are chosen within a
    group only, never to join groups."""
    n = len(groups)
    fresh = iter(range(max((g for g in groups if g is not None), default=-1) + 1, 2 * n + 1))
    state = _Groups(
        [g if g is not None else next(fresh) for g in groups],
        [np.eye(4) if p is None else np.asarray(p, float) for p in poses],
    )
    choices: dict[int, Choice] = {}
    while True:
        pending = {k: h for k, h in hypotheses.items() if k not in choices}
        choices.update(_within(state, pending, threshold))
        pending = {k: h for k, h in pending.items() if k not in choices and k not in checked_only}
        joined = _join_best(state, pending, threshold, ambiguity)
        if not joined:
            joined = _close_triangle(state, pending, threshold, ambiguity)
        if not joined:
            break
        choices.update(joined)
    for k, hyps in hypotheses.items():
        if k not in choices:
            choices[k] = Choice(k, None, _unchosen(hyps))
    return choices


def _unchosen(hyps: list[Hypothesis]) -> str:
    """Why a link was not chosen: its poses tied, or (a link with its kept pose alone) no
    other link agreed with where it puts its scans."""
    if len(hyps) == 1:
        return "not chosen: no other link agrees with where it puts its scans"
    rivals = "; ".join(f"pose {h.choice}" for h in hyps[1:])
    return f"ambiguous: the network could not choose ({rivals})"


def _within(state: _Groups, pending: dict[int, list[Hypothesis]], threshold: float) -> dict:
    """Choices of the links whose two scans lie in one group."""
    out = {}
    for k, hyps in pending.items():
        e = hyps[0].edge
        if state.group[e.target] != state.group[e.source]:
            continue
        fits = [h for h in hyps if _chi2(h.edge, state.pose) <= threshold]
        if len(fits) == 1:
            why = "" if fits[0].choice == 0 else f"its rival {fits[0].choice}, not its kept pose, "
            out[k] = Choice(k, fits[0], f"{why}agrees with the links that tie its scans")
        elif not fits:
            out[k] = Choice(k, None, "none of its poses agrees with the links kept", True)
        else:
            out[k] = Choice(k, None, "ambiguous: several of its poses agree with the links kept")
    return out


@dataclass(frozen=True)
class _Placement:
    """Where group ``b`` lies in group ``a``'s frame, the hypotheses (one per link) that agree
    on it, and their summed evidence."""

    a: int
    b: int
    T_a_b: np.ndarray
    members: tuple[Hypothesis, ...]
    evidence: float


def _placements(state: _Groups, hyps: list[Hypothesis], threshold: float) -> list[_Placement]:
    """Every placement that one of ``hyps`` (links between the same two groups) proposes, with
    the hypotheses of the other links that agree with it."""
    e0 = hyps[0].edge
    a, b = sorted((state.group[e0.target], state.group[e0.source]))
    out = []
    for h in hyps:
        T_a_b = _proposal(state, h.edge, a)
        agree: dict[int, Hypothesis] = {}
        for other in hyps:
            moved = _moved(state, b, T_a_b)
            if _chi2(other.edge, moved) <= threshold:
                best = agree.get(other.link)
                if best is None or other.evidence > best.evidence:
                    agree[other.link] = other
        members = tuple(agree.values())
        out.append(_Placement(a, b, T_a_b, members, sum(m.evidence for m in members)))
    return out


def _proposal(state: _Groups, edge: Edge, a: int) -> np.ndarray:
    """``T_a_b``: the pose of the source's or target's group in group ``a``'s frame that the
    edge implies (its other node's group is ``b``)."""
    P_t, P_s = state.pose[edge.target], state.pose[edge.source]
    if state.group[edge.target] == a:  # source in b: P_t @ T = T_a_b @ P_s
        return P_t @ edge.T_target_source @ np.linalg.inv(P_s)
    return P_s @ np.linalg.inv(edge.T_target_source) @ np.linalg.inv(P_t)


def _moved(state: _Groups, b: int, T_a_b: np.ndarray) -> list[np.ndarray]:
    """Node poses with group ``b`` placed in group ``a``'s frame."""
    return [T_a_b @ p if g == b else p for p, g in zip(state.pose, state.group, strict=True)]


def _join_best(
    state: _Groups, pending: dict[int, list[Hypothesis]], threshold: float, ambiguity: float
) -> dict[int, Choice]:
    """Join the two groups whose placement is best supported, if one is clear; returns the
    choices of the links that support it (empty: no join)."""
    by_pair: dict[tuple[int, int], list[Hypothesis]] = {}
    for hyps in pending.values():
        e = hyps[0].edge
        pair = tuple(sorted((state.group[e.target], state.group[e.source])))
        by_pair.setdefault(pair, []).extend(hyps)
    clear = [p for hyps in by_pair.values() if (p := _clear(state, hyps, threshold, ambiguity))]
    if not clear:
        return {}
    best = max(clear, key=lambda p: (len(p.members), p.evidence))
    state.join(best.a, best.b, best.T_a_b)
    n = len(best.members)
    return {
        h.link: Choice(h.link, h, f"one of {n} links that agree where it puts its scans' groups")
        for h in best.members
    }


def _clear(
    state: _Groups, hyps: list[Hypothesis], threshold: float, ambiguity: float
) -> _Placement | None:
    """The placement of two groups that at least two links agree on and no other placement
    rivals (see the module docstring); None when there is none."""
    found = sorted(_placements(state, hyps, threshold), key=lambda p: (len(p.members), p.evidence))
    best = found[-1]
    if len(best.members) < 2:
        return None
    for other in found[:-1]:
        same = {h.link: h.choice for h in other.members} == {h.link: h.choice for h in best.members}
        if same:
            continue
        if len(other.members) == len(best.members) and other.evidence >= ambiguity * best.evidence:
            return None
    return best


def _close_triangle(
    state: _Groups, pending: dict[int, list[Hypothesis]], threshold: float, ambiguity: float
) -> dict[int, Choice]:
    """Join three groups that links join pairwise around a triangle, where one choice of a
    pose per link closes it and no other choice does with as much evidence; returns the
    choices (empty: no triangle closes clearly)."""
    by_pair: dict[tuple[int, int], list[int]] = {}
    for k, hyps in pending.items():
        e = hyps[0].edge
        pair = tuple(sorted((state.group[e.target], state.group[e.source])))
        by_pair.setdefault(pair, []).append(k)
    for a, b, c in triangles(by_pair):
        sides = [by_pair[p] for p in ((a, b), (b, c), (a, c))]
        found = _closing(state, [pending[s[0]] for s in sides], (a, b, c), threshold)
        if found and _clearly_best(found, ambiguity):
            best = found[0][1]
            state.join(a, b, _proposal(state, best[0].edge, a))
            state.join(a, c, _proposal(state, best[2].edge, a))
            return {
                h.link: Choice(h.link, h, "one of 3 links whose poses close a cycle") for h in best
            }
    return {}


def triangles(pairs: Iterable[tuple[int, int]]) -> Iterator[tuple[int, int, int]]:
    """The triangles (a < b < c) whose three sides are among ``pairs`` (each (lo, hi)), in
    lexicographic order: the order of ``itertools.combinations`` over the groups, in time
    proportional to the pairs times the groups' neighbours instead of the groups cubed (a
    campaign given out of order can start hundreds of groups)."""
    after: dict[int, set[int]] = {}
    for lo, hi in pairs:
        if lo < hi:  # a link within one group closes no triangle
            after.setdefault(lo, set()).add(hi)
    for a in sorted(after):
        for b in sorted(after[a]):
            for c in sorted(after[a] & after.get(b, set())):
                yield a, b, c


def _closing(
    state: _Groups,
    sides: list[list[Hypothesis]],
    groups: tuple[int, int, int],
    threshold: float,
) -> list[tuple[float, tuple[Hypothesis, ...]]]:
    """Every choice of one hypothesis per side (a-b, b-c, a-c) that closes the triangle, with
    its summed evidence, most evidence first."""
    a, b, c = groups
    out = []
    for h_ab, h_bc, h_ac in product(*sides):
        T_ab = _proposal(state, h_ab.edge, a)
        T_ac = _proposal(state, h_ac.edge, a)
        moved = [
            T_ab @ p if g == b else T_ac @ p if g == c else p
            for p, g in zip(state.pose, state.group, strict=True)
        ]
        if _chi2(h_bc.edge, moved) <= threshold:
            out.append((h_ab.evidence + h_bc.evidence + h_ac.evidence, (h_ab, h_bc, h_ac)))
    return sorted(out, key=lambda x: -x[0])


def _clearly_best(found: list[tuple[float, tuple[Hypothesis, ...]]], ambiguity: float) -> bool:
    """The first closing choice has no rival: no other closes with ``ambiguity`` of its
    evidence."""
    return len(found) == 1 or found[1][0] < ambiguity * found[0][0]
