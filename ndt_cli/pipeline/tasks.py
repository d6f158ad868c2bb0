"""The tasks that worker processes run for a campaign: prepare a scan, register a link.

Tasks never raise for a problem with the data: a scan that cannot be used becomes a
:class:`~ndt_cli.pipeline.workers.Failure` (its one-line reason), a link that cannot be registered
a failed :class:`Link`.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ndt_cli.config.schema import Config
from ndt_cli.errors import NdtError
from ndt_cli.io.multiscan import split_spec
from ndt_cli.ndt.overlap import Sketch, sketch
from ndt_cli.ndt.prepare import PreparedScan, load_and_prepare
from ndt_cli.ndt.register import Guess, register_prepared
from ndt_cli.ndt.result import Deeper
from ndt_cli.pipeline.guesses import better
from ndt_cli.pipeline.links import Link, skipped_key
from ndt_cli.pipeline.network import LinkKind
from ndt_cli.pipeline.samples import SliceSample, slice_sample
from ndt_cli.pipeline.workers import Failure


@dataclass(frozen=True)
class LinkJob:
    """Which link to register: its index, the target and source scans (indices), its key, its
    kind, a guess of T_target_source (a :class:`Guess`; None: the search alone), and whether
    the search may look deeper (False: a probe)."""

    index: int
    target: int
    source: int
    key: str
    kind: LinkKind = LinkKind.ADJACENT
    guess: Guess | None = None
    deep: bool = True

    @property
    def pair(self) -> tuple[int, int]:
        """The two scans, lower index first."""
        return (min(self.target, self.source), max(self.target, self.source))

    def failed(self, reason: str) -> Link:
        return Link(self.index, self.target, self.source, self.key, failure=reason, kind=self.kind)

    def adopt(self, link: Link) -> Link:
        """A finished link with this job's inputs (e.g. of an earlier run, when its scans had
        other places in the campaign) as this job's."""
        return replace(
            link, index=self.index, target=self.target, source=self.source, kind=self.kind
        )


CACHED_SCANS = 6  # prepared scans a worker process keeps for its next links
_prepared: OrderedDict[tuple, PreparedScan] = OrderedDict()


def _cache_key(path: Path, cfg: Config) -> tuple | None:
    """A scan's identity for the cache: its name, file time and size, and the config."""
    try:
        st = split_spec(path)[0].stat()
    except OSError:
        return None
    return str(path), st.st_mtime_ns, st.st_size, cfg


def prepare_scan(path: Path, cfg: Config) -> PreparedScan | Failure:
    """The prepared scan with its free-space view, or why it cannot be used.
    A worker process keeps its last prepared scans: in a network every scan is in several
    links, and a worker that reads its scans itself (Dask) prepares each at most once for them."""
    key = _cache_key(path, cfg)
    if key is not None and key in _prepared:
        _prepared.move_to_end(key)
        return _prepared[key]
    try:
        scan = load_and_prepare(path, cfg)
    except NdtError as exc:
        return Failure(exc)
    if cfg.search.free_space_ratio > 0:
        _ = scan.sight  # built once here, in parallel, and shipped with the scan to its links
    if key is not None:
        _prepared[key] = scan
        while len(_prepared) > CACHED_SCANS:
            _prepared.popitem(last=False)
    return scan


@dataclass(frozen=True)
class ScanSummary:
    """What a campaign keeps of a scan: its preview points (x, y, z, scan frame) for the top
    view, its sketch for the overlap search, two of its slices for the report's link inspector
    (None: kept by an older run) and, where tasks are shipped their scans, the prepared scan
    itself."""

    preview: np.ndarray
    sketch: Sketch
    sample: SliceSample | None = None
    prepared: PreparedScan | None = None


def summarise_scan(path: Path, cfg: Config, ship: bool) -> ScanSummary | Failure:
    """The scan's :class:`ScanSummary` (with the prepared scan when ``ship``), or why it cannot
    be used."""
    value = prepare_scan(path, cfg)
    if isinstance(value, Failure):
        return value
    sample = slice_sample(value, cfg.slices.heights)
    return ScanSummary(value.preview(), sketch(value), sample, value if ship else None)


def register_link(job: LinkJob, target: PreparedScan, source: PreparedScan, cfg: Config) -> Link:
    """Register prepared scan ``source`` onto ``target``: by the search, and with a guess
    from it too, the better kept (:func:`~ndt_cli.pipeline.guesses.better`). A probe whose
    search skipped its deeper round is stored as a probe whichever result is kept, and says
    so: a full registration of the pair (the deeper round may find a rival the guess's result
    never met) is never taken from it."""
    try:
        searched = register_prepared(target, source, cfg, deeper=job.deep)
        result = searched
        if job.guess is not None:
            guessed = register_prepared(target, source, cfg, init=job.guess)
            result = better(searched, guessed, job.guess)
        if searched.deeper is Deeper.SKIPPED:
            result = replace(result, deeper=Deeper.SKIPPED)
    except NdtError as exc:
        return job.failed(str(exc))
    link = Link(job.index, job.target, job.source, job.key, result, kind=job.kind)
    return replace(link, key=skipped_key(job.key)) if link.skipped_deeper else link


def register_paths(job: LinkJob, target: Path, source: Path, cfg: Config) -> Link:
    """Read, prepare and register both scans in this process."""
    tgt, src = prepare_scan(target, cfg), prepare_scan(source, cfg)
    for value in (tgt, src):
        if isinstance(value, Failure):
            return job.failed(value)
    assert isinstance(tgt, PreparedScan) and isinstance(src, PreparedScan)
    return register_link(job, tgt, src, cfg)
