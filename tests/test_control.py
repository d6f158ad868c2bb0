"""Control stations: the file, and the world they give a network (levelled, or theirs)."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest
from test_adjust import CHAIN, SKIPS, measured, rot

from ndt_cli.core.transforms import rotation4, transform_errors
from ndt_cli.errors import InputError
from ndt_cli.pipeline.adjust import Solver
from ndt_cli.pipeline.control import (
    DEFAULT_SIGMA_XY,
    DEFAULT_SIGMA_Z,
    SIGMA_RANGE_M,
    Control,
    Station,
    read_control,
)
from ndt_cli.pipeline.datum import Cluster, datum, not_georeferenced

NAMES = ("north/scan_0.laz", "scan_1.laz", "campaign.e57#2")


def _file(tmp_path, text: str):
    p = tmp_path / "control.csv"
    p.write_text(text, encoding="utf-8")
    return p


def test_a_control_file_names_scans_as_the_outputs_do(tmp_path):
    text = (
        "scan,x,y,z,sigma_xy,sigma_z\n"
        "# GNSS on the scanner\n"
        "north/scan_0.laz,500000.125,5400000.5,101.25,0.01,0.015\n"
        "scan_1.laz, 500030.0 , 5400001.0, 102.0,,\n"
        "campaign.e57#2,500060,5400002,103,,\n"
    )
    got = read_control(_file(tmp_path, text), NAMES)
    assert [c.scan for c in got] == [0, 1, 2]
    np.testing.assert_array_equal(got[0].xyz, [500000.125, 5400000.5, 101.25])
    assert (got[0].sigma_xy, got[0].sigma_z) == (0.01, 0.015)
    assert (got[1].sigma_xy, got[1].sigma_z) == (DEFAULT_SIGMA_XY, DEFAULT_SIGMA_Z)
    assert got[2].name == "campaign.e57#2"
    by_file = read_control(_file(tmp_path, "scan_0.laz,1,2,3\n"), NAMES)  # the file's name
    assert by_file[0].scan == 0


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("scan_9.laz,1,2,3\n", "line 1: no scan named 'scan_9.laz'"),
        ("scan,x,y,z\nscan_1.laz,1,nan,3\n", "line 2: y is not finite"),
        ("scan_1.laz,1,2,3,0,0.1\n", "line 1: standard deviations must be positive"),
        ("scan_1.laz,1,2,3\nscan_1.laz,1,2,3\n", "line 2: scan 'scan_1.laz' is given twice"),
        ("scan_1.laz,1,2\n", "line 1: 3 fields; expected 'scan,x,y,z'"),
        ("scan_1.laz,1,2,east\n", "line 1: z 'east' is not a number"),
        ("# nothing\n", "no station in the control file"),
    ],
)
def test_every_problem_of_a_control_file_is_one_line_naming_it(tmp_path, text, needle):
    with pytest.raises(InputError, match=needle) as err:
        read_control(_file(tmp_path, text), NAMES)
    assert "control.csv" in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(InputError, match="control file not found"):
        read_control(tmp_path / "missing.csv", NAMES)


def _sloped_street(rng, n: int = 8, grade: float = 0.05) -> list[np.ndarray]:
    """True T_world_scan of scanners along a street rising ``grade`` (5 %), each tilted up to
    1 deg."""
    poses = []
    for k in range(n):
        x = 18.0 * k
        R = rot([*np.radians(rng.uniform(-1, 1, 2)), rng.uniform(-np.pi, np.pi)])
        T = rotation4(R)
        T[:3, 3] = [x, 2.0 * np.sin(k), grade * x + 1.6]
        poses.append(T)
    return poses


def _network(rng, truth, vertical_noise_deg: float = 0.02):
    """The network as the adjustment leaves it (poses in the anchor's frame, scans' reduction
    points at their origins), each scan's vertical with noise, and a solver of its links."""
    edges = [measured(truth, i, j, rng) for i, j in CHAIN + SKIPS]
    anchor_frame = [np.linalg.inv(truth[0]) @ T for T in truth]
    ups = {}
    for k, T in enumerate(truth):
        up = T[:3, :3].T @ [0.0, 0.0, 1.0]
        up = up + np.radians(vertical_noise_deg) * rng.normal(size=3)
        ups[k] = up / np.linalg.norm(up)
    cluster = Cluster(
        dict(enumerate(anchor_frame)),
        {k: np.zeros(3) for k in range(len(truth))},
        ups,
        dict.fromkeys(range(len(truth)), "structures"),
        0,
    )
    solver = Solver(len(truth), 0, edges, None, "huber", 4.74, 100)
    return cluster, solver, list(range(len(edges)))


