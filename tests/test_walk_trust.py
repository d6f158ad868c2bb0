"""What the walk vouches for: where no bridge is trusted (interiors), a link on no cycle
between scans taken one after the other may still tie a scan in on its gate's word; no other
bridge may, and a walk neighbour's link on a cycle is judged by its cycle."""

from __future__ import annotations

import numpy as np
import pytest
from test_adjust import measured, street

from ndt_cli.config import Config
from ndt_cli.config.scenes import for_scene
from ndt_cli.pipeline.graph import Edge
from ndt_cli.pipeline.network import Bridges
from ndt_cli.pipeline.verify import EdgeState, NodeStatus, verify


def _chain(walked: list[bool], trusted: list[bool], seed: int = 5) -> list[Edge]:
    """A street of scans 15 m apart joined in a chain (no cycle), edge k between k and k+1."""
    rng = np.random.default_rng(seed)
    truth = street(rng, n=len(walked) + 1)
    edges = []
    for k, (w, t) in enumerate(zip(walked, trusted, strict=True)):
        e = measured(truth, k, k + 1, rng, trusted=t)
        edges.append(Edge(e.target, e.source, e.T_target_source, e.covariance, t, walked=w))
    return edges


def test_a_gate_ok_bridge_between_walk_neighbours_ties_its_scan_in_where_no_other_does():
    """Edges 0-1 and 1-2 join walk neighbours, 2-3 does not (a pair the plan found), 3-4 is a
    walk neighbours' link its gate doubted: with no bridge trusted but the walk's, scans 0-2
    are ok, and 3 and 4 are not."""
    edges = _chain(walked=[True, True, False, True], trusted=[True, True, True, False])
    result = verify(5, 0, edges, trust_bridges=False)
    states = [e.state for e in result.edges]
    assert states == [EdgeState.USED, EdgeState.USED, EdgeState.UNUSED, EdgeState.UNUSED]
    assert "only a bridge between neighbours along the walk" in result.edges[2].reason
    assert "its own gate failed" in result.edges[3].reason
    assert [s is NodeStatus.OK for s in result.statuses()] == [True, True, True, False, False]


def test_without_walk_neighbours_no_bridge_ties_a_scan_in():
    """The same chain with no link marked as the walk's: only the anchor is ok, and every
    bridge says that no bridge is trusted."""
    edges = _chain(walked=[False] * 4, trusted=[True] * 4)
    result = verify(5, 0, edges, trust_bridges=False)
    assert [s is NodeStatus.OK for s in result.statuses()] == [True] + [False] * 4
    assert all("no bridge is trusted" in e.reason for e in result.edges)


def test_a_wrong_walk_link_on_a_cycle_is_judged_by_the_cycle():
    """A walk neighbours' link 4 m off that lies on a cycle of right links is rejected, not
    kept on its gate's word: the walk vouches only where nothing else can check."""
    rng = np.random.default_rng(9)
    truth = street(rng, n=4)
    pairs = [(0, 1), (1, 2), (2, 3), (0, 2), (1, 3)]
    edges = []
    for i, j in pairs:
        error = np.array([4.0, 0.0, 0.0]) if (i, j) == (1, 2) else None
        e = measured(truth, i, j, rng, error=error)
        walked = j == i + 1
        edges.append(Edge(i, j, e.T_target_source, e.covariance, True, walked=walked))
    result = verify(4, 0, edges, trust_bridges=False)
    assert result.edges[1].state is EdgeState.REJECTED
    assert all(result.edges[k].state is EdgeState.CONFIRMED for k in (0, 2, 3, 4))


def test_which_bridges_a_campaign_trusts():
    """A walk outdoors trusts every bridge its gate passed, indoors only the walk's, and a
    campaign out of walking order none, whatever the settings."""
    assert Bridges.of(True, True, walked=True) is Bridges.ALL
    assert Bridges.of(False, True, walked=True) is Bridges.WALK
    assert Bridges.of(False, False, walked=True) is Bridges.NONE
    assert all(Bridges.of(a, b, walked=False) is Bridges.NONE for a in (0, 1) for b in (0, 1))
    indoor = for_scene(Config(), "indoor").quality
    assert indoor.trust_bridges is False and indoor.trust_walk_bridges is True


def _walk_with_strangers(folder) -> list:
    """A route's first scan, then six scans of six other streets (each fits no scan), then
    the route's second scan: the order a walk has where most scans fit nowhere."""
    from ndt_cli import sim

    route = sim.write_survey(sim.route(seed=3, n_scans=2, rays=(1000, 120)), folder / "route")
    strangers = [
        sim.write_survey(sim.route(seed=60 + k, n_scans=1, rays=(1000, 120)), folder / f"x{k}")[0]
        for k in range(6)
    ]
    return [route[0], *strangers, *route[1:]]


def _walked(files, cfg: Config, out) -> bool:
    """Whether the campaign still follows its order once every file was placed."""
    from ndt_cli.pipeline.campaign import Campaign
    from ndt_cli.pipeline.local_pool import WorkerPool

    campaign = Campaign(cfg, out, WorkerPool(2), anchor=0)
    try:
        new = campaign._admit(files)
        campaign.tasks.summarise(new)
        campaign._discover(new)
        return campaign.walked
    finally:
        campaign.close()


@pytest.mark.slow
def test_scans_that_fit_nowhere_doubt_the_walk_only_where_unplaced_doubt_walk(tmp_path):
    """Outdoors six scans in a row that fit no scan are as many misses of the order: the
    campaign stops following it (and then trusts no bridge). Where they count neither way
    (``scene.unplaced_doubt_walk`` false, interiors: a room seen only through its doorway
    fits no scan), the same files leave the walk a hint."""
    files = _walk_with_strangers(tmp_path)
    assert _walked(files, Config(), tmp_path / "street") is False
    cfg = Config().replace(scene={"unplaced_doubt_walk": False})
    assert _walked(files, cfg, tmp_path / "indoor") is True
    assert for_scene(Config(), "indoor").scene.unplaced_doubt_walk is False
