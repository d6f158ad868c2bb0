"""Peer registration methods on one scan pair: open3d, small_gicp, KISS-Matcher (alone and
followed by small_gicp GICP) and PCL's command-line tools.

``peer_rows(target, source, T_target_source_gt)`` runs every peer that is installed twice:

* ``"no guess"``: identity start, or the peer's own global method (open3d FPFH + RANSAC, then ICP;
  KISS-Matcher, then small_gicp GICP);
* ``"guess 1 m / 2° off"``: start at ``T_gt @ D``, where ``D`` is a fixed perturbation in the
  source frame: ``guess_offset_m`` metres of horizontal translation along the direction 30° from
  the source x axis and ``guess_offset_deg`` degrees of yaw. The start itself therefore has
  errors of exactly ``guess_offset_deg`` / ``guess_offset_m`` by the measure below.

Each row: ``peer``, ``start``, ``wall_s``, ``rot_err_deg``, ``trans_err_m``, ``note``. The errors
are those of ``E = inv(T_gt) @ T_est``: its rotation angle (degrees) and the norm of its
translation (metres, the displacement of the source scanner centre).

Fixed parameters (the same for every pair; nothing is tuned per case):

* open3d point-to-plane ICP: voxel 0.15 m, normals from a 0.5 m / 30-neighbour search, maximum
  correspondence distance 1.0 m, at most 50 iterations.
* open3d FPFH + RANSAC: voxel 0.5 m, normals 1.0 m / 30, FPFH 2.5 m / 100, mutual matching,
  RANSAC with 3 points, 1.0 m inlier distance, edge-length checker 0.9, open3d's default
  criteria (100 000 iterations, confidence 0.999), random seed 0 (open3d runs RANSAC on all
  cores, so results may still vary between runs); then the ICP above from its result.
* small_gicp GICP and VGICP: its own voxel downsampling 0.15 m, maximum correspondence 1.0 m,
  VGICP voxels 1.0 m, at most 50 iterations, library-default thread count (1).
* KISS-Matcher (global: faster-PFH features, ROBIN max-clique pruning, GNC-TLS solver; no
  guess): voxel 0.3 m, the authors' setting for an outdoor scan pair (their KITTI Velodyne-64
  example; 0.2 m for their VLP-16 pair, 2.0 m for maps), every other parameter at the library's
  default (``use_quatro`` false, which the authors advise when roll and pitch are not
  negligible; at most 5000 correspondences; normal and FPFH radii 3 and 5 voxels; noise-bound
  gains 1.0 / 0.75); it runs on all cores (TBB). Then, as the authors recommend (their pipeline
  hands KISS-Matcher's result to small_gicp), small_gicp GICP with the parameters above from
  KISS-Matcher's result; that row's time is the sum of both calls.
* ``pcl_ndt3d``: ``-r 1.0`` (NDT grid), ``-f 0.2`` (its source voxel filter), ``-s 0.1`` (the
  tool's defaults) and ``-t 1e-6 -i 100``: PCL's NDT stops once a step is shorter than ``-t``, and
  with the default ``-t 0.01 -i 35`` it stops after about one step of the line search, barely
  moving from its start (said in the note).
* ``pcl_icp``: ``-d 1.0`` (maximum correspondence), ``-r 1.0``, ``-i 50``; the tool has no
  downsampling, so both clouds are voxel-downsampled to 0.15 m (centroids) here first.

The PCL tools take no initial guess: for the guess start the source is transformed by the guess
before it is written, and the tool's result is composed with it (said in the note).

The PCL tools print their transform to about 6 significant digits; its rotation is
re-orthonormalised (SVD) before the errors are computed.

Timing: ``wall_s`` is ``time.perf_counter`` around the whole peer call, including its own
downsampling, normal / covariance / feature estimation and, for the PCL tools, the process start
and the tool's reading and writing of PCD files (and the voxel downsampling done here for
``pcl_icp``). Not included: converting the numpy arrays to open3d point clouds, and writing the
input PCD files. KISS-Matcher's Python binding converts the (N,3) arrays point by point inside
the call (about 0.6 s per million points here): that is included, and the note gives the
library's own timers. Threads are the libraries' defaults (open3d and KISS-Matcher: all cores;
small_gicp and PCL: 1). Everything runs in this process, except the PCL tools (their own).

Run as a script: ``python benchmarks/peers.py target.laz source.laz T_target_source.txt``.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.metadata
import math
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository root importable
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ndt_cli.core.transforms import pose2d_matrix

NO_GUESS = "no guess"
NAN = float("nan")
GUESS_DIRECTION_DEG = 30.0  # horizontal direction of the guess's translation offset
TOOL_TIMEOUT_S = 1800.0

O3D_VOXEL = 0.15
O3D_NORMAL_RADIUS = 0.5
O3D_MAX_CORR = 1.0
O3D_ICP_ITER = 50
FPFH_VOXEL = 0.5
SG_VOXEL = 0.15
SG_MAX_CORR = 1.0
SG_VGICP_VOXEL = 1.0
SG_ITER = 50
KM_VOXEL = 0.3
PCL_NDT_ARGS = ("-r", "1.0", "-f", "0.2", "-s", "0.1", "-t", "1e-6", "-i", "100")
PCL_NDT_NOTE = "-t 1e-6 -i 100 (with -t 0.01 -i 35, the defaults, it stops after ~1 step)"
PCL_ICP_ARGS = ("-d", "1.0", "-r", "1.0", "-i", "50")
PCL_ICP_VOXEL = 0.15

Row = dict[str, object]


def guess_label(offset_m: float, offset_deg: float) -> str:
    """The ``start`` text of the guess rows, e.g. ``"guess 1 m / 2° off"``."""
    return f"guess {offset_m:g} m / {offset_deg:g}° off"


def perturbed_guess(T_gt: np.ndarray, offset_m: float, offset_deg: float) -> np.ndarray:
    """``T_gt`` composed with a fixed horizontal offset and yaw, applied in the source frame."""
    a = math.radians(GUESS_DIRECTION_DEG)
    D = pose2d_matrix(offset_m * math.cos(a), offset_m * math.sin(a), math.radians(offset_deg))
    return T_gt @ D


def errors(T_est: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    """Rotation angle (degrees) and translation norm (metres) of ``inv(T_gt) @ T_est``."""
    T_est = np.asarray(T_est, dtype=np.float64)
    if T_est.shape != (4, 4) or not np.all(np.isfinite(T_est)):
        return NAN, NAN
    E = np.linalg.inv(T_gt) @ T_est
    R = E[:3, :3]
    # atan2 form: accurate near 0 and 180 degrees, unlike arccos of the trace alone
    s = np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    angle = math.degrees(math.atan2(s, (np.trace(R) - 1.0) / 2.0))
    return angle, float(np.linalg.norm(E[:3, 3]))


def one_line(exc: BaseException, limit: int = 160) -> str:
    """First line of an exception's text, prefixed with its type, at most ``limit`` characters."""
    raw = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))  # ANSI colours (open3d)
    raw = re.sub(r"^\s*\[Open3D Error\] \(.*?\) \S+:\d+: ", "", raw, flags=re.S)  # its location
    text = raw.strip().splitlines()
    msg = f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")
    return msg if len(msg) <= limit else msg[: limit - 3] + "..."


