"""Links of a campaign: one registration of a scan pair, its identity, and its record on disk.

A link is known by the key of its inputs: both scans' contents (file hashes), which is the
target, and the config. Every finished link is written at once to ``links/<key>.json``
(atomically), so an interrupted campaign resumes where it stopped, and a campaign whose scans
were renamed, reordered or joined by more scans finds every link it already registered. What
the campaign needs of each scan without reading it again (its sketch for the overlap search,
its preview for the top view and its slice sample for the report) is kept there too, under the
key of the scan.
"""

from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.io import atomic
from ndt_cli.io.matrices import rigid_problem
from ndt_cli.io.serialize import to_json
from ndt_cli.ndt.bnb import ScoreField
from ndt_cli.ndt.overlap import Sketch
from ndt_cli.ndt.result import Deeper, RegistrationResult, Status
from ndt_cli.pipeline.network import LinkKind
from ndt_cli.pipeline.samples import SliceSample

log = logging.getLogger(__name__)

LINK_FOLDER = "links"
DIGEST = "digest"  # a link file's SHA-256 of the rest of its content: edits are found
_FORMAT = 4  # version of the link files: older ones are recomputed, not misread


def _digest(record: dict[str, Any]) -> str:
    """SHA-256 of a record's content (keys sorted, compact JSON)."""
    text = json.dumps(record, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def link_key(target_hash: str, source_hash: str, cfg_text: str) -> str:
    """Identity of a link's inputs: both files' hashes (target first) and the config; with an
    empty source hash, the identity of one scan prepared with the config."""
    text = f"{target_hash}\n{source_hash}\n{cfg_text}\nformat {_FORMAT}"
    return hashlib.sha256(text.encode()).hexdigest()


def skipped_key(key: str) -> str:
    """The key of a probe's link whose search skipped its deeper round
    (:class:`~ndt_cli.ndt.result.Deeper`): its result is not the one the link of ``key`` (the
    same inputs, registered in full) has. A probe whose search did not need it is that link."""
    return hashlib.sha256(f"{key}\nskipped".encode()).hexdigest()


@dataclass(frozen=True)
class Link:
    """One registration of the campaign: scan ``source`` onto scan ``target`` (indices into the
    campaign's scans). ``result`` is None when the link failed before registering (``failure`` says
    why: an unreadable scan, a worker that died)."""

    index: int
    target: int
    source: int
    key: str = ""
    result: RegistrationResult | None = None
    failure: str = ""
    kind: LinkKind = LinkKind.ADJACENT
    vouched: bool = False  # the network trusts it on the walk's word (set by
    # ndt_cli.pipeline.members, as kind is; not stored with the registration)

    @property
    def status(self) -> Status:
        return Status.FAILED if self.result is None else self.result.status

    @property
    def ok(self) -> bool:
        return self.status is Status.OK

    @property
    def skipped_deeper(self) -> bool:
        """Its search skipped the deeper round the free space asked for (a probe, see
        :class:`~ndt_cli.ndt.result.Deeper`)."""
        return self.result is not None and self.result.deeper is Deeper.SKIPPED

    @property
    def reason(self) -> str:
        """Why the link is not ok: the registration's warnings, or the failure."""
        return self.failure if self.result is None else "; ".join(self.result.warnings)

    @property
    def T_target_source(self) -> np.ndarray | None:
        return None if self.result is None else self.result.T_target_source

    def describe_levels(self) -> str:
        """Per cell size: iterations, score and time of the winning start (for logs)."""
        if self.result is None:
            return ""
        return "  ".join(level.describe() for level in self.result.levels)

    def to_dict(self) -> dict[str, Any]:
        result = None if self.result is None else self.result.to_dict()
        return {
            "index": self.index,
            "target": self.target,
            "source": self.source,
            "key": self.key,
            "failure": self.failure,
            "kind": self.kind.value,
            "result": result,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Link:
        result = d.get("result")
        return cls(
            int(d["index"]),
            int(d["target"]),
            int(d["source"]),
            str(d["key"]),
            None if result is None else RegistrationResult.from_dict(result),
            str(d.get("failure", "")),
            LinkKind(d.get("kind", LinkKind.ADJACENT.value)),
        )


class LinkStore:
    """The ``links/`` folder of a campaign's output: one JSON file per finished link, named by
    its key, and one file per scan with its sketch and preview, named by the scan's key."""

    def __init__(self, out: Path) -> None:
        self.folder = Path(out) / LINK_FOLDER

    def path(self, key: str) -> Path:
        return self.folder / f"{key[:40]}.json"

    def clean_stale(self) -> None:
        """Remove temporary files left by a run that was killed while writing a link."""
        for stale in self.folder.glob(".*.tmp*"):
            stale.unlink(missing_ok=True)

    def save(self, link: Link, names: tuple[str, str] = ("", "")) -> None:
        """Keep a finished link (``names``: its target's and source's, for a reader), with
        the digest of its content."""
        record = {**link.to_dict(), "target_name": names[0], "source_name": names[1]}
        record = json.loads(to_json(record))  # as it reads back
        record[DIGEST] = _digest(record)
        atomic.write_text(self.path(link.key), to_json(record))

    def load(self, key: str) -> Link | None:
        """The finished link whose inputs had this ``key``, else None: also when its file is
        damaged or was changed (its digest does not match its content, a transform that is
        not rigid, a file of an older ndt-cli without a digest); it is registered again."""
        path = self.path(key)
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
            digest = record.pop(DIGEST, None)
            link = Link.from_dict(record)
        except FileNotFoundError:
            return None
        except (OSError, ValueError, TypeError, KeyError, AttributeError):
            log.warning("%s: damaged: registered again", path)
            return None
        if digest != _digest(record):
            _untrusted(path, digest, "registered again")
            return None
        T = link.T_target_source
        if T is not None and rigid_problem(T, tol=1e-6):  # damaged: registered again
            return None
        return link if link.key == key else None

    def save_scan(
        self, scan_key: str, preview: np.ndarray, sketch: Sketch, sample: SliceSample | None
    ) -> None:
        """Keep what the campaign needs of a scan without reading it again (its preview, its
        sketch, the slices the link inspector draws), with the digest of its arrays."""
        field = sketch.field
        arrays = {
            "preview": preview,
            "field": field.values,
            "origin": field.origin,
            "resolution": np.float64(field.resolution),
            "centre": field.centre,
            "to_local": sketch.to_local,
            "keys": sketch.keys,
            **{f"slice_{k}": s for k, s in enumerate(sketch.slices)},
        }
        if sample is not None:
            arrays |= {f"inspect_{k}": s for k, s in enumerate(sample.slices)}
            arrays |= {"inspect_heights": np.array(sample.heights, dtype=float)}
        arrays = {name: np.asarray(a) for name, a in arrays.items()}
        with atomic.atomic_open(self._scan_path(scan_key), "wb") as fh:
            np.savez(fh, **arrays, **{DIGEST: np.array(_array_digest(arrays))})

    def load_scan(self, scan_key: str) -> tuple[np.ndarray, Sketch, SliceSample | None] | None:
        """A scan's preview, sketch and slice sample (None when an older run kept none), if
        kept (and unchanged since: else None, and the scan is read again)."""
        path = self._scan_path(scan_key)
        try:
            with np.load(path) as z:
                arrays = {name: z[name] for name in z.files if name != DIGEST}
                digest = str(z[DIGEST]) if DIGEST in z.files else None
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError):
            log.warning("%s: damaged: the scan is read again", path)
            return None
        if digest != _array_digest(arrays):
            _untrusted(path, digest, "read again")
            return None
        try:
            n = sum(name.startswith("slice_") for name in arrays)
            slices = tuple(arrays[f"slice_{k}"] for k in range(n))
            f = arrays
            field = ScoreField(f["field"], f["origin"], float(f["resolution"]), f["centre"])
            keys = f["keys"] if "keys" in f else np.zeros((0, 3), dtype=np.int64)
            sketch = Sketch(slices, field, f["to_local"], keys)
            return f["preview"], sketch, _sample(arrays, sketch)
        except (KeyError, TypeError, ValueError):
            return None

    def _scan_path(self, scan_key: str) -> Path:
        return self.folder / f"scan_{scan_key[:40]}.npz"


def _sample(arrays: dict[str, np.ndarray], sketch: Sketch) -> SliceSample | None:
    """The slices kept for the link inspector (None: an older run kept none)."""
    if "inspect_heights" not in arrays:
        return None
    heights = tuple(float(h) for h in arrays["inspect_heights"])
    cut = tuple(arrays[f"inspect_{k}"] for k in range(len(heights)))
    return SliceSample(sketch.to_local, heights, cut)


def _untrusted(path: Path, digest: str | None, what: str) -> None:
    """Say why a file of the store is not used: changed since it was written (a warning), or
    written without a digest by an older ndt-cli (a debug line: every such file is)."""
    if digest is None:
        log.debug("%s: no digest (an older ndt-cli wrote it): %s", path, what)
    else:
        log.warning("%s: changed since it was written (its digest): %s", path, what)


def _array_digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 of named arrays: each one's name, type, shape and bytes, by name."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()
