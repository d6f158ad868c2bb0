"""The scan network: links planned from where the scans are, redundant links checked against
each other, loops closed, a trustworthy status per scan. Every expected number comes from the
simulator's ground truth or is worked out by hand."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest
from conftest import street_files
from typer.testing import CliRunner

from ndt_cli import io, sim
from ndt_cli.cli import chain_app
from ndt_cli.config import Config
from ndt_cli.core.transforms import transform_errors
from ndt_cli.errors import InputError
from ndt_cli.io.matrices import read_pose_list
from ndt_cli.pipeline.chain import NetworkOptions, run_chain
from ndt_cli.pipeline.network import (
    LinkKind,
    classic_chain,
    default_radius,
    plan_near,
    read_pairs,
)
from ndt_cli.pipeline.verify import NodeStatus

runner = CliRunner()
ROT, TRANS = 0.3, 0.15  # deg, m: a pose within these of the truth is right


def _truth(poses: list[np.ndarray]) -> list[np.ndarray]:
    inv0 = np.linalg.inv(poses[0])
    return [inv0 @ T for T in poses]


def _right(T: np.ndarray | None, truth: np.ndarray) -> bool:
    if T is None:
        return False
    rot, trans = transform_errors(T, truth)
    return rot < ROT and trans < TRANS


def test_the_classic_chain_goes_around_unreadable_scans():
    pairs = [(k.target, k.source, k.kind) for k in classic_chain(5, {2})]
    A = LinkKind.ADJACENT
    assert pairs == [(0, 1, A), (1, 2, A), (1, 3, A), (3, 4, A)]


def _line(xs):
    return {k: np.array([x, 0.0]) for k, x in enumerate(xs)}


def test_each_scan_is_linked_to_its_nearest_within_the_radius():
    # scans on a line at 0, 10, 20, 35, 80 m: each one's two nearest within 16 m
    where = _line([0, 10, 20, 35, 80])
    pairs = plan_near([where], neighbours=2, radius=16.0)
    # nearest: 0 -> 1; 1 -> 0, 2; 2 -> 1, 3; 3 -> 2; 4 -> none within 16 m; the spanning
    # tree adds the shortest link that reaches scan 4 (3-4, 45 m)
    assert pairs == {(0, 1), (1, 2), (2, 3), (3, 4)}
    # within 21 m: 0 -> 1, 2; 1 -> 0, 2; 2 -> 1, 3, 0; 3 -> 2 (1 is 25 m away)
    assert plan_near([where], neighbours=4, radius=21.0) == {(0, 1), (0, 2), (1, 2), (2, 3), (3, 4)}


def test_the_spanning_tree_goes_around_pairs_that_failed():
    where = _line([0, 10, 20])
    # without 1-2 (failed), scan 2 is reached from scan 0 (20 m)
    assert plan_near([where], neighbours=1, radius=5.0, failed={(1, 2)}) == {(0, 1), (0, 2)}


def test_groups_are_planned_apart_and_the_radius_follows_the_spacing():
    a, b = _line([0, 10, 20]), {7: np.array([0.0, 0.0]), 9: np.array([0.0, 12.0])}
    assert plan_near([a, b], neighbours=1, radius=30.0) == {(0, 1), (1, 2), (7, 9)}
    # nearest-scan distances 10, 10, 10 and 12, 12: median 10 m
    assert default_radius([a, b]) == pytest.approx(22.0)
    assert np.isnan(default_radius([{3: np.zeros(2)}]))


def test_user_pairs_by_name_or_index(tmp_path):
    f = tmp_path / "pairs.csv"
    f.write_text("target,source\n# a comment\nscan_0.laz,scan_3.laz\n1,4\n")
    links = read_pairs(f, ["scan_0.laz", "scan_1.laz", "a/scan_2.laz", "scan_3.laz", "x.laz"])
    assert [(k.target, k.source, k.kind) for k in links] == [
        (0, 3, LinkKind.USER),
        (1, 4, LinkKind.USER),
    ]
    f.write_text("scan_0.laz,scan_1.laz\nscan_0.laz,nope.laz\n")
    with pytest.raises(InputError, match=r"line 2: no scan named 'nope\.laz'"):
        read_pairs(f, ["scan_0.laz", "scan_1.laz"])


@pytest.fixture(scope="module")
def street8(tmp_path_factory):
    """Eight scans of one street (13-17 m apart) as LAZ files, and their true poses."""
    return street_files(tmp_path_factory.mktemp("street8"), n_scans=8)


def _copy(files, folder):
    folder.mkdir()
    out = []
    for f in files:
        (folder / f.name).write_bytes(f.read_bytes())
        out.append(folder / f.name)
    return out


@pytest.mark.slow
def test_a_scan_from_another_street_is_never_ok_and_the_others_are(street8, tmp_path):
    files, poses = street8
    files = _copy(files, tmp_path / "scans")
    _, other, _ = sim.make_sequence(seed=77, n_scans=1, scan_kwargs={"n_azimuth": 1000})
    io.write(files[3], other[0])  # scan 3 is from another site
    out = tmp_path / "out"
    res = runner.invoke(chain_app, [*map(str, files), "-o", str(out), "-q", "-j", "2"])
    assert res.exit_code == 1, res.output
    truth = _truth(poses)
    rows = list(csv.DictReader((out / "poses.csv").read_text().splitlines()))
    ok = [k for k, r in enumerate(rows) if r["status"] == "ok"]
    assert 3 not in ok
    for k in ok:  # no scan is ok with a wrong pose
        T = np.array([float(rows[k][f"m{r}{c}"]) for r in range(4) for c in range(4)])
        assert _right(T.reshape(4, 4), truth[k]), k
    assert len(ok) >= 6
    listed = read_pose_list(out / "poses.txt")
    assert sorted(listed) == sorted(rows[k]["file"] for k in ok)  # poses.txt: ok scans only
    assert f"# {files[3].name}: " in (out / "poses.txt").read_text()  # the others, commented
    summary = json.loads((out / "summary.json").read_text())
    assert files[3].name in summary["network"]["scans_not_ok"]
    for row in rows:  # reasons name links by their scans, never by an index
        assert not re.search(r"link \d|T_\d+_\d+|links: \d", row["reason"]), row["reason"]


@pytest.mark.slow
def test_an_unreadable_scan_in_the_middle_is_bridged_by_the_skip_links(street8, tmp_path):
    files, poses = street8
    files = _copy(files, tmp_path / "scans")
    files[3].write_bytes(files[3].read_bytes()[:5000])  # truncated
    result = run_chain(files, Config(), tmp_path / "out", jobs=2)
    assert not result.ok
    truth, scans = _truth(poses), result.solution.scans
    assert scans[3].status is NodeStatus.UNPOSED and "unreadable" in scans[3].reason
    good = [k for k, s in enumerate(scans) if s.status is NodeStatus.OK]
    assert all(_right(scans[k].T_world_scan, truth[k]) for k in good)
    assert len(good) >= 6
    assert not [k for k in result.links if 3 in (k.target, k.source)]  # nothing to register


@pytest.mark.slow
def test_a_clean_street_is_all_ok_and_the_adjustment_is_no_worse(street8, tmp_path):
    files, poses = street8
    result = run_chain(files, Config(), tmp_path / "out", jobs=2)
    truth = _truth(poses)
    assert result.ok and all(s.sigma is not None for s in result.solution.scans)
    adjusted = [transform_errors(T, truth[k])[1] for k, T in enumerate(result.poses)]
    chained = [transform_errors(T, truth[k])[1] for k, T in enumerate(result.solution.chained)]
    assert max(adjusted) < TRANS
    assert np.mean(adjusted) <= np.mean(chained) + 0.002  # at least as good, to 2 mm
    # the uncertainty grows away from the anchor
    sigmas = [np.linalg.norm(s.sigma[:2]) for s in result.solution.scans]
    assert sigmas[0] < 1e-3 and sigmas[-1] > sigmas[1]


@pytest.mark.slow
def test_a_street_that_comes_back_to_its_start_closes_the_loop(tmp_path):
    out_leg = [(-60.0 + 14 * k, 2.5) for k in range(6)]
    back_leg = [(3.0 - 14 * k, -2.5) for k in range(5)] + [(-62.0, -2.5)]
    positions = np.array(out_leg + back_leg)
    _, scans, poses = sim.make_sequence(
        seed=41, n_scans=len(positions), positions=positions, scan_kwargs={"n_azimuth": 1000}
    )
    files = []
    for k, pts in enumerate(scans):
        files.append(tmp_path / f"loop_{k:02d}.laz")
        io.write(files[-1], pts)
    result = run_chain(files, Config(), tmp_path / "out", jobs=2)
    loops = [k for k in result.links if abs(k.target - k.source) > 3 and k.ok]  # found
    assert loops, [(k.target, k.source, k.status.value) for k in result.links]
    truth = _truth(poses)
    last = len(files) - 1
    adjusted = transform_errors(result.poses[last], truth[last])
    chained = transform_errors(result.solution.chained[last], truth[last])
    assert result.solution.scans[last].status is NodeStatus.OK
    assert adjusted[1] < chained[1], (adjusted, chained)
    assert adjusted[1] < TRANS and adjusted[0] < ROT


@pytest.mark.slow
def test_no_adjust_with_one_neighbour_is_the_classic_chain(street8, tmp_path):
    files, _ = street8
    net = NetworkOptions(neighbours=1, adjust=False)
    result = run_chain(files[:3], Config(), tmp_path / "out", jobs=1, network=net)
    assert [(k.target, k.source) for k in result.links] == [(0, 1), (1, 2)]
    assert result.solution.adjusted is False
    for k, T in enumerate(result.poses):  # the products of the links, as before
        expected = np.eye(4)
        for link in result.links[:k]:
            expected = expected @ link.T_target_source
        np.testing.assert_array_equal(T, expected)


NAMES = ["scan_0.laz", "scan_1.laz", "scan_2.laz", "scan_3.laz"]


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("scan_0.laz,scan_3.lz\n", r"line 1: no scan named 'scan_3\.lz'"),  # a typo
        ("0,4\n", r"line 1: no scan with index 4 \(0\.\.3\)"),
        ("0,\u00b2\n", "line 1: no scan named '\u00b2'"),  # int() refuses superscript digits
        ("0,1\n2,\u2461\n", "line 2: no scan named '\u2461'"),
    ],
)
def test_a_first_row_that_names_no_scan_is_an_error_not_a_header(tmp_path, text, needle):
    f = tmp_path / "pairs.csv"
    f.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=needle):
        read_pairs(f, NAMES)


def test_a_byte_order_mark_before_the_first_pair_is_read(tmp_path):
    f = tmp_path / "pairs.csv"
    f.write_bytes(b"\xef\xbb\xbf0,3\n")  # Excel's "CSV UTF-8"
    assert [(k.target, k.source) for k in read_pairs(f, NAMES)] == [(0, 3)]


@pytest.mark.slow
def test_memory_grows_with_the_distinct_pairs_not_the_rows(tmp_path):
    import tracemalloc

    f = tmp_path / "pairs.csv"
    f.write_text("0,1\n3,2\n" * 40_000)  # 320 kB, two distinct pairs
    tracemalloc.start()
    try:
        links = read_pairs(f, NAMES)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert [(k.target, k.source) for k in links] == [(0, 1), (3, 2)]
    assert peak < f.stat().st_size  # less than the file itself (a list of its rows: ~50x)


def test_reasons_name_the_links_by_their_scans():
    from ndt_cli.report.reasons import named_reason

    names = ("a.laz", "b.laz", "c.laz", "d.laz")
    used = [(0, 1), (1, 2), (0, 2), (2, 3)]  # the links the adjustment used, in its order
    assert named_reason("posed only through unused link 2 (T_0_2)", names, used) == (
        "posed only through unused link a.laz <- c.laz"
    )
    assert named_reason("only rejected links: 1, 3", names, used) == (
        "only rejected links: b.laz <- c.laz, c.laz <- d.laz"
    )
    why = "no ok link connects it to the anchor: link 1-3 failed; link 2-3 suspect"
    assert named_reason(why, names, used) == (
        "no ok link connects it to the anchor: link b.laz <- d.laz failed; "
        "link c.laz <- d.laz suspect"
    )