def row(
    peer: str, start: str, wall_s: float, T_est: np.ndarray | None, T_gt: np.ndarray, note: str = ""
) -> Row:
    """One result row; ``T_est`` None gives NaN errors."""
    rot, trans = (NAN, NAN) if T_est is None else errors(T_est, T_gt)
    return {
        "peer": peer,
        "start": start,
        "wall_s": float(wall_s),
        "rot_err_deg": rot,
        "trans_err_m": trans,
        "note": note,
    }


def timed(
    peer: str,
    start: str,
    T_gt: np.ndarray,
    fn: Callable[[], tuple[np.ndarray | None, str]],
) -> Row:
    """Run ``fn`` (returning the estimate and a note) under a timer; an exception becomes a note."""
    t0 = time.perf_counter()
    try:
        T_est, note = fn()
    except Exception as exc:
        return row(peer, start, time.perf_counter() - t0, None, T_gt, one_line(exc))
    return row(peer, start, time.perf_counter() - t0, T_est, T_gt, note)


def not_installed(peer: str, T_gt: np.ndarray, why: str = "not installed") -> Row:
    """The single row of a peer that is missing."""
    return row(peer, "-", NAN, None, T_gt, why)


# --------------------------------------------------------------------------- open3d


def _o3d_prepared(o3d, pc, voxel: float, radius: float):
    """Voxel-downsampled copy of ``pc`` with normals."""
    down = pc.voxel_down_sample(voxel)
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    return down


