"""The configuration's sections: frozen dataclasses with defaults (units in the comments), how a
nested dict becomes a :class:`Config`, and the values each key may take.

``configs/default.yaml`` documents every key. Every invalid value raises
:class:`~ndt_cli.errors.ConfigError` naming its key.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

from ndt_cli.config.rules import validate
from ndt_cli.errors import ConfigError

OptimizerName = Literal["newton", "lm_fixed", "lm"]


def key(default: Any, doc: str, *, surveyor: bool = False) -> Any:
    """A config key: its default, what it means (units, reasons) and whether a surveyor sets it
    (the other keys are method internals). ``--print-config`` writes ``doc`` as comments."""
    return field(default=default, metadata={"doc": doc, "surveyor": surveyor})


SceneKind = Literal["auto", "street", "indoor"]


@dataclass(frozen=True)
class SceneConfig:
    """What the scans are of: the settings of every other section suit it."""

    kind: SceneKind = key(
        "auto",
        "street (outdoors: streets, squares, forests), indoor (building interiors: slices "
        "below the ceiling, finer cells and search, rooms told apart) or auto (indoor when a "
        "ceiling covers most of the first scan's upward view); indoor changes only keys left "
        "at their street defaults (ndt_cli/config/scenes.py lists them)",
        surveyor=True,
    )
    radius_factor: float = key(
        2.2,
        "the network links each scan to the scans within this many times the median distance "
        "between nearest scans (the --radius option overrides it); indoors 3: interiors need "
        "cycles of links, since one registration alone proves nothing where rooms repeat",
    )
    unplaced_doubt_walk: bool = key(
        True,
        "a scan that fits no placed scan at all counts against following the campaign's "
        "order, as a scan that fits elsewhere than beside its neighbours in the order does; "
        "false (interiors): it counts neither way, since a room seen only through its doorway "
        "fits no scan in a right walk",
    )


@dataclass(frozen=True)
class InputConfig:
    """How the files' coordinates become the frame the method works in: metres, right-handed,
    z up. Transforms in the results are in that frame."""

    scale: float = key(1.0, "file units to metres (0.01 for centimetres)", surveyor=True)
    axes: str = key(
        "x,y,z",
        'file axis (with sign) that becomes x, y, z: "z,-x,y" turns a left-handed frame with x '
        "sideways, y up and z forward (e.g. 3DTK's) into a right-handed z-up one",
        surveyor=True,
    )
    min_range: float = key(
        0.0, "drop points nearer than this to the scanner: tripod, vehicle (m)", surveyor=True
    )
    max_range: float | None = key(
        None,
        "drop points farther than this from the scanner (m, after scale); null: keep all",
        surveyor=True,
    )
    chunk_points: int = key(
        4_000_000,
        "points read at a time from LAS/LAZ and E57 files (and the stride of a large file's "
        "ground sample: files with more points take it from their header's count)",
    )
    memory_mb: int = key(
        1000,
        "a scan whose coordinates take at most this many MB (12 bytes a point in LAZ, 24 in "
        "E57 and others) is read once and held while it is prepared; a larger LAZ or E57 file "
        "is read twice, chunk_points at a time, so memory stays bounded whatever its size (a "
        "LAS file above chunk_points always is: it is mapped, and read again without decoding)",
    )


VerticalMethod = Literal["auto", "structures", "ground", "scanner"]


@dataclass(frozen=True)
class GroundConfig:
    """Each scan's vertical and ground (z in the scan's own frame, metres)."""

    z: float | None = key(
        None,
        "ground level in the scans' own frame (m), for scans already levelled on level ground "
        "(indoors); null: find each scan's vertical and model the ground under it",
        surveyor=True,
    )
    vertical: VerticalMethod = key(
        "auto",
        "how each scan's vertical is found: structures (perpendicular to walls, facades and "
        "poles, which stand vertical whatever the grade or camber of the ground), ground (the "
        "normal of the roughly horizontal surfaces: right on level ground), auto (structures "
        "when their patches are clean, as a terrestrial scanner's facades are, else ground: "
        "robot and car lidars) or scanner (the scanner's own z: a compensated instrument, "
        "whose dual-axis compensator made z the vertical, or scans already levelled)",
        surveyor=True,
    )
    level: bool = key(
        True,
        "level each scan to the vertical found by ground.vertical; false is ground.vertical: "
        "scanner (the earlier spelling); ignored when ground.z is given",
    )


@dataclass(frozen=True)
class SlicesConfig:
    """Horizontal slices cut out of each scan and projected onto the ground plane."""

    heights: tuple[float, ...] = key(
        (1.0, 2.0, 4.0, 8.0, 12.0),
        "slice centres above the ground (m): 1 and 2 m cut facades, doors, cars, poles and "
        "trunks; 4, 8 and 12 m cut upper storeys above the street's clutter, whose differing "
        "heights tell buildings and corners apart (one slice alone can match the wrong corner "
        "or slide along a street)",
        surveyor=True,
    )
    thickness: float = key(0.40, "slice thickness (m), as in the paper")


@dataclass(frozen=True)
class GridConfig:
    """The target's NDT grids: one per slice and cell size."""

    cell_sizes: tuple[float, ...] = key(
        (20.0, 10.0, 5.0, 2.0, 1.0),
        "coarse to fine (m); every schedule also ends at 2 and 1 m, where the winner is chosen "
        "and judged; configs/paper.yaml has the paper's 200/100/50/25",
    )
    min_points: int = key(3, "points a cell needs to get a normal distribution")
    min_eigen_ratio: float = key(
        1e-3, "small covariance eigenvalue clamped to >= this times the large one"
    )
    min_variance: float = key(1e-4, "absolute floor of the covariance eigenvalues (m^2)")
    overlap: bool = key(False, "Biber's four grids shifted by half a cell")


