"""Marginal covariances of an ill-posed network: a result, never GTSAM's "indeterminate linear
system". The fallback's covariances are checked against GTSAM's own on a determined network,
and the free direction against the network's geometry."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from ndt_cli.pipeline.marginals import UNDETERMINED_VAR, _pseudo_inverse, marginal_covariances


def _graph(free_x: bool) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """Node 0 held; node 1 tied by a link that says nothing along x (when ``free_x``); node 2
    tied in full."""
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    precisions = np.array([1e4, 1e4, 1e4, 0.0 if free_x else 1e4, 1e4, 1e4])
    for k, at in ((1, [5.0, 0.0, 0.0]), (2, [0.0, 5.0, 0.0])):
        noise = gtsam.noiseModel.Diagonal.Precisions(precisions if k == 1 else np.full(6, 1e4))
        graph.add(gtsam.BetweenFactorPose3(0, k, gtsam.Pose3(gtsam.Rot3(), np.array(at)), noise))
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3())
    values.insert(1, gtsam.Pose3(gtsam.Rot3(), np.array([5.0, 0.0, 0.0])))
    values.insert(2, gtsam.Pose3(gtsam.Rot3(), np.array([0.0, 5.0, 0.0])))
    return graph, values


def test_the_fallback_equals_gtsams_marginals_on_a_determined_network():
    graph, values = _graph(free_x=False)
    reference = gtsam.Marginals(graph, values)
    mine = _pseudo_inverse(gtsam, graph, values, [0, 1, 2])
    for k in (0, 1, 2):
        expected = reference.marginalCovariance(k)
        np.testing.assert_allclose(mine[k], expected, rtol=1e-6, atol=1e-12)


def test_a_free_direction_is_undetermined_and_the_rest_as_gtsam_says():
    graph, values = _graph(free_x=True)
    with pytest.raises(RuntimeError, match="Indeterminate"):
        gtsam.Marginals(graph, values)  # what crashed the corridor's campaign
    covs = marginal_covariances(gtsam, graph, values, [1, 2])
    assert covs[1][3, 3] >= UNDETERMINED_VAR * 0.99  # x of node 1: free
    assert np.all(np.diag(covs[1])[[0, 1, 2, 4, 5]] < 1e-3)  # its rotation, y, z: known
    determined, _ = _graph(free_x=False)
    np.testing.assert_allclose(  # node 2 does not depend on node 1's free x
        covs[2], gtsam.Marginals(determined, values).marginalCovariance(2), rtol=1e-6, atol=1e-12
    )


def _corridor(n: int, free_last: bool) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """``n`` scans 16 m apart in a line, each tied to the one before it (rotation to 1e-4 rad,
    position to 1 cm); the last one's link says nothing along x when ``free_last``."""
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3())
    step = gtsam.Pose3(gtsam.Rot3(), np.array([16.0, 0.0, 0.0]))
    for k in range(1, n):
        precisions = np.array([1e8, 1e8, 1e8, 1e4, 1e4, 1e4])
        if free_last and k == n - 1:
            precisions[3] = 0.0
        noise = gtsam.noiseModel.Diagonal.Precisions(precisions)
        graph.add(gtsam.BetweenFactorPose3(k - 1, k, step, noise))
        values.insert(k, gtsam.Pose3(gtsam.Rot3(), np.array([16.0 * k, 0.0, 0.0])))
    return graph, values


@pytest.mark.slow
def test_a_long_corridor_keeps_its_determined_scans_determined():
    """Four hundred scans (6.4 km) and the last one free along x: the fallback gives the other
    scans GTSAM's covariances, not hundreds of metres (the anchor's prior beside a corridor's
    weakest directions put them within the decomposition's rounding)."""
    n = 400
    graph, values = _corridor(n, free_last=True)
    covs = marginal_covariances(gtsam, graph, values, range(n))
    reference = gtsam.Marginals(*_corridor(n - 1, free_last=False)[:1], values)
    for k in (1, 10, 100, n - 2):
        expected = reference.marginalCovariance(k)
        np.testing.assert_allclose(np.diag(covs[k]), np.diag(expected), rtol=1e-3)
    assert covs[n - 1][3, 3] >= UNDETERMINED_VAR * 0.99