def _o3d_icp(o3d, tgt, src, init: np.ndarray) -> tuple[np.ndarray, str]:
    """open3d point-to-plane ICP from ``init`` (its own downsampling and normals)."""
    reg = o3d.pipelines.registration
    t = _o3d_prepared(o3d, tgt, O3D_VOXEL, O3D_NORMAL_RADIUS)
    s = _o3d_prepared(o3d, src, O3D_VOXEL, O3D_NORMAL_RADIUS)
    res = reg.registration_icp(
        s,
        t,
        O3D_MAX_CORR,
        init,
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(max_iteration=O3D_ICP_ITER),
    )
    return np.asarray(res.transformation), f"ICP fitness {res.fitness:.2f}"


def _o3d_global(o3d, tgt, src) -> tuple[np.ndarray, str]:
    """open3d FPFH features, RANSAC on their matches, then the ICP above from its result."""
    reg = o3d.pipelines.registration
    o3d.utility.random.seed(0)
    t = _o3d_prepared(o3d, tgt, FPFH_VOXEL, 2 * FPFH_VOXEL)
    s = _o3d_prepared(o3d, src, FPFH_VOXEL, 2 * FPFH_VOXEL)
    feat = o3d.geometry.KDTreeSearchParamHybrid(radius=5 * FPFH_VOXEL, max_nn=100)
    ft = reg.compute_fpfh_feature(t, feat)
    fs = reg.compute_fpfh_feature(s, feat)
    dist = 2 * FPFH_VOXEL
    ransac = reg.registration_ransac_based_on_feature_matching(
        s,
        t,
        fs,
        ft,
        True,
        dist,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
            reg.CorrespondenceCheckerBasedOnDistance(dist),
        ],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    T, note = _o3d_icp(o3d, tgt, src, np.asarray(ransac.transformation))
    return T, f"RANSAC fitness {ransac.fitness:.2f}, {note}"


def open3d_rows(
    target: np.ndarray, source: np.ndarray, T_gt: np.ndarray, T_guess: np.ndarray, guess: str
) -> list[Row]:
    """open3d point-to-plane ICP (identity and guess starts) and FPFH + RANSAC + ICP."""
    try:
        import open3d as o3d
    except ImportError:
        return [not_installed("open3d point-to-plane ICP", T_gt)]
    except Exception as exc:  # a broken install (missing shared library, ...)
        return [not_installed("open3d point-to-plane ICP", T_gt, f"import failed: {one_line(exc)}")]
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    version = o3d.__version__.split("+")[0]
    tgt, src = (o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p)) for p in (target, source))
    # the conversion above is outside the timed calls
    name = f"open3d {version} point-to-plane ICP"
    return [
        timed(name, NO_GUESS, T_gt, lambda: _o3d_icp(o3d, tgt, src, np.eye(4))),
        timed(
            f"open3d {version} FPFH+RANSAC, ICP", NO_GUESS, T_gt, lambda: _o3d_global(o3d, tgt, src)
        ),
        timed(name, guess, T_gt, lambda: _o3d_icp(o3d, tgt, src, T_guess)),
    ]


# --------------------------------------------------------------------------- small_gicp


