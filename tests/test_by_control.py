"""Control places a scan: the control frame in a group's frame from its stations, and the
guesses of a lone scan's links from its station."""

from __future__ import annotations

import numpy as np

from ndt_cli.core.transforms import pose2d_matrix
from ndt_cli.pipeline.by_control import MAX_FRAME_MISFIT, frame_of, home_group, station_links
from ndt_cli.pipeline.discovery import Placed
from ndt_cli.pipeline.network import LinkKind

# the group's frame is the control's turned by 0.7 rad and shifted (what placement finds)
TURN, SHIFT = 0.7, np.array([-500_010.0, -5_400_020.0])
R_TRUE = np.array([[np.cos(TURN), -np.sin(TURN)], [np.sin(TURN), np.cos(TURN)]])
CONTROL = {k: np.array([500_000.0 + 30 * k, 5_400_000.0 + 4 * k * k, 100.0]) for k in range(4)}


def _placed(k: int, heading: float = 0.3) -> Placed:
    xy = R_TRUE @ CONTROL[k][:2] + R_TRUE @ SHIFT
    return Placed(0, pose2d_matrix(xy[0], xy[1], heading * k))


def test_two_stations_give_the_frame_and_a_misfit_or_one_station_gives_none():
    where = {k: _placed(k) for k in range(3)}
    R, t = frame_of({k: CONTROL[k] for k in (0, 1)}, where)
    np.testing.assert_allclose(R, R_TRUE, atol=1e-9)
    np.testing.assert_allclose(R @ CONTROL[3][:2] + t, R_TRUE @ (CONTROL[3][:2] + SHIFT), atol=1e-6)
    assert frame_of({0: CONTROL[0]}, where) is None
    assert frame_of({0: CONTROL[0], 3: CONTROL[3]}, where) is None  # scan 3 is not placed
    bad = {**CONTROL, 2: CONTROL[2] + [3 * MAX_FRAME_MISFIT, 0.0, 0.0]}
    assert frame_of({k: bad[k] for k in (0, 1, 2)}, where) is None
    mirrored = {k: CONTROL[k][[1, 0, 2]] for k in (0, 1, 2)}  # x and y swapped
    assert frame_of(mirrored, where) is None


def test_a_lone_scan_is_guessed_where_its_station_puts_it_heading_unknown():
    where = {k: _placed(k) for k in range(3)}
    frame = frame_of({k: CONTROL[k] for k in range(3)}, where)
    links = station_links(3, CONTROL[3], frame, where, [0, 1, 2], probes=2)
    assert [(k.target, k.source, k.kind) for k in links] == [
        (2, 3, LinkKind.FOUND),
        (1, 3, LinkKind.FOUND),
    ]
    truth = R_TRUE @ (CONTROL[3][:2] + SHIFT)  # scan 3 in the group's frame
    for k in links:
        in_group = where[k.target].T_group_scan @ k.guess.T_target_source
        np.testing.assert_allclose(in_group[:2, 3], truth, atol=1e-6)
        assert k.guess.sigma_deg == 180.0


def test_the_home_group_has_the_most_stations_the_anchor_s_on_a_tie():
    groups = [[0, 1, 2, 3], [4, 5], [6]]
    assert home_group(groups, {4: 0, 5: 0, 0: 0}, anchor=0) == [4, 5]
    assert home_group(groups, {4: 0, 0: 0}, anchor=0) == [0, 1, 2, 3]
    assert home_group(groups, {4: 0, 6: 0}, anchor=6) == [6]
    assert home_group([], {0: 0}, anchor=0) == []
