"""A link between neighbours along the walk that its gate doubted only because a pose the free
space refuted had more evidence (``quality.walk_vouch_free_space``, interiors): the walk
vouches for it when its own pose is clear of the free space, and it may then tie a scan in as
a bridge between walk neighbours does; a found link, or one doubted for anything else, is not
vouched for."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_hypotheses import _pose, _registered
from test_weak_links import _candidates

from ndt_cli.config import Config
from ndt_cli.config.scenes import for_scene
from ndt_cli.config.schema import from_dict
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import ConfigError
from ndt_cli.ndt.result import Rival, Status
from ndt_cli.pipeline.link_use import doubted_only_for_evidence
from ndt_cli.pipeline.members import network_links
from ndt_cli.pipeline.network import Bridges, LinkKind
from ndt_cli.pipeline.solution import solve
from ndt_cli.pipeline.verify import EdgeState, NodeStatus

SLID = (
    "the pose kept has 55% of the evidence of the pose the free space refuted (< 70%): it may "
    "be a pose slid along the scene",
)
VOUCH = (0.7, 0.0005)  # min_kept_evidence, walk_vouch_free_space as indoors
WALK = {(0, 1): LinkKind.ADJACENT}  # the neighbours along the walk


def _slid(status: Status = Status.SUSPECT, **fields):
    """A link its gate doubted only for the evidence of a refuted pose (55 % of it kept)."""
    made = {"warnings": SLID, "candidates": _candidates(0.55, 1.0), "free_space_around": 1e-4}
    return _registered(status, **(made | fields))


def test_only_a_link_doubted_for_the_evidence_alone_with_its_free_space_clear_is_vouched_for():
    assert doubted_only_for_evidence(_slid(), *VOUCH)
    assert not doubted_only_for_evidence(_slid(), 0.7, 0.0)  # off, as outdoors
    assert not doubted_only_for_evidence(_slid(free_space_around=0.0049), *VOUCH)
    assert not doubted_only_for_evidence(_slid(free_space_around=float("nan")), *VOUCH)
    assert not doubted_only_for_evidence(_slid(candidates=_candidates(0.8, 1.0)), *VOUCH)
    more = (*SLID, "ICP refinement rejected (it moved 0.43 m, 2.03 deg)")
    assert not doubted_only_for_evidence(_slid(warnings=more), *VOUCH)
    rival = Rival(np.eye(4), np.eye(3), 0.9, 0.0, "a pose turned +180.0 deg and 7.00 m away")
    assert not doubted_only_for_evidence(_slid(rivals=(rival,)), *VOUCH)
    assert not doubted_only_for_evidence(_slid(weak_direction=np.array([1.0, 0, 0])), *VOUCH)
    assert not doubted_only_for_evidence(_slid(refuted=True), *VOUCH)
    assert not doubted_only_for_evidence(_slid(Status.DEGENERATE), *VOUCH)


def test_the_network_vouches_only_for_walk_neighbours_and_then_does_not_merely_check_them():
    """Pairs (0, 1) neighbours along the walk and (0, 2) found: both doubted for the evidence
    alone; the walk's is vouched for and joins groups, the found one is only checked."""
    registered = {p: replace(_slid(), target=p[0], source=p[1]) for p in ((0, 1), (0, 2))}
    members = network_links(registered, set(registered), set(), WALK, weak=0.7, vouch=VOUCH)
    kinds = [(k.kind, k.vouched) for k in members.links]
    assert kinds == [(LinkKind.ADJACENT, True), (LinkKind.FOUND, False)]
    assert members.checked_only == {1}
    off = network_links(registered, set(registered), set(), WALK, weak=0.7)
    assert not any(k.vouched for k in off.links) and off.checked_only == {0, 1}


def _chain(vouched: bool) -> tuple[list, list[np.ndarray]]:
    """Scans 0-2 along a corridor: (0, 1) ok, (1, 2) right but doubted for the evidence of a
    refuted pose; both between walk neighbours."""
    T = [_pose(0, 0, 0), _pose(8, 1, 30), _pose(16, -1, 100)]
    hess = {"hessian": np.diag([1e4, 1e4, 1e6])}
    ok = _registered(Status.OK, T_target_source=np.linalg.inv(T[0]) @ T[1], **hess)
    slid = _slid(T_target_source=np.linalg.inv(T[1]) @ T[2], **hess)
    links = [
        replace(ok, index=0, target=0, source=1),
        replace(slid, index=1, target=1, source=2, vouched=vouched),
    ]
    return links, T