@dataclass(frozen=True)
class SourceConfig:
    """How the moving scan's slice points are thinned before scoring."""

    voxel: float = key(0.2, "2D voxel filter of the moving scan's slices (m); 0 = off")
    points_per_slice: int = key(
        20000, "at most this many moving points per slice (deterministic sample)"
    )


@dataclass(frozen=True)
class OptimizerConfig:
    """The local solver run at every cell size."""

    method: OptimizerName = key(
        "newton", "newton | lm_fixed (the paper's fixed-lambda LM) | lm (adaptive lambda)"
    )
    max_iterations: int = key(100, "per cell size and start (most stop after 10-40)")
    patience: int = key(5, "go finer after this many iterations without a better score")
    lm_lambda: float = key(0.01, "lm_fixed: lambda as a multiple of mean diag(J^T J)")
    max_step: float = key(0.5, "largest translation step (cell sizes)")
    max_rotation_step_deg: float = key(15.0, "largest rotation step (degrees)")


SearchMethod = Literal["bnb", "starts"]


@dataclass(frozen=True)
class SearchConfig:
    """Where the coarse-to-fine refinement starts when there is no initial guess."""

    method: SearchMethod = key(
        "bnb",
        "bnb: exact global search, branch and bound over (x, y, yaw) on a likelihood field of "
        "the target slices, then refinement from 5 m cells; starts: Newton from a grid of "
        "starts at the coarsest cell size (slower; kept for comparison)",
    )
    bnb_resolution: float = key(1.0, "bnb: pixel of the likelihood field and of the search (m)")
    bnb_window: float = key(
        50.0, "bnb: translations searched, +-this around the aligned scene centres (m)"
    )
    bnb_candidates: int = key(8, "bnb: best distinct poses refined by NDT")
    bnb_exclusion: float = key(
        8.0,
        "bnb: poses whose source centres land closer than this (m) and whose headings differ "
        "by at most 10 degrees are one candidate (a street's bays are 3-8 m: a pose slid by "
        "one is not a second candidate; indoors a room is 3-4 m wide and must be one)",
    )
    bnb_start_cell: float = key(
        5.0, "bnb: the refinement starts at the configured cells up to this size (m)"
    )
    fallback_ratio: float = key(
        0.95,
        "bnb: when the second distinct pose scores at least this share of the best (an "
        "ambiguous scene, or scans far apart), the start search runs too and its candidates "
        "join; on simulated links this kept far links as reliable as the start search alone",
    )
    yaw_starts: int = key(12, "starts: headings over 360 degrees")
    translation_range: float = key(
        40.0, "starts: translations cover +-this around the aligned slice centroids (m)"
    )
    translation_step: float = key(10.0, "starts: spacing of the translation starts (m)")
    points_per_slice: int = key(1000, "starts: moving points per slice during the search")
    keep_candidates: int = key(
        8, "starts: distinct coarse solutions refined to the finest cell size (at least 2)"
    )
    refine_offsets: bool = key(
        True, "restart each finer level from offsets of +-1/2 and +-1 cell in x and y too"
    )
    free_space_ratio: float = key(
        2.0,
        "a candidate is refuted when it puts more than this many times (1 or more) the share "
        "of points into the space the other scanner saw empty than the candidate that puts "
        "the least there (and free_space_share more); 0: never. True poses put 0-1.3 % there "
        "on simulated streets and interiors, 0-2 % on real scans; needs scans in their "
        "scanners' own frames",
    )
    free_space_penalty: float = key(
        0.0,
        "bnb: what a source point costs where the target's scanner saw empty space at its "
        "slice's height, in points on a target pixel (0: nothing, the field counts hits "
        "only); needs scans in their scanners' own frames. At 4 the truth was among the 24 "
        "candidates of 46 of 72 neighbour pairs of 5 simulated office floors (36 at 0), but "
        "the trust sweep's 9 floors had 30 of 81 scans ok (32 at 0) and 63 right links in "
        "their networks (70): off by default",
    )
    free_space_share: float = key(
        0.003,
        "how much more of the points (a share) a candidate must put into free space than the "
        "cleanest candidate to be refuted (indoors the true pose put 0-0.15 %, wrong poses "
        "slid by a room or turned 0.2-30 %)",
    )


