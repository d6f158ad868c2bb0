"""Coarse matches of many pairs of scans at once, on a campaign's executor.

Placing scans out of campaign order ranks every pair of scans by its coarse match
(:func:`ndt_cli.ndt.overlap.coarse_match`, about 30 ms each for a sparse scan): 8,128 pairs for
128 scans. They are computed in batches on the executor's workers, idle meanwhile, instead of
one after another in the command's process. A batch that fails (its worker died) is computed
here. A match is the same wherever it is computed.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import replace
from functools import partial

from numpy.linalg import inv

from ndt_cli.ndt.overlap import CoarseMatch, Sketch, coarse_match
from ndt_cli.pipeline.executors import Executor
from ndt_cli.pipeline.network import Pair, pair_of
from ndt_cli.pipeline.workers import Failure

BATCH_PAIRS = 32  # pairs per task: about a second of work, against milliseconds of shipping
PARTNERS = 2  # best coarse matches a scan placed out of order is registered to (a street's two
# neighbours; its other neighbours come with the network's plan, by position)


def match_batch(pairs: Sequence[tuple[Sketch, Sketch]]) -> list[CoarseMatch]:
    """The coarse match of each (target, source) pair of sketches (a task)."""
    return [coarse_match(target, source) for target, source in pairs]


def keyed(match: CoarseMatch, target: int, source: int) -> tuple[Pair, CoarseMatch]:
    """The match of ``source`` on ``target`` as the campaign keeps it: by the pair (lo, hi),
    as the pose of ``hi`` on ``lo``."""
    if target < source:
        return (target, source), match
    return (source, target), replace(match, T_target_source=inv(match.T_target_source))


def match_pairs(
    executor: Executor, sketches: Mapping[int, Sketch], pairs: Iterable[tuple[int, int]]
) -> dict[Pair, CoarseMatch]:
    """The coarse match of each pair (target, source) of scans, in batches of
    :data:`BATCH_PAIRS` on ``executor``, kept by pair (:func:`keyed`). The caller chooses
    each pair's target: the search is not symmetric, its pose differs by up to a pixel."""
    todo = sorted(set(pairs))
    chunks = [todo[k : k + BATCH_PAIRS] for k in range(0, len(todo), BATCH_PAIRS)]
    tasks = {
        n: partial(match_batch, [(sketches[a], sketches[b]) for a, b in chunk])
        for n, chunk in enumerate(chunks)
    }
    found: dict[Pair, CoarseMatch] = {}
    for n, value in executor.run(tasks):
        if isinstance(value, Failure):
            value = tasks[n]()
        found.update(keyed(m, a, b) for (a, b), m in zip(chunks[n], value, strict=True))
    return found


def seen_from(matches: Mapping[Pair, CoarseMatch], a: int, b: int) -> CoarseMatch:
    """The match of scans ``a`` and ``b`` kept in ``matches`` (by (lo, hi)), as the pose of
    ``b`` on ``a``."""
    m = matches[pair_of(a, b)]
    return m if a < b else replace(m, T_target_source=inv(m.T_target_source))


def partners(
    matches: Mapping[Pair, CoarseMatch], scan: int, others: Iterable[int], k: int = PARTNERS
) -> list[int]:
    """The ``k`` of ``others`` whose coarse match with ``scan`` (in ``matches``, keyed by
    (lo, hi)) scores highest; ties: the lowest index."""
    score = {o: matches[pair_of(scan, o)].score for o in others}
    return sorted(score, key=lambda o: (-score[o], o))[:k]
