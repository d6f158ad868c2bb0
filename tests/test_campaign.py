"""A campaign in any order: scans known by their content, links found from where the scans
are, the same network whatever the order. Expected poses come from the simulator's ground
truth; equal results are compared with each other, never with numbers from the code."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from types import SimpleNamespace

import laspy
import numpy as np
import pytest
from conftest import street_files
from typer.testing import CliRunner

from ndt_cli import sim
from ndt_cli.cli import chain_app, export_app
from ndt_cli.config import Config
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import ConfigError, InputError
from ndt_cli.io.matrices import read_pose_list
from ndt_cli.pipeline import placement
from ndt_cli.pipeline.campaign import Campaign
from ndt_cli.pipeline.chain import run_chain
from ndt_cli.pipeline.inputs import anchor_index, chain_inputs
from ndt_cli.pipeline.local_pool import WorkerPool
from ndt_cli.pipeline.network import LinkKind, PlannedLink
from ndt_cli.pipeline.options import NetworkOptions
from ndt_cli.pipeline.verify import NodeStatus

runner = CliRunner()
ROT, TRANS = 0.3, 0.15  # deg, m: a pose within these of the truth is right


def _right(T: np.ndarray | None, truth: np.ndarray) -> bool:
    if T is None:
        return False
    rot, trans = transform_errors(T, truth)
    return rot < ROT and trans < TRANS


def test_inputs_are_sorted_checked_and_the_anchor_named(tmp_path):
    for name in ("s10.xyz", "s2.xyz", "s1.xyz"):
        (tmp_path / name).write_text(f"{name[1:-4]} 0 0\n")  # each its own content
    inputs = chain_inputs(
        [tmp_path / "s10.xyz", tmp_path / "s2.xyz", tmp_path / "s1.xyz"], anchor="s2.xyz"
    )
    assert [p.name for p in inputs.paths] == ["s1.xyz", "s2.xyz", "s10.xyz"]
    assert inputs.anchor == 1 and inputs.network.neighbours == 4
    assert anchor_index("2", inputs.names) == 2
    with pytest.raises(ConfigError, match="--anchor nope"):
        anchor_index("nope", inputs.names)
    with pytest.raises(ConfigError, match="--radius"):
        chain_inputs(inputs.paths, radius=0.0)
    with pytest.raises(ConfigError, match="--neighbours"):
        chain_inputs(inputs.paths, neighbours=11)
    with pytest.raises(InputError, match="at least two"):
        chain_inputs(inputs.paths[:1])
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("s1.xyz,s10.xyz\n")
    user = chain_inputs(inputs.paths, pairs=pairs).network.pairs
    assert user == (PlannedLink(0, 2, LinkKind.USER),)


@pytest.fixture(scope="module")
def street8(tmp_path_factory):
    """Eight scans of one street (13-17 m apart) as LAZ files, and their true poses."""
    return street_files(tmp_path_factory.mktemp("street8"), n_scans=8)


def _link_files(out: Path) -> set[str]:
    return {p.name for p in (out / "links").glob("*.json")}


@pytest.mark.slow
def test_inserting_a_scan_in_the_middle_reuses_every_earlier_link(street8, tmp_path):
    files, _ = street8
    out = tmp_path / "out"
    first = run_chain([files[k] for k in (0, 1, 3, 4)], Config(), out, jobs=2)
    before = _link_files(out)
    second = run_chain(files[:5], Config(), out, jobs=2, resume=True)  # scan 2 in the middle
    assert second.ok  # (the first, with a 30 m gap, need not be)

    def pairs(result):
        return {
            (result.names[k.target], result.names[k.source]): n for n, k in enumerate(result.links)
        }

    earlier, now = pairs(first), pairs(second)
    kept = [n for pair, n in now.items() if pair in earlier]  # links of both networks
    assert len(kept) >= 2  # 0-1 and 3-4 at least: the links scan 2 does not replace
    assert set(kept) <= set(second.reused)  # every one of them taken, none registered again
    assert before <= _link_files(out)  # and no link file was renamed or dropped


@pytest.fixture(scope="module")
def shuffled8(street8, tmp_path_factory):
    """The eight scans chained in order and, renamed in a random order, shuffled (anchored on
    scan 0): the file order, and both result folders."""
    files, _ = street8
    root = tmp_path_factory.mktemp("shuffled8")
    order = np.random.default_rng(3).permutation(len(files))  # file k holds scan order[k]
    mixed = root / "mixed"
    mixed.mkdir()
    for k, scan in enumerate(order):
        (mixed / f"scan_{k}.laz").write_bytes(files[scan].read_bytes())
    anchor = f"scan_{int(np.flatnonzero(order == 0)[0])}.laz"  # scan 0, wherever it is now
    a, b = root / "in_order", root / "shuffled"
    assert runner.invoke(chain_app, [*map(str, files), "-o", str(a), "-q"]).exit_code == 0
    scans = sorted(mixed.glob("*.laz"))
    args = [*map(str, scans), "-o", str(b), "-q", "--anchor", anchor]
    assert runner.invoke(chain_app, args).exit_code == 0  # every scan ok
    return order, scans, a, b


@pytest.mark.slow
def test_a_shuffled_street_gives_the_same_result_as_the_street_in_order(street8, shuffled8):
    _, poses = street8
    order, _, a, b = shuffled8
    in_order, shuffled = read_pose_list(a / "poses.txt"), read_pose_list(b / "poses.txt")
    inv0 = np.linalg.inv(poses[0])
    for k, scan in enumerate(order):
        T_a, T_b = in_order[f"scan_{scan}.laz"], shuffled[f"scan_{k}.laz"]
        rot, trans = transform_errors(T_a, T_b)
        # the same pose, within what the networks' few different links move it: the links
        # tried while placing a scan are in the network too, and they differ with the order
        assert rot < 0.005 and trans < 0.005, (scan, rot, trans)
        assert _right(T_a, inv0 @ poses[scan])
    # the cost: at most twice the registrations of the street in order
    assert len(_link_files(b)) <= 2 * len(_link_files(a))


@pytest.mark.slow
def test_coarse_positions_of_a_shuffled_street_choose_links_and_do_no_harm(
    street8, shuffled8, tmp_path
):
    """A scanner's own GNSS (metres) on every standpoint, the street shuffled: the candidates
    by position are registered (no more registrations than without them), every scan is ok
    and right relative to the others, and the world is the positions' frame."""
    _, poses = street8
    order, scans, _, plain = shuffled8
    rng = np.random.default_rng(1)
    rows = []
    for k, scan in enumerate(order):
        x, y, z = poses[scan][:3, 3] + rng.normal(0.0, [1.5, 1.5, 2.0])
        rows.append(f"scan_{k}.laz,{x:.3f},{y:.3f},{z:.3f},2.0,3.0")
    (tmp_path / "gnss.csv").write_text("\n".join(rows) + "\n")
    coarse = tmp_path / "coarse"
    first = int(np.flatnonzero(order == 0)[0])  # the plain run's anchor: only positions differ
    args = [*map(str, scans), "-o", str(coarse), "-q", "--control", str(tmp_path / "gnss.csv")]
    assert runner.invoke(chain_app, [*args, "--anchor", f"scan_{first}.laz"]).exit_code == 0
    assert len(_link_files(coarse)) <= len(_link_files(plain))
    got = read_pose_list(coarse / "poses.txt")
    inv_first = np.linalg.inv(got[f"scan_{first}.laz"])
    for k, scan in enumerate(order):
        truth = np.linalg.inv(poses[0]) @ poses[scan]
        assert _right(inv_first @ got[f"scan_{k}.laz"], truth), k
    world = json.loads((coarse / "summary.json").read_text())["world"]
    assert world["frame"] == "control" and all(row["used"] for row in world["controls"])