def test_without_control_the_world_is_levelled_at_the_anchor():
    rng = np.random.default_rng(3)
    truth = _sloped_street(rng)
    cluster, solver, kept = _network(rng, truth)
    world = datum(cluster, (), solver, kept)
    assert world.frame == "levelled"
    for k, T in world.poses.items():
        up_error = np.degrees(np.arccos(np.clip(T[2, :3] @ truth[k][2, :3], -1, 1)))
        assert up_error < 0.02, (k, up_error)  # 8 verticals of 0.02 deg, averaged
    np.testing.assert_allclose(world.poses[0][:3, 3], 0.0, atol=1e-12)  # its ground point kept
    assert abs(world.poses[0][1, 0]) < 1e-3  # its x axis tipped horizontal, not turned about z


def test_stations_put_the_network_in_their_coordinates_and_a_blunder_is_rejected():
    rng = np.random.default_rng(4)
    truth = _sloped_street(rng)
    E = np.eye(4)
    E[:3, :3] = rot([0.0, 0.0, 0.7])
    E[:3, 3] = [500_000.0, 5_400_000.0, 230.0]  # UTM-like coordinates
    crs = [E @ T for T in truth]
    cluster, solver, kept = _network(rng, truth)
    noise = rng.normal(0.0, [0.01, 0.01, 0.015], (3, 3))
    stations = [
        Control(k, f"s{k}", crs[k][:3, 3] + e) for k, e in zip((0, 3, 7), noise, strict=True)
    ]
    blunder = Control(5, "s5", crs[5][:3, 3] + [0.6, 0.0, 0.0])
    world = datum(cluster, (*stations, blunder), solver, kept)
    assert world.frame == "control"
    for k, T in world.poses.items():
        rot_err, trans = transform_errors(T, crs[k])
        assert rot_err < 0.05 and trans < 0.03, (k, rot_err, trans)
    fits = {f.control.name: f for f in world.controls}
    assert not fits["s5"].used and "rejected" in fits["s5"].reason
    assert fits["s5"].residual[0] == pytest.approx(-0.6, abs=0.05)  # adjusted minus given
    assert all(fits[c.name].used for c in stations)
    assert all(np.abs(fits[c.name].residual).max() < 0.05 for c in stations)
    assert set(world.covariances) == set(world.poses)


def test_one_station_moves_the_levelled_frame_two_that_disagree_are_both_given_up():
    rng = np.random.default_rng(5)
    truth = _sloped_street(rng)
    cluster, solver, kept = _network(rng, truth)
    one = datum(cluster, (Control(2, "s2", np.array([10.0, 20.0, 30.0])),), solver, kept)
    assert one.frame == "control, heading from the anchor"
    np.testing.assert_allclose(one.poses[2][:3, 3], [10.0, 20.0, 30.0], atol=1e-9)
    a = Control(0, "s0", truth[0][:3, 3])
    b = Control(4, "s4", truth[4][:3, 3] + [5.0, 0.0, 0.0])  # 5 m too far from a
    two = datum(cluster, (a, b), solver, kept)
    assert two.frame == "levelled" and not any(f.used for f in two.controls)
    given = np.linalg.norm(b.xyz - a.xyz)
    true = np.linalg.norm(truth[4][:3, 3] - truth[0][:3, 3])
    assert f"{given:.2f} m apart, their scanners {true:.2f} m" in two.problem
    assert "which is wrong cannot be told" in two.problem