def test_a_vouched_link_ties_its_scan_in_as_a_bridge_between_walk_neighbours_does():
    links, T = _chain(vouched=True)
    walked = solve(3, 0, links, True, {}, bridges=Bridges.WALK)
    assert walked.scans[2].status is NodeStatus.OK
    rot, trans = transform_errors(walked.scans[2].T_world_scan, T[2])
    assert rot < 1e-6 and trans < 1e-6
    assert walked.links[1].state is EdgeState.USED
    assert "vouched for by the walk" in walked.links[1].reason
    assert "its gate's word" not in walked.links[1].reason
    assert "not chosen" not in walked.links[1].reason  # used: the choice's words do not apply
    assert "slid" in links[1].reason  # the gate's doubt stays the link's own (pairs.csv reason)
    alone = solve(3, 0, links, True, {}, bridges=Bridges.NONE)  # no bridge trusted at all
    assert alone.scans[2].status is not NodeStatus.OK


def test_the_report_says_why_a_link_its_gate_doubted_is_in_use():
    """The link table gives both: the gate's doubt and the network's word that the walk
    vouched for it (else a suspect link reads as used with no reason)."""
    from ndt_cli.report.html_cards import _lines
    from ndt_cli.report.html_chain import STATE_WORDS, link_row

    links, _ = _chain(vouched=True)
    fit = solve(3, 0, links, True, {}, bridges=Bridges.WALK).links[1]
    row = link_row(("a", "b", "c"), links[1], STATE_WORDS[fit.state], fit)
    assert row.status == "suspect" and row.state == "not checked"
    assert any("slid" in w for w in row.warnings)
    assert any(w.startswith("network:") and "vouched for by the walk" in w for w in row.warnings)
    caption = _lines(row, None)  # the link inspector's card says it too
    assert caption[0].startswith("adjacent, registration suspect")
    assert "vouched for by the walk" in caption[1]


def test_a_lone_vouched_link_reads_as_used_on_the_walks_word():
    """Scans 1 and 2 with one link between them, vouched for, and none to the anchor: no
    choice was made (no other link agrees or disagrees), so its reason says the walk vouched,
    not that it was not chosen; the two scans are ok in a cluster of their own."""
    _, T = _chain(vouched=True)
    hess = {"hessian": np.diag([1e4, 1e4, 1e6])}
    lone = _slid(T_target_source=np.linalg.inv(T[1]) @ T[2], **hess)
    links = [replace(lone, index=0, target=1, source=2, vouched=True)]
    solution = solve(3, 0, links, True, {}, bridges=Bridges.WALK)
    assert [s.cluster for s in solution.scans] == [0, 1, 1]
    assert solution.scans[2].status is NodeStatus.OK
    reason = solution.links[0].reason
    assert "vouched for by the walk" in reason and "not chosen" not in reason, reason


def test_the_verdict_lists_a_vouched_link_apart_from_those_its_gate_passed():
    from types import SimpleNamespace

    from ndt_cli.report.verdict import _link_remarks

    links, _ = _chain(vouched=True)
    solution = solve(3, 0, links, True, {}, bridges=Bridges.WALK)
    remarks = _link_remarks(SimpleNamespace(links=links, solution=solution, names="abc"))
    assert len(remarks) == 2
    assert "gate's word" in remarks[0] and "a <- b" in remarks[0] and "b <- c" not in remarks[0]
    assert "doubted by their gate" in remarks[1] and "b <- c" in remarks[1]


def test_a_link_not_vouched_for_ties_no_scan_in_on_a_doubting_gate():
    links, _ = _chain(vouched=False)
    walked = solve(3, 0, links, True, {}, bridges=Bridges.WALK)
    assert walked.scans[1].status is NodeStatus.OK
    assert walked.scans[2].status is not NodeStatus.OK


def test_interiors_let_the_walk_vouch_and_the_key_stays_within_what_refutes_a_pose_indoors():
    assert Config().quality.walk_vouch_free_space == 0.0
    assert for_scene(Config(), "indoor").quality.walk_vouch_free_space == 0.0005
    with pytest.raises(ConfigError, match=r"quality\.walk_vouch_free_space"):
        from_dict({"quality": {"walk_vouch_free_space": 0.01}})
