"""Register a sequence of scans pair by pair and chain the links into one frame.

Scan i is registered against scan i-1 (the last readable scan before it). The first scan, or
``anchor``, defines the world frame: ``T_world_scan`` of every other scan is the product of the
links between them. Links are independent and run in parallel processes; each finished link is
written at once (``links/NNNN.json``, atomically) with hashes of its inputs and config, so an
interrupted chain resumes where it stopped and gives the same outputs.
"""

from __future__ import annotations

import hashlib
import logging
import multiprocessing
import os
import re
import signal
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli import atomic
from ndt_cli.config import Config, dump
from ndt_cli.errors import NdtError, UserInterruptError
from ndt_cli.report import to_json

log = logging.getLogger(__name__)

LINK_FOLDER = "links"
_HASH_CHUNK = 1 << 20


def natural_key(path: str | Path) -> list[Any]:
    """Sort key: digit runs compare as numbers, so scan_2 comes before scan_10."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", str(path))]


def natural_sort(paths: Sequence[str | Path]) -> list[Path]:
    """Paths in natural order of their file names, then folders (see :func:`natural_key`)."""
    return [
        Path(p) for p in sorted(paths, key=lambda p: (natural_key(Path(p).name), natural_key(p)))
    ]


def file_hash(path: Path) -> str:
    """SHA-256 of a scan's file bytes (and its scan number in an E57); 'missing' if unreadable."""
    from ndt_cli.e57 import split_spec

    file, index = split_spec(path)
    h = hashlib.sha256(b"" if index is None else f"#{index}".encode())
    try:
        with open(file, "rb") as fh:
            while chunk := fh.read(_HASH_CHUNK):
                h.update(chunk)
    except OSError:
        return "missing"
    return h.hexdigest()


@dataclass(frozen=True)
class Link:
    """One registration of the chain: ``source`` onto ``target`` (indices into the scan list)."""

    index: int
    target: int
    source: int
    status: str  # ok | degenerate | suspect | not_converged | no_overlap | failed
    reason: str = ""
    T_target_source: np.ndarray | None = None
    score: float = float("nan")
    score_per_point: float = float("nan")
    overlap: float = float("nan")
    iterations: int = 0
    converged: bool = False
    runtime_s: float = 0.0
    key: str = ""
    levels: str = ""  # per cell size: iterations, score and time of the winning start
    ambiguity: float = float("nan")
    overlap_3d: float = float("nan")
    icp_rms: float = float("nan")
    icp_inliers: int = 0
    degenerate: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict[str, Any]:
        d = dict(vars(self))
        d["T_target_source"] = (
            None if self.T_target_source is None else self.T_target_source.tolist()
        )
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Link:
        d = dict(d)
        T = d.pop("T_target_source")
        return cls(T_target_source=None if T is None else np.array(T, dtype=float), **d)


@dataclass(frozen=True)
class ChainResult:
    """All links, and ``T_world_scan`` per scan (None when a failed link cuts it off)."""

    scans: tuple[Path, ...]
    links: tuple[Link, ...]
    poses: tuple[np.ndarray | None, ...]
    anchor: int
    unreadable: dict[int, str]
    previews: dict[int, np.ndarray]  # prepared scans: thinned slice points (x, y, z), scan frame
    reused: tuple[int, ...] = ()  # links taken from an earlier run (--resume)

    @property
    def ok(self) -> bool:
        return not self.unreadable and all(link.ok for link in self.links)