def test_scans_near_by_known_positions_are_candidates_within_radius_and_sigmas():
    from ndt_cli.pipeline.discovery import near_by_position

    positions = {
        0: (np.array([0.0, 0.0]), 0.02),
        1: (np.array([30.0, 0.0]), 0.02),  # 30 m: within 25 m + 3 sigmas? no (0.08 m)
        2: (np.array([20.0, 5.0]), 0.02),  # 20.6 m: yes
        3: (np.array([31.0, 0.0]), 3.0),  # 31 m, but a coarse GNSS fix of 3 m: yes
        4: (np.array([5.0, 0.0]), 0.02),  # nearest, and not a candidate
    }
    assert near_by_position(0, positions, [1, 2, 3], 25.0, 5) == [2, 3]
    assert near_by_position(0, positions, [1, 2, 3, 4], 25.0, 2) == [4, 2]
    assert near_by_position(5, positions, [0, 1], 25.0, 2) == []  # no position of its own


def test_excel_csv_utf8_with_its_byte_order_mark_and_crlf_is_read(tmp_path):
    """Excel's "CSV UTF-8" starts with a byte-order mark and ends lines with CR LF."""
    p = tmp_path / "control.csv"
    rows = "scan,x,y,z,sigma_xy,sigma_z\r\nscan_1.laz,500030.5,5400001.25,102.0,0.01,\r\n"
    p.write_bytes(b"\xef\xbb\xbf" + rows.encode())
    got = read_control(p, NAMES)
    assert [c.scan for c in got] == [1]
    np.testing.assert_array_equal(got[0].xyz, [500030.5, 5400001.25, 102.0])
    assert (got[0].sigma_xy, got[0].sigma_z) == (0.01, DEFAULT_SIGMA_Z)


HEADER = "scan,x,y,z,sigma_xy,sigma_z\n"


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (  # a decimal comma splits a coordinate in two: seven fields
            HEADER + "scan_1.laz,500184,9872,5400001.5,102.0,,\n",
            "line 2: 7 fields where the header has 6 (a decimal comma? write 500184.9872)",
        ),
        (HEADER + "scan_1.laz,500184.98,5400001.5,102.0\n", "line 2: 4 fields where the header"),
        (
            "scan_1.laz;500184,98;5400001,5;102,0\n",
            "line 1: fields separated by semicolons: separate them with commas",
        ),
        (  # northing and height swapped: a height in the millions
            "scan_1.laz,500184.98,102.0,5400001.5\n",
            "line 1: column z: 5,400,001.500 m is no height",
        ),
        ("scan_1.laz,1e300,1e300,1e300\n", "line 1: column x: 1e+300 m is no coordinate"),
        ("scan_1.laz,1,2,3,1e300,1e300\n", "line 1: sigma_xy 1e+300 m is out of range"),
        ("scan_1.laz,1,2,3,0.01,1e-300\n", "line 1: sigma_z 1e-300 m is out of range"),
        (",1,2,3\n", "line 1: no scan named (the first field is empty)"),
        (HEADER.replace("\n", ",extra\n") + "scan_1.laz,1,2,3,,,\n", "line 1: a header must"),
        ("name,easting,northing,height\nscan_1.laz,1,2,3\n", "line 1: a header must read"),
        ("scan_1.laz\t1\t2\t3\n", "line 1: fields separated by tabs"),
        (HEADER + "scan_1.laz,1,2,3,,\n" + HEADER, "line 3: a header again (two files joined?)"),
    ],
)
def test_a_row_that_cannot_be_read_as_written_is_one_line_naming_it(tmp_path, text, needle):
    with pytest.raises(InputError, match=re.escape(needle)) as err:
        read_control(_file(tmp_path, text), NAMES)
    assert "control.csv" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("row", "needle"),
    [
        ("scan.laz,1,2,3", "'scan.laz' names 2 scans (north/scan.laz, south/scan.laz)"),
        ("street.e57,1,2,3", "line 1: 'street.e57' holds 3 scans: name one as street.e57#0"),
    ],
)
def test_a_name_that_several_scans_share_is_an_error_not_the_last_of_them(tmp_path, row, needle):
    names = ("north/scan.laz", "south/scan.laz", "street.e57#0", "street.e57#1", "street.e57#2")
    with pytest.raises(InputError, match=re.escape(needle)):
        read_control(_file(tmp_path, row + "\n"), names)
    exact = read_control(_file(tmp_path, "south/scan.laz,1,2,3\nstreet.e57#0,4,5,6\n"), names)
    assert [c.scan for c in exact] == [1, 2]


