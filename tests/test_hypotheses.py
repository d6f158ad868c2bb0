"""The network's choice among the poses of ambiguous links: poses and groups built by hand, the
expected choice worked out from them."""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations

import numpy as np

from ndt_cli.pipeline.graph import CHI2_6_999, Edge
from ndt_cli.pipeline.hypotheses import Hypothesis, choose, triangles

COV = np.diag([1e-6] * 3 + [1e-4] * 3)  # 0.06 deg, 1 cm


def _pose(x: float, y: float, yaw_deg: float) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:2, 3] = x, y
    return T


TRUE = [_pose(0, 0, 0), _pose(8, 1, 30), _pose(15, -1, 100), _pose(24, 0, 200), _pose(31, 2, 5),
        _pose(39, -1, 60)]  # fmt: skip
FLIP = _pose(54, 0, 180)  # a corridor's symmetry: turned by 180 degrees about (27, 0)


def _groups() -> tuple[list[int | None], list[np.ndarray]]:
    """Nodes 0-2 in a group in node 0's frame, nodes 3-5 in another in node 3's frame."""
    a = [np.linalg.inv(TRUE[0]) @ TRUE[v] for v in range(3)]
    b = [np.linalg.inv(TRUE[3]) @ TRUE[v] for v in range(3, 6)]
    return [0, 0, 0, 1, 1, 1], a + b


def _hyp(link: int, choice: int, i: int, j: int, T: np.ndarray, evidence: float) -> Hypothesis:
    return Hypothesis(link, choice, Edge(i, j, T, COV), evidence)


def _true(i: int, j: int) -> np.ndarray:
    return np.linalg.inv(TRUE[i]) @ TRUE[j]


def _flipped(i: int, j: int) -> np.ndarray:
    """The link as it reads when scan j's side of the corridor is the other way round."""
    return np.linalg.inv(TRUE[i]) @ FLIP @ TRUE[j]


def test_two_links_that_agree_on_a_placement_join_the_groups_whichever_pose_each_kept():
    groups, poses = _groups()
    hyps = {
        7: [_hyp(7, 0, 0, 3, _true(0, 3), 1.0), _hyp(7, 1, 0, 3, _flipped(0, 3), 0.9)],
        8: [
            _hyp(8, 0, 1, 4, _pose(5, 5, 90) @ _true(1, 4), 1.0),
            _hyp(8, 1, 1, 4, _true(1, 4), 0.7),
        ],
    }
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert got[7].chosen.choice == 0 and got[8].chosen.choice == 1
    assert "2 links that agree" in got[8].reason


def test_links_whose_rivals_agree_as_well_as_their_kept_poses_leave_the_groups_apart():
    groups, poses = _groups()
    hyps = {
        k: [_hyp(k, 0, i, j, _true(i, j), 1.0), _hyp(k, 1, i, j, _flipped(i, j), 0.9)]
        for k, (i, j) in {7: (0, 3), 8: (1, 4)}.items()
    }
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert all(c.chosen is None and not c.rejected for c in got.values())
    assert "could not choose" in got[7].reason
    clear = choose(groups, poses, hyps, CHI2_6_999, 0.95)  # 1.8 < 0.95 * 2: the kept poses
    assert clear[7].chosen.choice == 0 and clear[8].chosen.choice == 0


def test_a_link_left_unchosen_with_its_kept_pose_alone_is_not_called_ambiguous():
    """A firm link that only bridges would keep goes to the choice with its kept pose alone;
    left unchosen, it says no other link agreed, not that it had rivals."""
    groups, poses = _groups()
    got = choose(groups, poses, {7: [_hyp(7, 0, 0, 3, _true(0, 3), 1.0)]}, CHI2_6_999, 0.5)
    assert got[7].chosen is None and not got[7].rejected
    assert "ambiguous" not in got[7].reason and "no other link agrees" in got[7].reason


def test_a_lone_ambiguous_link_between_two_groups_is_never_enough():
    groups, poses = _groups()
    hyps = {7: [_hyp(7, 0, 0, 3, _true(0, 3), 1.0), _hyp(7, 1, 0, 3, _flipped(0, 3), 0.6)]}
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert got[7].chosen is None and not got[7].rejected