@pytest.mark.slow
def test_two_campaigns_in_one_call_keep_apart(tmp_path):
    both = sim.two_sites(seed=2, n_scans=(4, 3))
    files = sim.write_survey(both, tmp_path / "scans")
    out = tmp_path / "out"
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(out), "-q", "-j", "2"])
    assert res.exit_code == 1, res.output  # not every scan is ok in one frame
    poses = read_pose_list(out / "poses.txt")
    inv0 = np.linalg.inv(both.poses[0])
    for name, T, site in zip(both.names, both.poses, both.site, strict=True):
        if site == 0:  # the anchor's campaign: ok, right
            assert _right(poses[f"{name}.laz"], inv0 @ T), name
        else:  # never ok in the anchor's frame
            assert f"{name}.laz" not in poses
    summary = json.loads((out / "summary.json").read_text())
    assert summary["network"]["clusters"] == {"0": 4, "1": 3}  # each site a cluster of its own
    rows = {r["file"]: r for r in csv.DictReader((out / "poses.csv").open())}
    for name, site in zip(both.names, both.site, strict=True):
        assert rows[f"{name}.laz"]["cluster"] == str(site), name
    # the other site's poses: in the frame of its own first scan, right relative to each other
    other = [k for k, site in enumerate(both.site) if site == 1]
    first = np.linalg.inv(both.poses[other[0]])
    for k in other:
        row = rows[f"{both.names[k]}.laz"]
        T = np.array([float(row[f"m{i}{j}"]) for i in range(4) for j in range(4)]).reshape(4, 4)
        assert _right(T, first @ both.poses[k]), both.names[k]
    # poses_cluster1.txt gives them as poses.txt gives cluster 0's
    cluster1 = read_pose_list(out / "poses_cluster1.txt")
    assert set(cluster1) == {f"{both.names[k]}.laz" for k in other}
    for k in other:
        assert _right(cluster1[f"{both.names[k]}.laz"], first @ both.poses[k]), both.names[k]
    # ndt-export --cluster 1: the other site's points, where they are relative to its first scan
    res = runner.invoke(export_app, [str(out), "--out", str(tmp_path / "1.laz"), "--cluster", "1"])
    assert res.exit_code == 0, res.output
    cloud = laspy.read(tmp_path / "1.laz")
    xyz, index = np.column_stack([cloud.x, cloud.y, cloud.z]), np.asarray(cloud.scan_index)
    assert set(index) == set(other)
    for k in other:
        truth = both.scans[k] @ (first @ both.poses[k])[:3, :3].T + (first @ both.poses[k])[:3, 3]
        d = np.linalg.norm(xyz[index == k] - truth, axis=1)
        assert np.percentile(d, 99) < TRANS, (k, np.percentile(d, 99))
    res = runner.invoke(export_app, [str(out), "--out", str(tmp_path / "2.laz"), "--cluster", "2"])
    assert res.exit_code == 2 and "--cluster 2" in res.output


