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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.io import atomic
from ndt_cli.io.matrices import rigid_problem
from ndt_cli.io.serialize import to_json
from ndt_cli.ndt.bnb import ScoreField
from ndt_cli.ndt.overlap import Sketch
from ndt_cli.ndt.result import RegistrationResult, Status
from ndt_cli.pipeline.network import LinkKind
from ndt_cli.pipeline.samples import SliceSample

LINK_FOLDER = "links"
_FORMAT = 4  # version of the link files: older ones are recomputed, not misread


def link_key(target_hash: str, source_hash: str, cfg_text: str) -> str:
    """Identity of a link's inputs: both files' hashes (target first) and the config; with an
    empty source hash, the identity of one scan prepared with the config."""
    text = f"{target_hash}\n{source_hash}\n{cfg_text}\nformat {_FORMAT}"
    return hashlib.sha256(text.encode()).hexdigest()


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

    @property
    def status(self) -> Status:
        return Status.FAILED if self.result is None else self.result.status

    @property
    def ok(self) -> bool:
        return self.status is Status.OK

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
        """Keep a finished link (``names``: its target's and source's, for a reader)."""
        record = {**link.to_dict(), "target_name": names[0], "source_name": names[1]}
        atomic.write_text(self.path(link.key), to_json(record))

    def load(self, key: str) -> Link | None:
        """The finished link whose inputs had this ``key``, else None (also when its file is
        damaged: unreadable, or a transform that is not rigid; it is registered again)."""
        try:
            link = Link.from_dict(json.loads(self.path(key).read_text(encoding="utf-8")))
        except (OSError, ValueError, TypeError, KeyError, AttributeError):
            return None
        T = link.T_target_source
        if T is not None and rigid_problem(T, tol=1e-6):  # damaged: registered again
            return None
        return link if link.key == key else None

    def save_scan(
        self, scan_key: str, preview: np.ndarray, sketch: Sketch, sample: SliceSample | None
    ) -> None:
        """Keep what the campaign needs of a scan without reading it again."""
        arrays = {f"slice_{k}": s for k, s in enumerate(sketch.slices)}
        if sample is not None:
            arrays |= {f"inspect_{k}": s for k, s in enumerate(sample.slices)}
            arrays |= {"inspect_heights": np.array(sample.heights, dtype=float)}
        field = sketch.field
        with atomic.atomic_open(self.folder / f"scan_{scan_key[:40]}.npz", "wb") as fh:
            np.savez(
                fh,
                preview=preview,
                field=field.values,
                origin=field.origin,
                resolution=np.float64(field.resolution),
                centre=field.centre,
                to_local=sketch.to_local,
                **arrays,
            )

    def load_scan(self, scan_key: str) -> tuple[np.ndarray, Sketch, SliceSample | None] | None:
        """A scan's preview, sketch and slice sample (None when an older run kept none), if
        kept."""
        try:
            with np.load(self.folder / f"scan_{scan_key[:40]}.npz") as z:
                n = sum(name.startswith("slice_") for name in z.files)
                slices = tuple(z[f"slice_{k}"] for k in range(n))
                field = ScoreField(z["field"], z["origin"], float(z["resolution"]), z["centre"])
                sketch = Sketch(slices, field, z["to_local"])
                sample = None
                if "inspect_heights" in z.files:
                    heights = tuple(float(h) for h in z["inspect_heights"])
                    cut = tuple(z[f"inspect_{k}"] for k in range(len(heights)))
                    sample = SliceSample(sketch.to_local, heights, cut)
                return z["preview"], sketch, sample
        except (OSError, ValueError, KeyError):
            return None
