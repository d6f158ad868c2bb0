"""Benchmark of the global adjustment and the link verification on a simulated network.

A serpentine street of ``--nodes`` scanners (rows of 50, 15 m apart; rows 30 m apart) with
links to the next, the second-next and (mostly) the third-next scanner, plus loop links to the
nearest scanner of the next row: about 3 links per node. Each link carries noise drawn from its
own covariance (0.01-0.02 deg, 3-6 mm); ``--outliers`` trusted links are metres off; a share
``--untrusted`` of the links is untrusted (a fifth of those wrong). Figures are printed, never
asserted; times come from a shared machine.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/adjust_bench.py [--nodes 1000]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from importlib.metadata import version
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import gtsam  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from ndt_cli.pipeline.adjust import adjust  # noqa: E402
from ndt_cli.pipeline.graph import Edge  # noqa: E402
from ndt_cli.pipeline.verify import EdgeState, NodeStatus, verify  # noqa: E402

ROW = 50


def network_pairs(n: int) -> list[tuple[int, int]]:
    """(target, source) of every link: next, second-next, most third-next, loops across rows."""
    pairs = [(i, i + 1) for i in range(n - 1)] + [(i, i + 2) for i in range(n - 2)]
    pairs += [(i, i + 3) for i in range(n - 3) if i % 5 != 0]
    for i in range(0, n - ROW, 5):  # the scanner facing i in the next row (serpentine)
        j = (i // ROW + 1) * ROW + (ROW - 1 - i % ROW)
        if j < n and abs(j - i) > 3:
            pairs.append((i, j))
    return pairs


def truth_poses(n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """``T_world_scan`` along the serpentine: random headings, small tilts, world = node 0."""
    poses = []
    for k in range(n):
        row, col = divmod(k, ROW)
        x = 15.0 * (col if row % 2 == 0 else ROW - 1 - col)
        T = np.eye(4)
        tilt = rng.normal(0, 0.004, 2)
        T[:3, :3] = Rotation.from_rotvec([*tilt, rng.uniform(-np.pi, np.pi)]).as_matrix()
        T[:3, 3] = [x, 30.0 * row, rng.normal(0, 0.3)]
        poses.append(T)
    world = np.linalg.inv(poses[0])
    return [world @ T for T in poses]


def link_covariance(rng: np.random.Generator) -> np.ndarray:
    M = np.zeros((6, 6))
    M[:3, :3] = Rotation.from_rotvec(rng.normal(0, 1, 3)).as_matrix() @ np.diag(
        np.radians([0.01, 0.012, 0.02])
    )
    M[3:, 3:] = Rotation.from_rotvec(rng.normal(0, 1, 3)).as_matrix() @ np.diag(
        [0.003, 0.004, 0.006]
    )
    B = np.eye(6) + 0.1 * rng.normal(size=(6, 6))
    C = M @ B @ B.T @ M.T
    return 0.5 * (C + C.T)


def make_edges(
    truth: list[np.ndarray], pairs: list[tuple[int, int]], args: argparse.Namespace
) -> tuple[list[Edge], list[Edge], set[int]]:
    """Noisy links, the same links without the gross errors, and which links are wrong."""
    rng = np.random.default_rng(args.seed + 1)
    k_untrusted = set(rng.choice(len(pairs), int(args.untrusted * len(pairs)), replace=False))
    wrong = set(rng.choice(len(pairs), args.outliers, replace=False))
    wrong |= set(sorted(k_untrusted)[: len(k_untrusted) // 5])
    edges, clean = [], []
    for k, (i, j) in enumerate(pairs):
        C = link_covariance(rng)
        noise = gtsam.Pose3.Expmap(rng.multivariate_normal(np.zeros(6), C)).matrix()
        T = np.linalg.inv(truth[i]) @ truth[j] @ noise
        clean.append(Edge(i, j, T, C))
        if k in wrong:
            T = T.copy()
            T[:3, 3] += rng.normal(0, 1.5, 3)
        edges.append(Edge(i, j, T, C, trusted=k not in k_untrusted))
    return edges, clean, wrong


def chained(edges: list[Edge], n: int) -> list[np.ndarray]:
    by_pair = {(e.target, e.source): e.T_target_source for e in edges}
    poses = [np.eye(4)]
    for i in range(n - 1):
        poses.append(poses[-1] @ by_pair[(i, i + 1)])
    return poses


def error_m(poses, truth) -> tuple[float, float]:
    e = [np.linalg.norm(P[:3, 3] - T[:3, 3]) for P, T in zip(poses, truth, strict=True)]
    return float(np.mean(e)), float(np.max(e))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=1000)
    parser.add_argument("--outliers", type=int, default=5)
    parser.add_argument("--untrusted", type=float, default=0.03)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    truth = truth_poses(args.nodes, np.random.default_rng(args.seed))
    edges, clean, wrong = make_edges(truth, network_pairs(args.nodes), args)
    n_untrusted = sum(not e.trusted for e in edges)
    print(f"{platform.machine()}, {os.cpu_count()} cores, gtsam {version('gtsam')}")
    print(f"{args.nodes} nodes, {len(edges)} links: {len(wrong)} wrong, {n_untrusted} untrusted")
    t0 = time.perf_counter()
    plain = adjust(args.nodes, 0, clean)
    total = time.perf_counter() - t0
    print(
        f"adjust (links without gross errors): {total:.2f} s = solve {plain.solve_s:.2f} s "
        f"({plain.iterations} it) + marginals {plain.marginals_s:.2f} s + set-up; "
        "error mean / max {:.4f} / {:.4f} m".format(*error_m(plain.poses, truth))
    )
    adjacent = [e for e in clean if e.source == e.target + 1]
    if len(adjacent) == args.nodes - 1:
        mean, worst = error_m(chained(adjacent, args.nodes), truth)
        print(f"chained next-scan links: error mean / max {mean:.4f} / {worst:.4f} m")
    for batch in (False, True):
        result = verify(args.nodes, 0, edges, batch=batch)
        t = result.timings
        print(
            f"verify ({'batch' if batch else 'one at a time'}): {result.time_s:.2f} s = "
            f"{result.solves} solves {t['solve_s']:.2f} s + untrusted tests {t['test_s']:.2f} s "
            f"+ marginals {t['marginals_s']:.2f} s + set-up"
        )
        print(f"  {result!r}")
        rejected = {k for k, s in enumerate(result.states()) if s is EdgeState.REJECTED}
        print(
            f"  wrong links rejected {len(wrong & rejected)}/{len(wrong)}, correct links "
            f"rejected {len(rejected - wrong)}, nodes ok "
            f"{sum(s is NodeStatus.OK for s in result.statuses())}/{args.nodes}; "
            "error mean / max {:.4f} / {:.4f} m".format(*error_m(result.poses, truth))
        )


if __name__ == "__main__":
    main()