def small_gicp_rows(
    target: np.ndarray, source: np.ndarray, T_gt: np.ndarray, T_guess: np.ndarray, guess: str
) -> list[Row]:
    """small_gicp GICP and VGICP (its own downsampling and covariances) from both starts."""
    try:
        import small_gicp
    except ImportError:
        return [not_installed("small_gicp GICP", T_gt)]
    except Exception as exc:
        return [not_installed("small_gicp GICP", T_gt, f"import failed: {one_line(exc)}")]
    try:
        version = importlib.metadata.version("small_gicp")
    except importlib.metadata.PackageNotFoundError:
        version = "?"
    tgt = np.ascontiguousarray(target, dtype=np.float64)
    src = np.ascontiguousarray(source, dtype=np.float64)

    def run(kind: str, init: np.ndarray) -> tuple[np.ndarray, str]:
        res = small_gicp.align(
            tgt,
            src,
            init,
            registration_type=kind,
            voxel_resolution=SG_VGICP_VOXEL,
            downsampling_resolution=SG_VOXEL,
            max_correspondence_distance=SG_MAX_CORR,
            max_iterations=SG_ITER,
        )
        note = f"{res.iterations} it, {res.num_inliers} inliers"
        return np.asarray(res.T_target_source), note + ("" if res.converged else ", not converged")

    rows = []
    for kind in ("GICP", "VGICP"):
        name = f"small_gicp {version} {kind}"
        rows.append(timed(name, NO_GUESS, T_gt, lambda k=kind: run(k, np.eye(4))))
        rows.append(timed(name, guess, T_gt, lambda k=kind: run(k, T_guess)))
    return rows


# --------------------------------------------------------------------------- KISS-Matcher


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "?"


def kiss_matcher_rows(
    target: np.ndarray, source: np.ndarray, T_gt: np.ndarray, T_guess: np.ndarray, guess: str
) -> list[Row]:
    """KISS-Matcher (global, no guess), and the same followed by small_gicp GICP."""
    try:
        import kiss_matcher
    except ImportError:
        return [not_installed("KISS-Matcher", T_gt)]
    except Exception as exc:
        return [not_installed("KISS-Matcher", T_gt, f"import failed: {one_line(exc)}")]
    name = f"KISS-Matcher {_version('kiss-matcher')}"
    t0 = time.perf_counter()
    try:
        T, own = _kiss_match(kiss_matcher, target, source)
    except Exception as exc:
        return [row(name, NO_GUESS, time.perf_counter() - t0, None, T_gt, one_line(exc))]
    wall = time.perf_counter() - t0
    note = f"voxel {KM_VOXEL:g} m, defaults; {own}"
    rows = [row(name, NO_GUESS, wall, T, T_gt, note)]
    try:
        import small_gicp
    except Exception:
        return [*rows, not_installed(f"{name} + small_gicp GICP", T_gt, "small_gicp not installed")]
    then = f"{name} + small_gicp {_version('small_gicp')} GICP"
    t0 = time.perf_counter()
    res = small_gicp.align(
        np.ascontiguousarray(target, dtype=np.float64),
        np.ascontiguousarray(source, dtype=np.float64),
        T,
        registration_type="GICP",
        downsampling_resolution=SG_VOXEL,
        max_correspondence_distance=SG_MAX_CORR,
        max_iterations=SG_ITER,
    )
    gicp = time.perf_counter() - t0
    note = f"GICP {gicp:.2f} s, {res.iterations} it" + ("" if res.converged else ", not converged")
    return [*rows, row(then, NO_GUESS, wall + gicp, np.asarray(res.T_target_source), T_gt, note)]


def _kiss_match(km, target: np.ndarray, source: np.ndarray) -> tuple[np.ndarray, str]:
    """KISS-Matcher's T_target_source and a note of its own timers and inliers."""
    matcher = km.KISSMatcher(km.KISSMatcherConfig(KM_VOXEL))
    sol = matcher.estimate(source, target)  # maps source points onto the target
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = np.asarray(sol.rotation), np.asarray(sol.translation)
    parts = (
        matcher.get_processing_time(),
        matcher.get_extraction_time(),
        matcher.get_rejection_time(),
        matcher.get_matching_time(),
        matcher.get_solver_time(),
    )
    note = f"library timers {sum(parts):.2f} s, {matcher.get_num_final_inliers()} inliers"
    return T, note + ("" if sol.valid else ", not valid")


# --------------------------------------------------------------------------- PCL tools


def write_pcd(path: Path, points: np.ndarray) -> None:
    """Write (N,3) points as a binary PCD v0.7 file of float32 x y z."""
    data = np.ascontiguousarray(points, dtype="<f4")
    n = len(data)
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\n"
        f"TYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
        "DATA binary\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(data.tobytes())


