"""Weak links and the choice among rivals: a link kept with little of the evidence of a pose the
free space refuted (``quality.weak_links_join`` false, interiors) is only checked within a
group, never joins two; the halves of a symmetric floor made two such links agree on the far
half turned by 180 degrees."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from test_hypotheses import _flipped, _groups, _hyp, _pose, _registered

from ndt_cli.config import Config
from ndt_cli.config.scenes import for_scene
from ndt_cli.core.transforms import transform_errors
from ndt_cli.ndt.result import Candidate, Rival, Status
from ndt_cli.pipeline.graph import CHI2_6_999
from ndt_cli.pipeline.hypotheses import choose
from ndt_cli.pipeline.link_use import kept_share
from ndt_cli.pipeline.members import network_links
from ndt_cli.pipeline.network import Bridges
from ndt_cli.pipeline.solution import solve
from ndt_cli.pipeline.verify import NodeStatus


def _candidates(*evidence: float) -> tuple[Candidate, ...]:
    """Candidates with these evidences, the kept pose first."""
    return tuple(Candidate(float(k), 0.0, 0.0, e, e) for k, e in enumerate(evidence))


def test_a_links_kept_share_is_its_kept_poses_evidence_over_the_most_of_any_candidate():
    assert kept_share(_registered(Status.SUSPECT, candidates=_candidates(0.19, 1.0, 0.5))) == 0.19
    assert kept_share(_registered(Status.OK, candidates=_candidates(2.0, 1.5))) == 1.0
    assert kept_share(_registered(Status.OK)) == 1.0  # no candidates: nothing was refuted


def test_a_weak_link_of_the_network_is_only_checked_where_weak_links_join_no_groups():
    """Links (0, 1) kept with the most evidence, (1, 2) with 19 % of a refuted pose's, (0, 2)
    with 80 %: below 0.7 only (1, 2) is only checked; with no bar, none is."""
    made = {(0, 1): (1.0, 0.5), (1, 2): (0.19, 1.0), (0, 2): (0.8, 1.0)}
    registered = {
        p: replace(
            _registered(Status.SUSPECT, candidates=_candidates(*e)), target=p[0], source=p[1]
        )
        for p, e in made.items()
    }
    plan = set(made)
    members = network_links(registered, plan, set(), {}, weak=0.7)
    assert [(k.target, k.source) for k in members.links] == [(0, 1), (0, 2), (1, 2)]
    assert members.checked_only == {2}
    assert not network_links(registered, plan, set(), {}).checked_only


def test_two_weak_links_that_agree_on_a_turned_placement_do_not_join_the_groups():
    """Two links between the halves of a corridor, each only with the pose that turns the far
    half by 180 degrees: they agree, and join the groups wrongly, unless they are only
    checked."""
    groups, poses = _groups()
    hyps = {7: [_hyp(7, 0, 0, 3, _flipped(0, 3), 1.0)], 8: [_hyp(8, 0, 1, 4, _flipped(1, 4), 1.0)]}
    joined = choose(groups, poses, hyps, CHI2_6_999, 0.5)
    assert joined[7].chosen is not None and joined[8].chosen is not None  # the trap
    apart = choose(groups, poses, hyps, CHI2_6_999, 0.5, checked_only={7, 8})
    assert all(c.chosen is None for c in apart.values())


def test_interiors_keep_weak_links_from_joining_groups_and_streets_let_them():
    assert Config().quality.weak_links_join is True
    assert for_scene(Config(), "indoor").quality.weak_links_join is False


def _link(k: int, i: int, j: int, T: np.ndarray, status: Status, **fields):
    """Link ``k`` of the network: scan ``j`` onto scan ``i`` with transform ``T``."""
    r = _registered(status, T_target_source=T, hessian=np.diag([1e4, 1e4, 1e6]), **fields)
    return replace(r, index=k, target=i, source=j)


def test_a_weak_bridge_places_no_scan_for_the_choice_among_rivals():
    """Scans 0-2 tied by a cycle; scan 3 joined by a firm link kept with 19 % of a refuted
    pose's evidence, turned by 180 degrees and 14 m off (the far half of a symmetric floor),
    and by a link whose kept pose agrees with it and whose rival is the truth. Where the weak
    link placed scan 3 in the group, the ambiguous link was chosen by agreeing with it, the
    two closed a cycle and scan 3 was ok and wrong; only checked, the weak link places
    nothing, and scan 3 is not ok."""
    T = [_pose(0, 0, 0), _pose(6, 1, 20), _pose(12, -1, 80), _pose(20, 0, 150)]
    flip = _pose(54, 0, 180)  # the floor turned by 180 degrees about (27, 0)

    def rel(i, j, W=None):
        return np.linalg.inv(T[i]) @ (np.eye(4) if W is None else W) @ T[j]

    rival = Rival(rel(1, 3), np.diag([1e4, 1e4, 1e6]), 0.9, 0.0, "a pose turned +180.0 deg")
    links = [
        _link(0, 0, 1, rel(0, 1), Status.OK),
        _link(1, 0, 2, rel(0, 2), Status.OK),
        _link(2, 1, 2, rel(1, 2), Status.OK),
        _link(3, 0, 3, rel(0, 3, flip), Status.SUSPECT, candidates=_candidates(0.19, 1.0)),
        _link(4, 1, 3, rel(1, 3, flip), Status.SUSPECT, rivals=(rival,)),
    ]
    walk = Bridges.NONE
    trap = solve(4, 0, links, True, {}, bridges=walk)
    assert trap.scans[3].status is NodeStatus.OK  # ok and turned: what the rule prevents
    rot, trans = transform_errors(trap.scans[3].T_world_scan, T[3])
    assert rot > 179.0 and trans > 10.0
    safe = solve(4, 0, links, True, {}, bridges=walk, checked_only={3})
    assert safe.scans[3].status is not NodeStatus.OK
    assert all(s.status is NodeStatus.OK for s in safe.scans[:3])