def test_within_a_group_the_pose_that_fits_is_chosen_and_none_fitting_is_rejected():
    groups, poses = _groups()
    hyps = {
        5: [_hyp(5, 0, 0, 2, _flipped(0, 2), 1.0), _hyp(5, 1, 0, 2, _true(0, 2), 0.8)],
        6: [
            _hyp(6, 0, 3, 5, _flipped(3, 5), 1.0),
            _hyp(6, 1, 3, 5, _pose(3, 0, 0) @ _true(3, 5), 0.9),
        ],
    }
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert got[5].chosen.choice == 1 and "rival 1" in got[5].reason
    assert got[6].chosen is None and got[6].rejected


def test_links_only_checked_never_join_groups_however_well_they_agree():
    """Two probes between the groups that agree on the true placement join them when they may;
    only checked, they stay undecided, while one within a group is still chosen by its fit."""
    groups, poses = _groups()
    hyps = {
        7: [_hyp(7, 0, 0, 3, _true(0, 3), 1.0), _hyp(7, 1, 0, 3, _flipped(0, 3), 0.6)],
        8: [
            _hyp(8, 0, 1, 4, _true(1, 4), 1.0),
            _hyp(8, 1, 1, 4, _pose(5, 5, 90) @ _true(1, 4), 0.7),
        ],
        5: [_hyp(5, 0, 0, 2, _flipped(0, 2), 1.0), _hyp(5, 1, 0, 2, _true(0, 2), 0.8)],
    }
    assert choose(groups, poses, hyps, CHI2_6_999, 0.5)[7].chosen.choice == 0
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5, checked_only={5, 7, 8})
    assert got[7].chosen is None and got[8].chosen is None and not got[7].rejected
    assert got[5].chosen.choice == 1


def test_a_scan_on_no_firm_link_is_a_group_of_its_own():
    groups, poses = _groups()
    groups[5], poses[5] = None, None  # scan 5 has only ambiguous links
    hyps = {
        k: [_hyp(k, 0, i, 5, _true(i, 5), 1.0), _hyp(k, 1, i, 5, _pose(0, 7, 0) @ _true(i, 5), 0.8)]
        for k, i in {1: 3, 2: 4}.items()
    }
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert got[1].chosen.choice == 0 and got[2].chosen.choice == 0


def _singletons() -> tuple[list[int | None], list[np.ndarray | None]]:
    """Nodes 3, 4, 5 on no firm link (each a group of its own); 0-2 in a group."""
    groups, poses = _groups()
    for v in (3, 4, 5):
        groups[v], poses[v] = None, None
    return groups, poses


def test_a_triangle_that_closes_with_one_choice_joins_its_three_scans():
    groups, poses = _singletons()
    hyps = {
        1: [_hyp(1, 0, 3, 4, _true(3, 4), 1.0)],  # a link no cycle of firm links checks
        2: [_hyp(2, 0, 4, 5, _true(4, 5), 1.0)],
        3: [_hyp(3, 0, 3, 5, _flipped(3, 5), 1.0), _hyp(3, 1, 3, 5, _true(3, 5), 0.6)],
    }
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert [got[k].chosen.choice for k in (1, 2, 3)] == [0, 0, 1]
    assert "close a cycle" in got[3].reason


def test_a_triangle_that_closes_as_well_with_rivals_stays_undecided():
    groups, poses = _singletons()
    hyps = {  # every link may be read with scan 5 on the other side of the corridor
        1: [_hyp(1, 0, 3, 4, _true(3, 4), 1.0)],
        2: [_hyp(2, 0, 4, 5, _true(4, 5), 1.0), _hyp(2, 1, 4, 5, _flipped(4, 5), 0.9)],
        3: [_hyp(3, 0, 3, 5, _true(3, 5), 1.0), _hyp(3, 1, 3, 5, _flipped(3, 5), 0.9)],
    }
    got = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert all(c.chosen is None for c in got.values())