@dataclass(frozen=True)
class RefineConfig:
    """After NDT, robust point-to-plane ICP in full 6-DOF on thinned 3D points (the paper's
    suggested last step)."""

    method: Literal["none", "icp"] = key(
        "icp", "icp, or none: keep the NDT result (planar pose, levelling and tz)"
    )
    voxel: float = key(0.1, "3D thinning of both scans (m)")
    max_distance: float = key(
        1.0, "first correspondence distance (m); shrinks by 0.7 per iteration"
    )
    min_distance: float = key(0.1, "final correspondence distance (m)")
    huber: float = key(0.02, "Huber threshold of the point-to-plane residuals (m)")
    iterations: int = key(40, "ICP iterations at most")
    max_correction: float = key(
        1.0, "an ICP change larger than this (m, or this many degrees) is not trusted"
    )


@dataclass(frozen=True)
class QualityConfig:
    """The quality gate: a converged registration that misses any threshold is suspect (exit
    code 1). Every check's false alarms and misses were measured on varied simulated streets
    and real scans (``benchmarks/trust_sweep.py``, docs/gate.md); thresholds may be made
    stricter than these defaults, never looser."""

    max_ambiguity: float = key(
        0.95,
        "a distinct candidate that the free space does not refute and that has at least this "
        "share of the kept pose's evidence is its rival: the link is ambiguous and the network "
        "chooses between them (indoors 0.5: NDT's evidence favours poses that put the two "
        "scanners close together)",
    )
    max_ambiguity_turned: float = key(
        0.8,
        "the same for a candidate turned from the kept pose by 90 or 180 degrees: streets, "
        "blocks and rooms of right angles repeat when turned, and a pair that does not overlap "
        "matches only such copies (wrong links of a district: their turned rivals had "
        "0.76-0.94 of the evidence; indoors the 0.5 above governs)",
    )
    min_constraint_ratio: float = key(
        0.01,
        "degeneracy of a pose from the slices alone (no ICP): smaller over larger curvature of "
        "the NDT score in translation (ordinary streets 0.001-0.6, a straight corridor of "
        "uniform facades about 0.001); below it the link is degenerate and the weak direction "
        "is named",
    )
    min_constraint_ratio_icp: float = key(
        0.02,
        "degeneracy of a pose refined by ICP: smallest over largest eigenvalue of ICP's "
        "translation information once rotation is free (right links of varied streets and "
        "real scans 0.037-0.6; corridors and links slid along a street 0.001-0.013)",
    )
    max_free_space: float = key(
        0.10,
        "the share of points the final pose puts into space the other scanner saw empty, in "
        "front of what it saw in their direction (right poses: simulated streets up to 0.062, "
        "real scans up to 0.091; wrong poses that passed every other check 0.113 and more); "
        "needs scans in their scanners' own frames (off with search.free_space_ratio: 0); not "
        "asked where max_free_space_around is 0.01 or less (indoors: right poses of open-plan "
        "floors put 10-17 % here, 0-0.02 % around)",
    )
    max_free_space_around: float = key(
        0.05,
        "the same share in front of all the other scanner saw around each direction (a ceiling "
        "or a corridor wall seen at grazing angles puts right interior poses at 4-7 % of the "
        "share above, 0-0.15 % of this one; right poses of real scans up to 2 %); indoors 0.005",
    )
    min_kept_evidence: float = key(
        0.7,
        "a pose kept because the free space refuted candidates of more evidence needs at least "
        "this share of the most evidence, else the link is suspect (on a busy street, scans "
        "39 m apart, the eighth candidate, 0.53 of it, was kept 2.7 m off; right kept poses "
        "of the sample street 0.89)",
    )
    min_score_per_point: float = key(
        0.0,
        "optional: NDT score per moving slice point on 1 m cells; 0 = off. It measures how "
        "much of the slices fit, not whether the pose is right: right links of varied streets "
        "scored 0.02-0.38, wrong ones 0.02-0.43, and a threshold of 0.12 flagged 30 % of the "
        "right links",
    )
    min_overlap: float = key(
        0.0,
        "optional: share of moving slice points that fall into a target cell; 0 = off (0.2 "
        "flagged 21 % of the right links of varied streets and caught no wrong link the other "
        "checks let through)",
    )
    overlap_distance: float = key(
        0.2, "3D overlap after ICP: a moving point needs a target point this near (m); reported"
    )
    trust_bridges: bool = key(
        True,
        "a link that no cycle of links checks (a bridge of the network) may tie a scan in on "
        "its own gate's word; false: only links on a cycle of links that agree do (interiors, "
        "where a room repeated along a corridor makes a single registration wrong without a "
        "sign)",
    )
    weak_links_join: bool = key(
        True,
        "a link kept with less than min_kept_evidence of the evidence of a pose the free space "
        "refuted may join two groups of scans in the choice among rivals; false (interiors): "
        "it is only checked within a group (two such links 25 and 34 m long agreed on an office "
        "floor's far half turned by 180 degrees, and its scans were ok and wrong)",
    )
    trust_walk_bridges: bool = key(
        True,
        "with trust_bridges false, a bridge between neighbours along the walk (scans taken one "
        "after the other, or either side of one scan no ok link touches: a room seen only "
        "through its door) may still tie a scan in on its own gate's word: the walk vouches for "
        "them, as it does outdoors; the wrong links that a gate passed indoors were between "
        "scans 13-26 m apart that the walk did not pair; false: no bridge at all",
    )
    walk_vouch_free_space: float = key(
        0.0,
        "a link between neighbours along the walk that the gate doubted only because a pose the "
        "free space refuted had more evidence (min_kept_evidence) is trusted as if the gate had "
        "passed it when its pose puts at most this share of the points in front of all the "
        "other scanner saw around them; 0: never. A pose that brings the scanners together "
        "meets more of both near fields and scores more, which indoors doubts right links "
        "between corridor neighbours (right ones put 0-0.02 % there, two wrong ones 0.06 % "
        "and 0.49 %); indoors 0.0005",
    )