def _in_crs(truth: list[np.ndarray]) -> list[np.ndarray]:
    """The truth in UTM-like coordinates: turned 0.7 rad about the vertical and moved."""
    E = np.eye(4)
    E[:3, :3] = rot([0.0, 0.0, 0.7])
    E[:3, 3] = [500_000.0, 5_400_000.0, 230.0]
    return [E @ T for T in truth]


def _gnss(crs: list[np.ndarray], scans, rng, swap=None) -> list[Control]:
    """GNSS stations (1 cm / 1.5 cm noise) on ``scans``; ``swap``: two scans whose point
    numbers were swapped (each row carries the other's coordinates)."""
    at = {k: crs[k][:3, 3] + rng.normal(0.0, [0.01, 0.01, 0.015]) for k in scans}
    a, b = swap or (None, None)
    other = {a: b, b: a}
    return [Control(k, f"s{k}", at[other.get(k, k)]) for k in scans]


def test_two_swapped_stations_among_five_are_rejected_and_the_three_right_ones_kept():
    """The two ends of a level street swapped (a wrong point number on each; on a slope their
    heights would tell): the network is not flipped by 180 deg onto them, the consistent
    majority places it."""
    rng = np.random.default_rng(4)
    truth = _sloped_street(rng, grade=0.0)
    crs = _in_crs(truth)
    cluster, solver, kept = _network(rng, truth)
    world = datum(cluster, _gnss(crs, (0, 2, 4, 5, 7), rng, swap=(0, 7)), solver, kept)
    assert world.frame == "control" and not world.problem
    for k, T in world.poses.items():
        rot_err, trans = transform_errors(T, crs[k])
        assert rot_err < 0.05 and trans < 0.03, (k, rot_err, trans)
    used = {f.control.name for f in world.controls if f.used}
    assert used == {"s2", "s4", "s5"}
    swap = np.linalg.norm(crs[7][:3, 3] - crs[0][:3, 3])
    for f in world.controls:
        if not f.used:  # each is off by the distance between the two ends
            assert "rejected" in f.reason
            assert np.linalg.norm(f.residual) == pytest.approx(swap, abs=0.1)


def test_two_stations_against_two_is_never_georeferenced():
    rng = np.random.default_rng(4)
    truth = _sloped_street(rng, grade=0.0)
    cluster, solver, kept = _network(rng, truth)
    world = datum(cluster, _gnss(_in_crs(truth), (0, 2, 5, 7), rng, swap=(0, 7)), solver, kept)
    assert world.frame == "levelled" and not any(f.used for f in world.controls)
    assert "2 against 2 (s0, s7 | s2, s5)" in world.problem
    assert "which is right cannot be told" in world.problem
    assert not_georeferenced(world, _stations(4), [f"s{k}" for k in range(8)]).startswith(
        "0 of 4 control station(s) in use, 2 needed: the stations form groups"
    )


def _stations(n: int) -> tuple[Station, ...]:
    return tuple(Station(f"s{k}", k + 1, np.zeros(3), 0.02, 0.03) for k in range(n))


@pytest.mark.parametrize(
    ("given", "problem"),
    [
        (  # a mirror keeps the distances: two stations fit it turned, four mirrored
            lambda q: q[:, [1, 0, 2]],
            "2 of the 4 stations agree with the network as given, 4 fit it mirrored: are x and y "
            "(easting, northing) swapped?",
        ),
        (
            lambda q: q / 0.3048,
            "0 of the 4 stations agree with the network as given, 4 fit it with distances 3.2808 "
            "times the network's: coordinates in feet (0.3048 m), or on a map projection's grid "
            "without --crs?",
        ),
    ],
)
def test_control_that_fits_no_placement_says_the_likely_cause(given, problem):
    """Without --crs nothing checks the columns or the unit before the run: the stations then
    agree with no placement of the network, and the message says why."""
    rng = np.random.default_rng(7)
    truth = _sloped_street(rng)
    cluster, solver, kept = _network(rng, truth)
    right = np.array([T[:3, 3] for T in _in_crs(truth)])
    scans = (0, 2, 4, 7)
    q = given(right[list(scans)])
    world = datum(
        cluster, [Control(k, f"s{k}", xyz) for k, xyz in zip(scans, q, strict=True)], solver, kept
    )
    assert world.frame == "levelled" and not any(f.used for f in world.controls)
    assert world.problem == problem