def _registered(status, **fields):
    from ndt_cli.ndt.result import RegistrationResult
    from ndt_cli.pipeline.links import Link

    r = RegistrationResult(np.eye(4), status, True, 1.0, 1.0, 1.0, (), (), (), np.eye(3), 0, 0, 0)
    return Link(0, 0, 1, result=replace(r, **fields))


def test_a_link_without_rivals_and_determined_everywhere_is_one_a_cycle_can_check():
    """The network holds such a link even when its gate doubted it and the plan did not pair
    it; one with rivals, a weak direction or refuted by its data it does not."""
    from ndt_cli.ndt.result import Rival, Status
    from ndt_cli.pipeline.link_use import determined, firm

    rival = Rival(np.eye(4), np.eye(3), 0.9, 0.0, "a pose turned +180.0 deg and 7.00 m away")
    doubted = _registered(Status.SUSPECT)
    assert firm(doubted) and determined(doubted)
    weak = _registered(Status.SUSPECT, weak_direction=np.array([1.0, 0.0, 0.0]))
    assert firm(weak) and not determined(weak)
    assert not firm(_registered(Status.SUSPECT, rivals=(rival,)))
    assert not firm(_registered(Status.SUSPECT, refuted=True))
    assert not firm(_registered(Status.FAILED))


def test_the_triangles_of_a_graph_are_those_of_every_triple_in_the_same_order():
    """Against the brute force over every triple of groups, on random graphs sparse and dense
    (with links within one group, which close nothing)."""
    rng = np.random.default_rng(5)
    for n, density in ((12, 0.15), (20, 0.4), (9, 1.0), (30, 0.05)):
        pairs = {(a, b) for a in range(n) for b in range(a, n) if rng.random() < density}
        brute = [
            t
            for t in combinations(range(n), 3)
            if {(t[0], t[1]), (t[1], t[2]), (t[0], t[2])} <= pairs
        ]
        assert list(triangles(pairs)) == brute, (n, density)
    assert list(triangles([(0, 1), (1, 2)])) == []


def test_the_network_holds_probes_with_rivals_only_to_check_them():
    """Of the links registered, a probe the plan did not pair is in the network when its gate
    passed it, and, only to be checked, when it has rivals and is determined everywhere; a
    weak or refuted probe with rivals is left out. A planned link with rivals is an ordinary
    member; the classic chain holds its chain whatever each link is."""
    from ndt_cli.ndt.result import Rival, Status
    from ndt_cli.pipeline.members import network_links
    from ndt_cli.pipeline.network import LinkKind

    rival = Rival(np.eye(4), np.eye(3), 0.6, 0.0, "a pose slid 0.5 m")
    weak = np.array([1.0, 0.0, 0.0])
    made = {
        (0, 1): (Status.OK, {}),
        (1, 2): (Status.SUSPECT, {"rivals": (rival,)}),  # planned
        (0, 2): (Status.SUSPECT, {"rivals": (rival,)}),  # a probe: only checked
        (2, 3): (Status.SUSPECT, {"rivals": (rival,), "weak_direction": weak}),  # left out
        (1, 3): (Status.OK, {}),  # gate-ok (scans 2 and 3 are not lonely)
        (0, 3): (Status.SUSPECT, {"refuted": True}),  # refuted: left out
    }
    registered = {
        (a, b): replace(_registered(status, **fields), target=a, source=b)
        for (a, b), (status, fields) in made.items()
    }
    members = network_links(
        registered, {(0, 1), (1, 2)}, set(), dict.fromkeys([(0, 1), (1, 2)], LinkKind.ADJACENT)
    )
    pairs = [(k.target, k.source) for k in members.links]
    assert pairs == [(0, 1), (0, 2), (1, 2), (1, 3)]
    assert [k.index for k in members.links] == [0, 1, 2, 3]
    assert members.checked_only == {1}
    classic = network_links(registered, set(), set(), {}, classic=(4, ()))
    assert [(k.target, k.source) for k in classic.links] == [(0, 1), (1, 2), (2, 3)]
    assert not classic.checked_only