@dataclass(frozen=True)
class Config:
    """All settings of a registration."""

    scene: SceneConfig = field(default_factory=SceneConfig)
    input: InputConfig = field(default_factory=InputConfig)
    ground: GroundConfig = field(default_factory=GroundConfig)
    slices: SlicesConfig = field(default_factory=SlicesConfig)
    grid: GridConfig = field(default_factory=GridConfig)
    source: SourceConfig = field(default_factory=SourceConfig)
    optimizer: OptimizerConfig = field(default_factory=OptimizerConfig)
    search: SearchConfig = field(default_factory=SearchConfig)
    refine: RefineConfig = field(default_factory=RefineConfig)
    quality: QualityConfig = field(default_factory=QualityConfig)

    def __post_init__(self) -> None:
        validate(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (lists instead of tuples), ready for YAML/JSON."""
        return _plain(dataclasses.asdict(self))

    def replace(self, **sections: dict[str, Any]) -> Config:
        """A copy with some keys of some sections changed: ``replace(grid={"overlap": True})``."""
        data = self.to_dict()
        for name, values in sections.items():
            if name not in data:
                raise ConfigError(f"unknown section '{name}'")
            data[name].update(values)
        return from_dict(data)


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj


def _convert(value: Any, tp: Any, key: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert (int->float, list->tuple)."""
    origin = typing.get_origin(tp)
    if origin is typing.Union or origin is types.UnionType:
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert(value, inner[0], key)
    if origin is Literal:
        choices = typing.get_args(tp)
        if value not in choices:
            raise ConfigError(
                f"'{key}' must be one of {', '.join(map(str, choices))}, got {value!r}"
            )
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"'{key}' must be a list, got {type(value).__name__}")
        item_tp = typing.get_args(tp)[0]
        return tuple(_convert(v, item_tp, f"{key}[{i}]") for i, v in enumerate(value))
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"'{key}' must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"'{key}' must be an integer, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"'{key}' must be a string, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"'{key}' must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"'{key}' must be a finite number, got {value}")
        return float(value)
    raise ConfigError(f"'{key}': unsupported type")  # pragma: no cover - programming error


def _section_from_dict(cls: type, data: Any, prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"'{prefix}' must be a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(
            f"unknown key '{prefix}.{unknown[0]}' (known: {', '.join(sorted(names))})"
            if prefix
            else f"unknown section '{unknown[0]}' (known: {', '.join(sorted(names))})"
        )
    kwargs = {}
    for name, value in data.items():
        key = f"{prefix}.{name}" if prefix else name
        tp = hints[name]
        if dataclasses.is_dataclass(tp):
            kwargs[name] = _section_from_dict(tp, value if value is not None else {}, key)
        else:
            kwargs[name] = _convert(value, tp, key)
    return kwargs if cls is Config else cls(**kwargs)


def from_dict(data: dict[str, Any] | None) -> Config:
    """Build a :class:`Config` from a nested dict; missing keys take their defaults."""
    return Config(**_section_from_dict(Config, data or {}, ""))
