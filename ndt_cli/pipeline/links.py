"""Links of a chain: one registration of a scan pair, its identity, and its record on disk.

Every finished link is written at once to ``links/TTTT-SSSS.json`` (target and source scan
indices; atomically) with the key of its inputs (both files' hashes, the config, and a loop
closure's guess), so an interrupted chain resumes where it stopped.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ndt_cli.io import atomic
from ndt_cli.io.serialize import to_json
from ndt_cli.ndt.result import RegistrationResult, Status
from ndt_cli.pipeline.network import LinkKind

LINK_FOLDER = "links"
_FORMAT = 2  # version of the link files: older ones are recomputed, not misread


def link_key(target_hash: str, source_hash: str, cfg_text: str) -> str:
    """Identity of a link's inputs: both files' hashes and the config."""
    text = f"{target_hash}\n{source_hash}\n{cfg_text}\nformat {_FORMAT}"
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class Link:
    """One registration of the chain: scan ``source`` onto scan ``target`` (indices into the
    scan list). ``result`` is None when the link failed before registering (``failure`` says
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
    """The ``links/`` folder of a chain's output: one JSON file per finished link."""

    def __init__(self, out: Path) -> None:
        self.folder = Path(out) / LINK_FOLDER

    def path(self, target: int, source: int) -> Path:
        return self.folder / f"{target:04d}-{source:04d}.json"

    def clean_stale(self) -> None:
        """Remove temporary files left by a run that was killed while writing a link."""
        for stale in self.folder.glob(".*.tmp*"):
            stale.unlink(missing_ok=True)

    def save(self, link: Link) -> None:
        atomic.write_text(self.path(link.target, link.source), to_json(link.to_dict()))

    def save_preview(self, scan_key: str, points: np.ndarray) -> None:
        """Keep a scan's preview points (for the top view of a resumed chain)."""
        with atomic.atomic_path(self.folder / f"preview_{scan_key[:16]}.npy") as tmp:
            np.save(tmp, points)

    def load_preview(self, scan_key: str) -> np.ndarray | None:
        try:
            return np.load(self.folder / f"preview_{scan_key[:16]}.npy")
        except (OSError, ValueError):
            return None

    def load(self, target: int, source: int, key: str) -> Link | None:
        """The finished link of this pair if its inputs had this ``key``, else None."""
        try:
            text = self.path(target, source).read_text(encoding="utf-8")
            link = Link.from_dict(json.loads(text))
        except (OSError, ValueError, TypeError, KeyError):
            return None
        return link if link.key == key else None
