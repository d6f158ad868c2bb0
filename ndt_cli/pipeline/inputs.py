"""A campaign's inputs from what a user gives: the scans in campaign order (natural order of
the file names, E57 files expanded into their scans), the anchor (an index or a scan name), the
network's options checked, and the user's pairs read. Everything is checked before any heavy
work; a problem is a :class:`~ndt_cli.errors.NdtError` naming the option or the file."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ndt_cli.errors import ConfigError, InputError, OutputError
from ndt_cli.io.crs import crs_wkt
from ndt_cli.pipeline.control import check_in_system, matched, read_stations
from ndt_cli.pipeline.guesses import parse_sigma, read_init_poses
from ndt_cli.pipeline.network import read_pairs
from ndt_cli.pipeline.options import NetworkOptions
from ndt_cli.pipeline.scans import DuplicateScanError, file_hash, natural_sort, scan_names


@dataclass(frozen=True)
class ChainInputs:
    """The scans in campaign order, the anchor's index and the network's options."""

    paths: tuple[Path, ...]
    anchor: int
    network: NetworkOptions

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(scan_names(list(self.paths)))


def campaign_scans(scans: Sequence[str | Path]) -> list[Path]:
    """The scans in campaign order: natural order of their names, each E57 file expanded into
    its scans (``FILE.e57#K``; PTX files likewise)."""
    from ndt_cli.io.multiscan_files import expand

    return expand(natural_sort(scans))


def refuse_twice(paths: Sequence[Path]) -> None:
    """Raise when two paths name one scan (the same file, or the same scan of one E57)."""
    from ndt_cli.io.multiscan import split_spec

    seen: dict[tuple[Path, int | None], Path] = {}
    for p in paths:
        file, index = split_spec(p)
        key = (file.resolve(), index)
        if key in seen:
            raise InputError(f"the same scan as {seen[key]}: give every scan once", p)
        seen[key] = p


def check_scans(paths: Sequence[Path]) -> None:
    """Raise the one-line error of the first scan that cannot be used, before any heavy work:
    a file that is missing, unreadable, of an unknown format or with a broken header
    (:func:`~ndt_cli.io.points.check_readable`), or a file whose content another scan has
    (the same scan under two names: registered once, it would be exported twice)."""
    from ndt_cli.io.points import check_readable

    for p in paths:
        check_readable(p)
    refuse_copies(paths)


def refuse_copies(paths: Sequence[Path]) -> None:
    """Raise :class:`DuplicateScanError` when two scans have the same content."""
    seen: dict[str, Path] = {}
    for p in paths:
        h = file_hash(p)
        if h is not None and h in seen:
            raise DuplicateScanError(seen[h], p)
        if h is not None:
            seen[h] = p


def anchor_index(anchor: str, names: Sequence[str]) -> int:
    """The index of the anchor scan given as an index or as a scan's (or file's) name."""
    for k, name in enumerate(names):
        if anchor in (name, Path(name).name):
            return k
    if re.fullmatch("[0-9]+", anchor) and int(anchor) < len(names):
        return int(anchor)
    raise ConfigError(
        f"--anchor {anchor} is neither a scan index (0..{len(names) - 1}) nor a scan name"
    )


def network_options(
    neighbours: int,
    adjust: bool,
    radius: float | None,
    pairs: Path | None,
    names: Sequence[str] | None,
    control: Path | None = None,
    crs: str | None = None,
    init_poses: Path | None = None,
    init_sigma: str = "1,5",
) -> NetworkOptions:
    """The network's options, checked; ``pairs``: a CSV of user pairs (see
    :func:`~ndt_cli.pipeline.network.read_pairs`); ``control``: a CSV of stations
    (:mod:`ndt_cli.pipeline.control`) and ``crs`` their coordinate system; ``init_poses``:
    approximate poses of scans within ``init_sigma`` (``M,DEG``; :mod:`~ndt_cli.pipeline.guesses`).
    ``names``: the campaign's scans, every station must name one; None in field mode (scans yet
    to land)."""
    if not 1 <= neighbours <= 10:
        raise ConfigError(f"--neighbours must be between 1 and 10, got {neighbours}")
    if radius is not None and not 0 < radius <= 1e4:
        raise ConfigError(f"--radius must be above 0 and at most 10000 m, got {radius}")
    sigma = parse_sigma(init_sigma)
    user = tuple(read_pairs(pairs, names or [], sigma)) if pairs is not None else ()
    guessed = read_init_poses(init_poses, names or []) if init_poses is not None else {}
    stations = read_stations(control) if control is not None else ()
    if names is not None and control is not None:
        matched(stations, names, control)
    if crs is not None and control is None:
        raise ConfigError("--crs names the coordinate system of --control: give both")
    if stations and not adjust:
        raise ConfigError("--control needs the adjustment (not --no-adjust)")
    wkt = crs_wkt(crs) if crs is not None else ""
    scale = 1.0
    if wkt and control is not None:
        scale = check_in_system(stations, wkt, crs, control)
    return NetworkOptions(neighbours, adjust, radius, user, stations, wkt, scale, guessed, sigma)


def chain_inputs(
    scans: Sequence[str | Path],
    *,
    anchor: str = "0",
    neighbours: int = 4,
    adjust: bool = True,
    radius: float | None = None,
    pairs: Path | None = None,
    control: Path | None = None,
    crs: str | None = None,
    init_poses: Path | None = None,
    init_sigma: str = "1,5",
) -> ChainInputs:
    """Everything ``ndt-chain`` needs to know before it starts, checked."""
    paths = campaign_scans(scans)
    if len(paths) < 2:
        raise InputError("ndt-chain needs at least two scans")
    refuse_twice(paths)
    check_scans(paths)
    names = scan_names(paths)
    index = anchor_index(anchor, names)
    net = network_options(
        neighbours, adjust, radius, pairs, names, control, crs, init_poses, init_sigma
    )
    return ChainInputs(tuple(paths), index, net)


def expected_links(n_scans: int, network: NetworkOptions) -> int:
    """About how many links a campaign of ``n_scans`` registers (for a progress display):
    half of each scan's neighbours (links are shared), the chain, the user's pairs."""
    per_scan = 1.0 if network.classic else max(1.0, network.neighbours / 2)
    return max(1, round(per_scan * (n_scans - 1))) + len(network.pairs)


def refuse_another_campaign(out: Path, paths: Sequence[Path]) -> None:
    """Raise :class:`OutputError` when the folder ``out`` holds the result of a campaign that
    shares no scan with ``paths`` (no file, no content): replacing it needs ``--overwrite``.
    The same campaign, a growing or a shrinking one, shares scans and updates it."""
    earlier = earlier_scans(out)
    if not earlier:
        return
    files = {str(p.resolve()) for p in paths}
    hashes = {file_hash(p) for p in paths} - {None}
    if any(f in files or h in hashes for f, h in earlier):
        return
    raise OutputError(
        f"holds the result of another campaign (its {len(earlier)} scan(s), "
        f"{Path(earlier[0][0]).name} first, are none of these): --overwrite replaces it, "
        "or choose another --out",
        out,
    )


def earlier_scans(out: Path) -> list[tuple[str, str | None]]:
    """(absolute file, SHA-256 or None) of each scan of the result in ``out``: a campaign's
    (``summary.json``) or a pair's (``result.json``); empty when it holds neither (or they
    cannot be read: the folder check has vouched that ndt-cli wrote it)."""
    import json

    try:
        if (out / "summary.json").is_file():
            data = json.loads((out / "summary.json").read_text(encoding="utf-8"))
            files = data.get("scan_files") or data.get("scans") or []
            hashes = data.get("scan_sha256") or [None] * len(files)
        elif (out / "result.json").is_file():
            data = json.loads((out / "result.json").read_text(encoding="utf-8"))
            ends = [e for e in ("target", "source") if data.get(f"{e}_file")]
            files = [data[f"{e}_file"] for e in ends]
            hashes = [data.get(f"{e}_sha256") for e in ends]
        else:
            return []
        pairs = zip(files, hashes, strict=False)  # a damaged file may hold fewer hashes
        return [(str(Path(f).resolve()), h if isinstance(h, str) else None) for f, h in pairs]
    except (OSError, ValueError, TypeError, AttributeError):
        return []