def preview(scan: Any, max_points: int = 4000) -> np.ndarray:
    """Thinned slice points of a prepared scan as (x, y, z) in the scan's own frame (metres)."""
    xy = np.concatenate(scan.slices)
    step = max(1, len(xy) // max_points)
    xyz = np.column_stack([xy[::step], np.zeros(len(xy[::step]))])
    T = scan.from_local()
    return xyz @ T[:3, :3].T + T[:3, 3]


# ----------------------------------------------------------------------------- workers

_FAULT_EXIT = False  # set in workers by NDT_CLI_FAULT_EXIT_ON=register (tests only)


def _init_worker(threads: int) -> None:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is handled by the parent
    if os.environ.get("NDT_CLI_FAULT_EXIT_ON") == "register":  # fault injection for tests
        global _FAULT_EXIT
        _FAULT_EXIT = True
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _prepare_scan(path: Path, cfg: Config) -> Any:
    """A worker task: the prepared scan, or the one-line error text when it cannot be used."""
    from ndt_cli.prepare import load_and_prepare

    try:
        return load_and_prepare(path, cfg)
    except NdtError as exc:
        return str(exc)


def _register_link(
    index: int, i: int, j: int, target: Any, source: Any, cfg: Config, key: str
) -> Link:
    """A worker task: register prepared scan ``source`` (j) onto ``target`` (i)."""
    from ndt_cli.engine import register_prepared

    if _FAULT_EXIT and source.path is not None and "crash" in source.path.name:
        os._exit(3)  # simulate a worker killed mid-task

    try:
        r = register_prepared(target, source, cfg)
    except NdtError as exc:
        return Link(index, i, j, "failed", reason=str(exc), key=key)
    return Link(
        index,
        i,
        j,
        r.status,
        reason="; ".join(r.warnings),
        T_target_source=r.T_target_source,
        score=r.score,
        score_per_point=r.score_per_point,
        overlap=r.overlap,
        iterations=r.iterations,
        converged=r.converged,
        runtime_s=r.runtime_s,
        key=key,
        ambiguity=r.ambiguity,
        overlap_3d=r.overlap_3d,
        icp_rms=r.icp_rms,
        icp_inliers=r.icp_inliers,
        degenerate=r.degenerate,
        levels="  ".join(
            f"{lv.cell_size:g} m: {lv.iterations} it, score {lv.score:.0f}, {lv.time_s:.2f} s"
            for lv in r.levels
        ),
    )


class WorkerPool:
    """Worker processes for chain tasks that survive a worker dying.

    Processes are spawned, not forked: a forked child of a process whose Numba threads already
    ran can deadlock. When a worker dies (killed, out of memory, a crash in a library), every
    task in flight fails with BrokenProcessPool; those tasks are then rerun one at a time in a
    fresh single-worker pool, so only the task that kills its worker fails.
    """

    def __init__(self, jobs: int, threads: int) -> None:
        self.jobs = jobs
        self.threads = threads
        self._pool: ProcessPoolExecutor | None = None

    def _new(self, workers: int) -> ProcessPoolExecutor:
        self.close()
        self._pool = ProcessPoolExecutor(
            max_workers=workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_worker,
            initargs=(self.threads,),
        )
        return self._pool

    def run(self, tasks: dict[int, tuple]) -> Iterator[tuple[int, Any]]:
        """Yield (key, result) as tasks finish; a task that fails yields its one-line reason."""
        queue = list(tasks)
        workers = self.jobs
        while queue:
            pool = self._pool if self._pool and workers == self.jobs else self._new(workers)
            futures = {pool.submit(*tasks[k]): k for k in queue}
            broken: list[int] = []
            for fut in as_completed(futures):
                key = futures[fut]
                try:
                    yield key, fut.result()
                except BrokenProcessPool:
                    broken.append(key)
                except Exception as exc:  # a bug in a task: report it for that task only
                    yield key, f"worker error: {' '.join(str(exc).split())[:200]}"
            queue = [k for k in queue if k in broken]
            if queue and workers == 1:  # in isolation the first task in line killed its worker
                culprit = queue.pop(0)
                yield culprit, "the worker process died (killed, out of memory or crashed)"
            if queue:
                workers = 1
                self._new(1)

    def terminate(self) -> None:
        """Stop the workers now (on Ctrl-C): running tasks are abandoned, nothing is written."""
        pool = self._pool
        if pool is None:
            return
        for proc in list(getattr(pool, "_processes", {}).values()):
            proc.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


def _scan_status(path: Path, cfg: Config) -> str | None:
    """A worker task: None if the scan can be read and sliced, else the one-line reason."""
    value = _prepare_scan(path, cfg)
    return value if isinstance(value, str) else None


def _register_paths(
    index: int, i: int, j: int, target: Path, source: Path, cfg: Config, key: str
) -> Link:
    """A worker task that reads both scans itself (executors that do not ship scan data)."""
    scans = [_prepare_scan(target, cfg), _prepare_scan(source, cfg)]
    for value in scans:
        if isinstance(value, str):
            return Link(index, i, j, "failed", reason=value, key=key)
    return _register_link(index, i, j, scans[0], scans[1], cfg, key)


# ----------------------------------------------------------------------------- driver


def plan_links(n_scans: int, unreadable: set[int]) -> list[tuple[int, int]]:
    """(target, source) per scan after the first: the last readable scan before it as target.

    Link ``k`` has source scan ``k + 1``; a link whose source cannot be read fails, and the next
    scan is registered against the last readable one instead.
    """
    pairs = []
    last = 0
    for j in range(1, n_scans):
        pairs.append((last, j))
        if j not in unreadable or last in unreadable:
            last = j
    return pairs


def compose_poses(n_scans: int, links: Sequence[Link], anchor: int) -> list[np.ndarray | None]:
    """``T_world_scan`` per scan from the links (world = the anchor scan's frame).

    A link without a transform (failed) leaves its source without a pose; scans that were
    registered against a scan without a pose get none either.
    """
    poses: list[np.ndarray | None] = [None] * n_scans
    poses[anchor] = np.eye(4)
    with_T = [link for link in links if link.T_target_source is not None]
    for link in sorted(with_T, key=lambda k: k.source):  # forward: T_w_j = T_w_i @ T_i_j
        if link.source > anchor and poses[link.target] is not None:
            poses[link.source] = poses[link.target] @ link.T_target_source
    for link in sorted(with_T, key=lambda k: -k.source):  # backward: T_w_i = T_w_j @ inv(T_i_j)
        if link.source <= anchor and poses[link.source] is not None:
            poses[link.target] = poses[link.source] @ np.linalg.inv(link.T_target_source)
    return poses


def link_key(target_hash: str, source_hash: str, cfg_text: str) -> str:
    """Identity of a link's inputs: both files' hashes and the config."""
    return hashlib.sha256(f"{target_hash}\n{source_hash}\n{cfg_text}".encode()).hexdigest()


def _load_finished(out: Path, index: int, key: str) -> Link | None:
    path = out / LINK_FOLDER / f"{index:04d}.json"
    try:
        import json

        link = Link.from_dict(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError, KeyError):
        return None
    return link if link.key == key else None


def run_chain(
    scans: Sequence[str | Path],
    cfg: Config,
    out: str | Path,
    *,
    jobs: int | None = None,
    resume: bool = False,
    anchor: int = 0,
    on_progress: Callable[[Link], None] | None = None,
    executor: str = "local",
    scheduler: str | None = None,
) -> ChainResult:
    """Register the scans in the order given, write each link as it finishes, compose poses.

    ``executor``: ``local`` (processes on this machine, ``jobs`` of them) or ``dask`` (the
    cluster at ``scheduler``, or a LocalCluster of ``jobs`` workers); results are the same.
    """
    paths = [Path(p) for p in scans]
    out = Path(out)
    n = len(paths)
    jobs = max(1, jobs or os.cpu_count() or 1)
    threads = max(1, (os.cpu_count() or 1) // jobs)
    cfg_text = dump(cfg)
    hashes = [file_hash(p) for p in paths]

    unreadable: dict[int, str] = {}
    finished: dict[int, Link] = {}

    def plan() -> tuple[list[tuple[int, int]], list[str]]:
        pairs = plan_links(n, set(unreadable))
        return pairs, [link_key(hashes[i], hashes[j], cfg_text) for i, j in pairs]

    def report(link: Link) -> None:
        finished[link.index] = link
        if on_progress:
            on_progress(link)

    for stale in (out / LINK_FOLDER).glob(".*.tmp*"):  # left by a run that was killed
        stale.unlink(missing_ok=True)
    if executor == "dask":
        from ndt_cli.dask_executor import DaskPool

        pool: Any = DaskPool(scheduler, jobs, threads)
    else:
        pool = WorkerPool(jobs, threads)
    ships = getattr(pool, "ships_data", True)
    try:
        pairs, keys = plan()
        if resume:
            for index, key in enumerate(keys):
                link = _load_finished(out, index, key)
                if link is not None and (link.target, link.source) == pairs[index]:
                    finished[index] = link
        # read and slice each scan that an unfinished link needs, once, in parallel
        needed = sorted({s for k, pair in enumerate(pairs) if k not in finished for s in pair})
        prepared: dict[int, Any] = {}
        check = _prepare_scan if ships else _scan_status
        for i, value in pool.run({i: (check, paths[i], cfg) for i in needed}):
            if isinstance(value, str):
                unreadable[i] = value
            elif value is not None:
                prepared[i] = value
        if unreadable:  # re-plan around the scans that could not be read
            pairs, keys = plan()
            finished = {k: v for k, v in finished.items() if v.key == keys[k]}
        reused = set(finished)
        for link in list(finished.values()):
            report(link)
        todo: dict[int, tuple] = {}
        for index, (i, j) in enumerate(pairs):
            if index in finished:
                continue
            if i in unreadable or j in unreadable:
                reason = unreadable.get(j) or unreadable[i]
                report(Link(index, i, j, "failed", reason=reason, key=keys[index]))
                continue
            if ships:
                todo[index] = (
                    _register_link,
                    index,
                    i,
                    j,
                    prepared[i],
                    prepared[j],
                    cfg,
                    keys[index],
                )
            else:  # the worker reads both scans itself
                todo[index] = (_register_paths, index, i, j, paths[i], paths[j], cfg, keys[index])
        for index, link in pool.run(todo):
            if isinstance(link, str):  # the worker died or raised: this link fails, not the chain
                i, j = pairs[index]
                report(Link(index, i, j, "failed", reason=link, key=keys[index]))
                continue
            atomic.write_text(out / LINK_FOLDER / f"{index:04d}.json", to_json(link.to_dict()))
            report(link)
    except KeyboardInterrupt:
        pool.terminate()
        raise UserInterruptError(
            f"interrupted: {len(finished)} finished link(s) kept in {out / LINK_FOLDER}; "
            "run again with --resume to continue"
        ) from None
    finally:
        pool.close()

    links = tuple(finished[k] for k in sorted(finished))
    for reason in dict(sorted(unreadable.items())).values():
        log.warning("%s", reason)
    return ChainResult(
        scans=tuple(paths),
        links=links,
        poses=tuple(compose_poses(n, links, anchor)),
        anchor=anchor,
        unreadable=dict(sorted(unreadable.items())),
        previews={i: preview(p) for i, p in sorted(prepared.items())},
        reused=tuple(sorted(reused)),
    )