def voxel_centroids(points: np.ndarray, voxel: float) -> np.ndarray:
    """Centroid of the points in each occupied cube of side ``voxel``."""
    ijk = np.floor((points - points.min(axis=0)) / voxel).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    sums = np.column_stack([np.bincount(inverse, weights=points[:, k]) for k in range(3)])
    return sums / counts[:, None]


_MATRIX_ROW = re.compile(
    r"^\s*(" + r"\s+".join([r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"] * 4) + r")\s*$"
)


def parse_last_matrix(text: str) -> np.ndarray | None:
    """The last block of four consecutive lines of four numbers in ``text`` (Eigen's print)."""
    lines = text.splitlines()
    for end in range(len(lines), 3, -1):
        block = lines[end - 4 : end]
        if all(_MATRIX_ROW.match(line) for line in block):
            T = np.array([[float(v) for v in line.split()] for line in block])
            if np.allclose(T[3], [0, 0, 0, 1], atol=1e-6):
                U, _, Vt = np.linalg.svd(T[:3, :3])  # printed to ~6 digits: re-orthonormalise
                T[:3, :3] = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
                T[3] = 0.0, 0.0, 0.0, 1.0
                return T
    return None


def pcl_version(exe: str) -> str:
    """PCL version from the shared libraries the tool links (``ldd``), or ``""``."""
    ldd = shutil.which("ldd")
    if ldd is None:
        return ""
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        out = subprocess.run([ldd, exe], capture_output=True, text=True, timeout=10).stdout
        m = re.search(r"libpcl_common\.so\.(\d+\.\d+)", out)
        if m:
            return m.group(1)
    return ""


def run_pcl_tool(
    exe: str,
    args: tuple[str, ...],
    target: np.ndarray,
    source: np.ndarray,
    T_init: np.ndarray,
    voxel: float | None,
) -> tuple[np.ndarray, float]:
    """Write the PCD files, run the tool in a scratch directory, parse its final transform.

    The source is pre-transformed by ``T_init`` (the tools take no initial guess); the result is
    ``T_tool @ T_init``. With ``voxel`` set, both clouds are first voxel-downsampled (timed).
    """
    with tempfile.TemporaryDirectory(prefix="peers_pcl_") as tmp:
        inputs, cwd = Path(tmp) / "in", Path(tmp) / "out"
        inputs.mkdir()
        cwd.mkdir()  # the tools save their results into the working directory
        src = source @ T_init[:3, :3].T + T_init[:3, 3]
        t0 = time.perf_counter()
        if voxel is not None:
            target, src = voxel_centroids(target, voxel), voxel_centroids(src, voxel)
        t_voxel = time.perf_counter() - t0
        write_pcd(inputs / "target.pcd", target)
        write_pcd(inputs / "source.pcd", src)
        t0 = time.perf_counter()
        proc = subprocess.run(
            [exe, *args, str(inputs / "target.pcd"), str(inputs / "source.pcd")],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=TOOL_TIMEOUT_S,
        )
        t_tool = time.perf_counter() - t0
    T = parse_last_matrix(proc.stdout)
    if T is None:
        tail = (proc.stderr.strip() or proc.stdout.strip()).splitlines()
        last = tail[-1][:120] if tail else "no output"
        raise RuntimeError(f"no transform in output (exit code {proc.returncode}): {last}")
    return T @ T_init, t_voxel + t_tool


def pcl_rows(
    target: np.ndarray, source: np.ndarray, T_gt: np.ndarray, T_guess: np.ndarray, guess: str
) -> list[Row]:
    """``pcl_ndt3d`` and ``pcl_icp`` from both starts, when they are on PATH."""
    rows = []
    tools = [
        ("pcl_ndt3d", "NDT", PCL_NDT_ARGS, None, PCL_NDT_NOTE),
        (
            "pcl_icp",
            "ICP",
            PCL_ICP_ARGS,
            PCL_ICP_VOXEL,
            f"voxel {PCL_ICP_VOXEL:g} m done here (tool has none)",
        ),
    ]
    for tool, what, args, voxel, base_note in tools:
        exe = shutil.which(tool)
        if exe is None:
            rows.append(not_installed(f"PCL {tool} ({what})", T_gt, "not installed (not on PATH)"))
            continue
        version = pcl_version(exe)
        name = f"PCL {version} {tool}" if version else f"PCL {tool}"
        for start, init in ((NO_GUESS, np.eye(4)), (guess, T_guess)):
            extra = "" if start == NO_GUESS else "guess: source pre-transformed"
            note = "; ".join(s for s in (base_note, extra) if s)
            t0 = time.perf_counter()
            try:
                T, wall_s = run_pcl_tool(exe, args, target, source, init, voxel)
            except Exception as exc:
                msg = one_line(exc)
                rows.append(row(name, start, time.perf_counter() - t0, None, T_gt, msg))
                continue
            rows.append(row(name, start, wall_s, T, T_gt, note))
    return rows


# --------------------------------------------------------------------------- entry points

FAMILIES = (open3d_rows, small_gicp_rows, kiss_matcher_rows, pcl_rows)  # one peer each


def peer_rows(
    target: np.ndarray,
    source: np.ndarray,
    T_target_source_gt: np.ndarray,
    *,
    guess_offset_m: float = 1.0,
    guess_offset_deg: float = 2.0,
) -> list[dict]:
    """Register ``source`` onto ``target`` with every available peer, from both starts.

    ``target``, ``source``: (N,3) points in metres, each in its scanner frame;
    ``T_target_source_gt``: 4x4 ground truth. Returns one dict per (peer, start); see the module
    docstring for the keys, parameters and what the times include. A missing peer gives one
    row noted "not installed"; a peer's exception becomes its row's note. Raises ValueError
    for empty or non-finite input (which crashes small_gicp instead of raising).
    """
    target = np.asarray(target, dtype=np.float64).reshape(-1, 3)
    source = np.asarray(source, dtype=np.float64).reshape(-1, 3)
    for name, pts in (("target", target), ("source", source)):
        if len(pts) == 0 or not np.all(np.isfinite(pts)):  # some libraries crash on these
            raise ValueError(f"{name} points must be a non-empty, finite (N,3) array")
    T_gt = np.asarray(T_target_source_gt, dtype=np.float64)
    T_guess = perturbed_guess(T_gt, guess_offset_m, guess_offset_deg)
    guess = guess_label(guess_offset_m, guess_offset_deg)
    rows: list[dict] = []
    for fn in FAMILIES:
        rows.extend(fn(target, source, T_gt, T_guess, guess))
    return rows


def format_table(rows: list[dict]) -> str:
    """Rows as a fixed-width text table."""

    def num(v: object, fmt: str) -> str:
        return "-" if not isinstance(v, float) or math.isnan(v) else format(v, fmt)

    w_peer = max([len("peer"), *(len(str(r["peer"])) for r in rows)])
    w_start = max([len("start"), *(len(str(r["start"])) for r in rows)])
    head = f"{'peer':<{w_peer}}  {'start':<{w_start}}  {'wall s':>7}  {'rot °':>8}  {'trans m':>8}"
    head += "  note"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['peer']!s:<{w_peer}}  {r['start']!s:<{w_start}}  {num(r['wall_s'], '7.2f'):>7}  "
            f"{num(r['rot_err_deg'], '8.3f'):>8}  {num(r['trans_err_m'], '8.3f'):>8}  {r['note']}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Command line: two point files and a 4x4 ground-truth ``T_target_source`` text file."""
    from ndt_cli import io
    from ndt_cli.io.matrices import read_matrix

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("target", help="target point file (.ply .las .laz .pcd .xyz .txt)")
    ap.add_argument("source", help="source point file")
    ap.add_argument("ground_truth", help="text file: 4 rows of 4 numbers, T_target_source")
    ap.add_argument("--guess-offset-m", type=float, default=1.0)
    ap.add_argument("--guess-offset-deg", type=float, default=2.0)
    a = ap.parse_args(argv)
    target, source = io.read(a.target).points, io.read(a.source).points
    T_gt = read_matrix(a.ground_truth)
    print(f"target {len(target):,} points, source {len(source):,} points")
    rows = peer_rows(
        target,
        source,
        T_gt,
        guess_offset_m=a.guess_offset_m,
        guess_offset_deg=a.guess_offset_deg,
    )
    print(format_table(rows))


if __name__ == "__main__":
    main()
