"""Neighbours along the walk past a scan that tied in nothing: a room scanned between two
corridor standpoints and seen only through its door registers to neither, and the corridor
scans either side of it were taken one after the other as far as the corridor goes. Indoors
(only the walk's bridges trusted) the link between them then ties a scan in on its gate's
word, as a link between scans taken one after the other does; past a scan that is tied in,
or past two, it does not."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from test_hypotheses import _pose, _registered

from ndt_cli.core.transforms import transform_errors
from ndt_cli.ndt.result import Status
from ndt_cli.pipeline.members import network_links, walk_pairs
from ndt_cli.pipeline.network import Bridges, LinkKind
from ndt_cli.pipeline.solution import solve
from ndt_cli.pipeline.verify import NodeStatus
from ndt_cli.pipeline.walk import Walk

# corridor scans 0, 1, 3 and 4, 8 m apart; scan 2 in a room beside the corridor
TRUE = [_pose(0, 0, 0), _pose(8, 1, 30), _pose(11, 6, 75), _pose(16, -1, 100), _pose(24, 0, 200)]
HESS = {"hessian": np.diag([1e4, 1e4, 1e6])}


def _walk(n: int, order: list[int] | None = None) -> Walk:
    walk = Walk()
    walk.add([None] * n)
    walk.order = order or list(range(n))
    return walk


def _link(i: int, j: int, status: Status = Status.OK):
    """A link from i to j: right when ok, 3 m and 180 degrees off otherwise (a wrong pose its
    gate doubted)."""
    T = np.linalg.inv(TRUE[i]) @ TRUE[j]
    if status is not Status.OK:
        T = T @ _pose(3, 0, 180)
    return replace(_registered(status, T_target_source=T, **HESS), target=i, source=j)


def test_the_walk_passes_one_scan_set_aside_and_no_more():
    walk = _walk(6)
    assert walk.neighbours() == walk.adjacent == {(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)}
    assert walk.neighbours({2}) - walk.adjacent == {(1, 3)}
    assert walk.neighbours({2, 3}) == walk.adjacent  # two in a row: no pair past them
    assert walk.neighbours({0, 5}) == walk.adjacent  # at the ends there is no scan beyond
    assert walk.neighbours({1, 3}) - walk.adjacent == {(0, 2), (2, 4)}
    shuffled = _walk(4, order=[3, 0, 2, 1])  # the walk's order, not the indices'
    assert shuffled.neighbours({0}) - shuffled.adjacent == {(2, 3)}


def test_only_a_scan_no_ok_link_touches_is_passed():
    walk = _walk(5)
    corridor = {(0, 1): _link(0, 1), (3, 4): _link(3, 4)}
    assert walk_pairs(walk, corridor, 5)[(1, 3)] is LinkKind.PAST  # 2 registered to nothing
    assert walk_pairs(walk, corridor, 5)[(0, 1)] is LinkKind.ADJACENT
    lonely = {**corridor, (1, 2): _link(1, 2, Status.SUSPECT), (2, 3): _link(2, 3, Status.FAILED)}
    assert (1, 3) in walk_pairs(walk, lonely, 5)
    tied = {**lonely, (2, 4): _link(2, 4)}  # the room scan tied in elsewhere
    assert (1, 3) not in walk_pairs(walk, tied, 5)
    assert (1, 3) not in walk_pairs(walk, {(0, 1): _link(0, 1)}, 5)  # scan 3 tied in neither


def _campaign_links(room_tied: bool) -> list:
    """The corridor 0-1, 1-3, 3-4 ok (bridges: no cycle), the room scan 2 registered wrong
    to both neighbours (suspect), or right to scan 1 (ok) when ``room_tied``."""
    registered = {
        (0, 1): _link(0, 1),
        (1, 2): _link(1, 2, Status.OK if room_tied else Status.SUSPECT),
        (2, 3): _link(2, 3, Status.SUSPECT),
        (1, 3): _link(1, 3),
        (3, 4): _link(3, 4),
    }
    walk = _walk(5)
    return network_links(registered, set(registered), set(), walk_pairs(walk, registered, 5))


def test_indoors_the_corridor_past_an_untied_room_scan_is_ok_and_right():
    members = _campaign_links(room_tied=False)
    kinds = {(k.target, k.source): k.kind for k in members.links}
    assert kinds[(1, 3)] is LinkKind.PAST and members.walk[(1, 3)] is LinkKind.PAST
    assert kinds[(0, 1)] is kinds[(3, 4)] is LinkKind.ADJACENT
    solution = solve(5, 0, members.links, True, {}, bridges=Bridges.WALK)
    statuses = [s.status for s in solution.scans]
    assert statuses == [NodeStatus.OK, NodeStatus.OK, statuses[2], NodeStatus.OK, NodeStatus.OK]
    assert statuses[2] is not NodeStatus.OK  # the room: only wrong links its gates doubted
    assert [solution.scans[k].cluster for k in (0, 1, 3, 4)] == [0, 0, 0, 0]
    for k in (1, 3, 4):
        rot, trans = transform_errors(solution.scans[k].T_world_scan, TRUE[k])
        assert rot < 1e-6 and trans < 1e-6, (k, rot, trans)


def test_past_a_room_scan_tied_in_the_corridor_link_is_no_walk_link():
    """Scan 2 is tied to scan 1: the walk's next standpoint after 1 is 2, so the link 1-3 is a
    found bridge, and indoors it ties nothing in on its gate's word: scans 3 and 4 stand
    apart, in a cluster of their own (the walk's link 3-4)."""
    members = _campaign_links(room_tied=True)
    kinds = {(k.target, k.source): k.kind for k in members.links}
    assert kinds[(1, 3)] is LinkKind.FOUND
    solution = solve(5, 0, members.links, True, {}, bridges=Bridges.WALK)
    assert [s.cluster for s in solution.scans] == [0, 0, 0, 1, 1]
    assert solution.scans[2].status is NodeStatus.OK  # its walk neighbour's ok link