@pytest.mark.slow
def test_a_junction_side_streets_and_a_loop_are_all_ok_without_pairs(tmp_path):
    loop = sim.block_loop(seed=0, spacing=20.0)  # 21 standpoints round the block
    files = sim.write_survey(loop, tmp_path / "scans")
    result = run_chain(files, Config(), tmp_path / "out", jobs=2)
    inv0 = np.linalg.inv(loop.poses[0])
    for k, s in enumerate(result.solution.scans):
        assert s.status is NodeStatus.OK, (k, s.reason)
        assert _right(s.T_world_scan, inv0 @ loop.poses[k]), k
    # the loop is closed: a link joins the last scan to the scans where the loop began
    last = len(files) - 1
    assert any(
        last in (k.target, k.source) and abs(k.target - k.source) > 5 and k.ok for k in result.links
    )


def test_a_group_s_edge_is_its_scans_with_the_fewest_ok_links_within_it():
    """A line of 12 scans linked to their neighbours: the two ends (one ok link each) come
    first; a group no larger than the bound is all edge."""
    line = list(range(12))
    links = {(a, a + 1): SimpleNamespace(ok=True) for a in line[:-1]}
    links[(3, 5)] = SimpleNamespace(ok=False)  # not ok: does not count
    edge = placement.edge(line, links)
    assert len(edge) == placement.BRIDGE_MEMBERS and edge[:2] == [0, 11]
    assert placement.edge(line[:5], links) == line[:5]