def test_standard_deviations_at_the_ends_of_their_range_solve():
    """0.1 mm and 1 km: the adjustment's weights stay finite (they gave a traceback at 1e-300
    and 1e300)."""
    rng = np.random.default_rng(8)
    truth = _sloped_street(rng)
    crs = _in_crs(truth)
    cluster, solver, kept = _network(rng, truth)
    lo, hi = SIGMA_RANGE_M
    stations = [Control(0, "s0", crs[0][:3, 3], lo, lo), Control(7, "s7", crs[7][:3, 3], hi, hi)]
    stations.append(Control(4, "s4", crs[4][:3, 3]))
    world = datum(cluster, stations, solver, kept)
    assert world.frame == "control"
    assert transform_errors(world.poses[0], crs[0])[1] < 0.01


def test_the_campaign_is_not_georeferenced_when_fewer_than_two_stations_are_in_use():
    rng = np.random.default_rng(9)
    truth = _sloped_street(rng)
    crs = _in_crs(truth)
    cluster, solver, kept = _network(rng, truth)
    names = [f"s{k}" for k in range(8)]
    one = datum(cluster, [Control(3, "s3", crs[3][:3, 3])], solver, kept)
    assert not_georeferenced(one, _stations(1), names) == ""  # one station: a one-station world
    two = [Control(3, "s3", crs[3][:3, 3]), Control(5, "s5", crs[5][:3, 3])]
    assert not_georeferenced(datum(cluster, two, solver, kept), _stations(2), names) == ""
    outside = replace(cluster, poses={k: T for k, T in cluster.poses.items() if k != 5})
    lone = datum(outside, two, solver, kept[:0])
    assert lone.frame == "control, heading from the anchor"
    why = not_georeferenced(lone, _stations(2), names)
    assert why == (
        "1 of 2 control station(s) in use, 2 needed: 1 on scans no link ties to the anchor (s5)"
    )
    typo = (*_stations(1), Station("s_9", 7, np.zeros(3), 0.02, 0.03))  # its scan never came
    why = not_georeferenced(one, typo, names)
    assert why == ("1 of 2 control station(s) in use, 2 needed: line 7: no scan named 's_9'")
    assert "the anchor has no link yet" in not_georeferenced(None, typo, names)


@pytest.mark.parametrize(
    ("blunders", "georeferenced"),
    [
        ({7: [5.0, 0.0, 0.0]}, True),  # two right, one 5 m off: the two place the street
        ({0: [5.0, 0.0, 0.0], 5: [0.0, -7.0, 0.0], 7: [-4.0, 6.0, 0.0]}, False),  # 2 of 5 agree
    ],
)
def test_the_stations_that_agree_must_be_the_majority(blunders, georeferenced):
    rng = np.random.default_rng(10)
    truth = _sloped_street(rng, grade=0.0)
    crs = _in_crs(truth)
    cluster, solver, kept = _network(rng, truth)
    scans = (2, 4, 7) if len(blunders) == 1 else (0, 2, 4, 5, 7)
    stations = [Control(k, f"s{k}", crs[k][:3, 3] + blunders.get(k, 0.0)) for k in scans]
    world = datum(cluster, stations, solver, kept)
    used = {f.control.name for f in world.controls if f.used}
    if georeferenced:
        assert world.frame == "control" and used == {"s2", "s4"}
        assert all(transform_errors(T, crs[k])[1] < 0.03 for k, T in world.poses.items())
    else:
        assert world.frame == "levelled" and not used
        assert world.problem == (
            "only 2 of the 5 stations agree with one placement of the network (s2, s4): not a "
            "majority, which are right cannot be told"
        )