@pytest.mark.parametrize(
    ("outcomes", "hint"),
    [
        ([], True),
        ([False] * 5, True),  # too few scans to judge
        ([True, False, True, False, True, False], True),  # half placed by the order
        ([True, False, False, False, True, False], False),
        ([True] * 9 + [False], True),  # a walk with one gap
    ],
)
def test_the_order_stays_a_hint_while_it_places_half_the_scans(outcomes, hint):
    from ndt_cli.pipeline.discovery import HINT_TRIALS, order_is_a_hint

    assert HINT_TRIALS == 6  # the cases above are written for it
    assert order_is_a_hint(outcomes) is hint


@pytest.mark.slow
def test_a_shuffled_route_is_placed_by_its_coarse_matches_with_the_same_poses(tmp_path, caplog):
    """Sixteen scans of a route in random order: the order soon proves no hint, the rest are
    placed best coarse match first; every scan is right and where the route in order puts
    it, and ok, but for a scan that only a bridge ties in: out of order no bridge is trusted
    (a street fits itself shifted by a few blocks), so that scan is suspect, saying so."""
    route = sim.route(seed=3, n_scans=16, rays=(1500, 200))
    mixed = sim.shuffled(route, seed=2)
    # file k of the mixed campaign holds scan order[k] of the route (its true pose says which)
    order = [
        next(j for j, P in enumerate(route.poses) if np.array_equal(P, Q)) for Q in mixed.poses
    ]
    walk = run_chain(sim.write_survey(route, tmp_path / "walk"), Config(), tmp_path / "a", jobs=2)
    with caplog.at_level("INFO", logger="ndt_cli.progress"):
        files = sim.write_survey(mixed, tmp_path / "mixed")
        # in the walk's folder: a pair both register is taken from its store (links are keyed
        # by the scans' content, and a registration gives the same link again)
        shuffled = run_chain(
            files, Config(), tmp_path / "a", jobs=2, anchor=order.index(0), resume=True
        )
    assert any("no hint" in r.getMessage() for r in caplog.records)
    # each scan out of order is registered to its best coarse matches at once, not beside the
    # scans placed so far in turn (a scan whose neighbours were not placed yet paid 5 or 6)
    registered = len(shuffled.links) + len(shuffled.tried)
    assert registered <= 1.5 * (len(walk.links) + len(walk.tried)), registered
    assert shuffled.solution.roots == {0: order.index(0)}  # one cluster, in the anchor's frame
    ok_links: dict[int, list[int]] = {}  # per scan, the scans its ok links reach
    for link in shuffled.links:
        if link.ok:
            ok_links.setdefault(link.target, []).append(link.source)
            ok_links.setdefault(link.source, []).append(link.target)
    inv0 = np.linalg.inv(route.poses[0])
    for k, scan in enumerate(order):
        a, b = walk.solution.scans[scan], shuffled.solution.scans[k]
        assert a.status is NodeStatus.OK, (scan, a.reason)
        if b.status is not NodeStatus.OK:
            assert b.status is NodeStatus.SUSPECT and "unused link" in b.reason, (scan, b.reason)
            assert len(ok_links.get(k, [])) == 1, (scan, ok_links.get(k))
        assert a.cluster == b.cluster == 0, (scan, b.cluster)
        assert _right(b.T_world_scan, inv0 @ route.poses[scan]), scan
        if b.status is NodeStatus.OK:  # the same network but the bridge: within a link's
            rot, trans = transform_errors(a.T_world_scan, b.T_world_scan)  # accuracy
            assert rot < 0.005 and trans < 0.005, (scan, rot, trans)


def _guesses(poses: list[np.ndarray], seed: int) -> dict[int, np.ndarray]:
    """Approximate poses, as a site's GNSS and compass give them: each within 1 m and 5
    degrees of the truth (the default --init-sigma)."""
    rng = np.random.default_rng(seed)
    out = {}
    for k, P in enumerate(poses):
        a = np.radians(rng.uniform(-5.0, 5.0))
        turn = np.eye(4)
        turn[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        guess = P @ turn
        guess[:2, 3] += rng.uniform(-0.7, 0.7, 2)
        out[k] = guess
    return out


@pytest.mark.slow
def test_scans_placed_out_of_order_are_matched_coarsely_only_where_no_position_is_known(
    tmp_path, caplog
):
    """Ten scans of a route in random order placed together (what a campaign does once its
    order proves no hint), eight with an approximate pose, and a scan of another street:
    those with a pose are registered to the scans their poses put near them, and only the
    others are matched coarsely, first with the scans their landmarks rank first; the other
    street's scan, which none of those places, then with every scan. Bridged (out of order
    no bridge is trusted, so none is registered the other way round) and consolidated, every
    scan of the route is ok and right, the other street's is not ok."""
    route = sim.route(seed=3, n_scans=10, rays=(1000, 120))
    mixed = sim.shuffled(route, seed=2)
    order = [
        next(j for j, P in enumerate(route.poses) if np.array_equal(P, Q)) for Q in mixed.poses
    ]
    stranger = sim.write_survey(sim.route(seed=41, n_scans=2, rays=(1000, 120)), tmp_path / "x")
    blind = {2, 7, 10}  # files without an approximate pose; 10: the other street's scan
    guesses = _guesses(list(mixed.poses), seed=4)
    net = NetworkOptions(init_poses={k: T for k, T in guesses.items() if k not in blind})
    campaign = Campaign(Config(), tmp_path / "out", WorkerPool(2), anchor=0, network=net)
    try:
        files = [*sim.write_survey(mixed, tmp_path / "mixed"), stranger[0]]
        new = campaign._admit(files)
        campaign.tasks.summarise(new)
        campaign.walked = False  # what the campaign concludes when the order is no hint
        with caplog.at_level("INFO", logger="ndt_cli.progress"):
            campaign._place_by_matches(new)
        assert campaign.coarse and all(set(p) & blind for p in campaign.coarse)
        assert {p for p in campaign.coarse if 10 in p} == {(k, 10) for k in range(10)}
        assert any("alone: matched with the next by rank" in r.getMessage() for r in caplog.records)
        turned = set(campaign.tasks.turned)
        campaign._bridge(new)
        assert campaign.tasks.turned == turned  # no bridge is trusted: none turned round
        campaign._consolidate()
        scans = campaign.result().solution.scans
    finally:
        campaign.close()
    inv_0, inv_true = np.linalg.inv(scans[0].T_world_scan), np.linalg.inv(route.poses[order[0]])
    for k, scan in enumerate(order):
        assert scans[k].status is NodeStatus.OK, (k, scans[k].reason)
        assert _right(inv_0 @ scans[k].T_world_scan, inv_true @ route.poses[scan]), k
    assert scans[10].status is not NodeStatus.OK


@pytest.mark.slow
def test_shuffled_files_that_say_when_they_were_taken_are_placed_as_walked(tmp_path, caplog):
    """The scans of a route in random order, each file with its points' GPS times (as scanners
    write them): the campaign follows their time order, which is the walk, so it registers
    what the walk does and ends with the walk's statuses and poses, where files without times
    are placed by coarse matches (the test above)."""
    route = sim.route(seed=3, n_scans=10, rays=(1500, 200))
    mixed = sim.shuffled(route, seed=2)
    order = [
        next(j for j, P in enumerate(route.poses) if np.array_equal(P, Q)) for Q in mixed.poses
    ]
    assert order != sorted(order)
    walk_files = sim.write_survey(route, tmp_path / "walk", times=True)
    walk = run_chain(walk_files, Config(), tmp_path / "a", jobs=2)
    with caplog.at_level("INFO", logger="ndt_cli.progress"):
        files = sim.write_survey(mixed, tmp_path / "mixed", times=True)
        shuffled = run_chain(files, Config(), tmp_path / "b", jobs=2, anchor=order.index(0))
    said = [r.getMessage() for r in caplog.records]
    assert "the scans' acquisition times give the walk" in said
    assert not any("no hint" in m for m in said)
    names = [f"scan_{k:02d}" for k in order]  # the walk's name of each shuffled file

    def pairs(result, name_of):  # each link's scans by their walk names, and its kind
        return sorted(
            (*sorted((name_of[k.target], name_of[k.source])), k.kind) for k in result.links
        )

    assert pairs(shuffled, names) == pairs(walk, [f"scan_{k:02d}" for k in range(len(order))])
    assert len(shuffled.tried) == len(walk.tried)
    inv0 = np.linalg.inv(route.poses[0])
    for k, scan in enumerate(order):
        a, b = walk.solution.scans[scan], shuffled.solution.scans[k]
        assert a.status is b.status is NodeStatus.OK, (scan, a.reason, b.reason)
        assert _right(b.T_world_scan, inv0 @ route.poses[scan]), scan
        rot, trans = transform_errors(a.T_world_scan, b.T_world_scan)  # the same links, the
        assert rot < 1e-4 and trans < 1e-5, (scan, rot, trans)  # scans numbered otherwise


@pytest.mark.slow
def test_a_pair_s_coarse_match_is_the_same_whichever_scan_came_first(tmp_path):
    """Two scans given either way round: the coarse match that places the second is computed
    on the scan whose content sorts first, so both campaigns keep the same pose, inverted
    (to rounding: the search is not symmetric, and a pixel's difference swayed which
    neighbours a scan of a long route was registered to)."""
    route = sim.route(seed=4, n_scans=2, rays=(600, 90))
    files = sim.write_survey(route, tmp_path / "scans")
    found = []
    for order in (files, files[::-1]):
        campaign = Campaign(Config(), tmp_path / f"out{len(found)}", WorkerPool(1))
        try:
            campaign.add_scans(order)
        finally:
            campaign.close()
        found.append(campaign.coarse[(0, 1)].T_target_source)
    np.testing.assert_allclose(found[0], np.linalg.inv(found[1]), rtol=0, atol=1e-12)


@pytest.mark.slow
def test_scans_landing_one_by_one_out_of_time_order_are_walked_by_their_times(tmp_path):
    """Field mode's campaign fed a scan at a time, the files copied from the card in an order
    of their own: each new scan is matched first with its neighbours in time already there,
    and the campaign ends where the same scans given at once end."""
    route = sim.route(seed=3, n_scans=8, rays=(1500, 200))
    files = sim.write_survey(route, tmp_path / "scans", times=True)
    at_once = run_chain(files, Config(), tmp_path / "a", jobs=2)
    landed = [5, 2, 7, 0, 3, 6, 1, 4]  # file k of the campaign is scan landed[k] of the walk
    campaign = Campaign(Config(), tmp_path / "b", WorkerPool(2))
    try:
        for scan in landed:
            campaign.add_scan(files[scan])
        assert [landed[k] for k in campaign.walk.order] == list(range(8)) and campaign.walked
        one_by_one = campaign.result()
    finally:
        campaign.close()
    a = at_once.solution.scans
    b = [one_by_one.solution.scans[landed.index(scan)] for scan in range(8)]
    assert all(x.status is y.status is NodeStatus.OK for x, y in zip(a, b, strict=True))
    for k in range(1, 8):  # each scan in the frame of the walk's first scan
        T_a = np.linalg.inv(a[0].T_world_scan) @ a[k].T_world_scan
        T_b = np.linalg.inv(b[0].T_world_scan) @ b[k].T_world_scan
        rot, trans = transform_errors(T_a, T_b)  # networks of a few other links, scans up to
        assert rot < 0.01 and trans < 0.01, (k, rot, trans)  # 112 m away: within a centimetre
        assert _right(T_b, route.relative(0, k)), k
