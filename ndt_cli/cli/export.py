"""``ndt-export``: the registered point cloud of a result, with its attributes and CRS."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, NamedTuple

import typer

from ndt_cli.cli.common import (
    PROGRESS,
    DebugOpt,
    JsonOpt,
    OneLineCommand,
    QuietOpt,
    ResultDirArg,
    VersionOpt,
    new_app,
    setup_logging,
    user_errors,
)

export_app = new_app()
log = logging.getLogger(PROGRESS)

_FORMATS = (".las", ".laz", ".ply", ".e57")
_HELP = "\n\n".join(
    [
        "Apply the registered pose T_world_scan of every ok scan of an ndt-chain or "
        "ndt-register result to the original files and write the registered cloud: one merged "
        "LAS, LAZ or PLY file (by the extension of --out), or one file per scan (--per-scan), "
        "or an E57 with one scan per station, each with its pose in its header.",
        "Every point dimension is kept (intensity, colour, classification, returns, GPS time, "
        "extra bytes); each point records its scan in the extra dimension scan_index; the "
        "anchor scan's coordinate system (WKT or GeoTIFF keys) is copied; coordinates are "
        "stored to the millimetre. Suspect scans are left out unless --include-suspect; "
        "unposed scans always. A campaign that the network split exports its anchor's "
        "cluster (0), or the cluster --cluster names, in the frame of that cluster's first "
        "scan.",
        "Exit codes: 0 written; 2 bad input (not a result folder, a scan file missing, a result "
        "its --control did not georeference) or an output that cannot be written; 130 stopped "
        "by Ctrl-C.",
        "Examples:\n\n"
        "  ndt-export street/ --out street.laz\n\n"
        "  ndt-export street/ --out street_2cm.laz --voxel 0.02\n\n"
        "  ndt-export street/ --per-scan registered/ --format laz\n\n"
        "  ndt-export street/ --out street.e57",
    ]
)


@export_app.command(help=_HELP, cls=OneLineCommand)
def export_cmd(
    result_dir: ResultDirArg = None,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="The merged file: .las, .laz, .ply, .e57.")
    ] = None,
    per_scan: Annotated[
        Path | None, typer.Option("--per-scan", help="Write one file per scan into this folder.")
    ] = None,
    fmt: Annotated[
        str, typer.Option("--format", help="Format of the --per-scan files: las, laz, ply.")
    ] = "laz",
    voxel: Annotated[
        float | None,
        typer.Option(help="Keep one point per voxel of this size (m), world frame."),
    ] = None,
    scans: Annotated[
        str | None, typer.Option(help="Only these scans: names or indices, comma-separated.")
    ] = None,
    include_suspect: Annotated[
        bool, typer.Option("--include-suspect", help="Export suspect scans too.")
    ] = False,
    cluster: Annotated[
        int,
        typer.Option(min=0, help="Export this cluster of scans (0: the anchor's; see poses.csv)."),
    ] = 0,
    json_out: JsonOpt = False,
    quiet: QuietOpt = False,
    debug: DebugOpt = False,
    version: VersionOpt = None,
) -> None:
    setup_logging(quiet or json_out, False)
    with user_errors("ndt-export", debug):
        target, per_scan_dir = _targets(result_dir, out, per_scan, fmt, voxel)
        assert result_dir is not None
        chosen = _Choice(scans, include_suspect, cluster)
        written = _run(result_dir, target, per_scan_dir, voxel, chosen, quiet)
    if json_out:
        from ndt_cli.io.serialize import to_json

        typer.echo(to_json(written), nl=False)
    elif not quiet:
        where = per_scan_dir if per_scan_dir is not None else target
        count = f"{written['points_written']} points of {len(written['scans'])} scans"
        typer.echo(f"{count} written to {where}")


def _targets(
    result_dir: Path | None, out: Path | None, per_scan: Path | None, fmt: str, voxel: float | None
) -> tuple[Path, Path | None]:
    """The output file (or the per-scan folder and the file type), checked before any work."""
    from ndt_cli.errors import ConfigError, InputError, OutputError

    if result_dir is None:
        raise InputError("give the RESULT_DIR of ndt-chain or ndt-register (see --help)")
    if (out is None) == (per_scan is None):
        raise ConfigError("give either --out FILE or --per-scan FOLDER")
    if voxel is not None and not 0.001 <= voxel <= 100:
        raise ConfigError(f"--voxel must be between 0.001 and 100 m, got {voxel}")
    kind = fmt.lower().lstrip(".")
    if per_scan is not None and kind == "e57":
        raise ConfigError("--per-scan writes las, laz or ply; E57 holds every scan in one file")
    if per_scan is not None and f".{kind}" not in _FORMATS:
        raise ConfigError(f"--format must be las, laz or ply, got {fmt!r}")
    try:
        _check_place(out if out is not None else per_scan, per_scan is not None)
    except OSError as exc:
        raise OutputError(f"cannot write here ({exc.strerror or exc})", out or per_scan) from None
    return (out if out is not None else Path(f"scan.{kind}")), per_scan


def _check_place(path: Path, folder: bool) -> None:
    """The file (or the folder, ``folder``) to write: a legal name of the right kind."""
    from ndt_cli.errors import OutputError

    if len(os.fsencode(path.name)) > 255:
        raise OutputError("the name is longer than 255 bytes", path)
    if folder and path.exists() and not path.is_dir():
        raise OutputError("exists and is not a folder; --per-scan names a folder", path)
    if not folder and path.is_dir():
        raise OutputError("is a folder; --out names the file to write", path)
    if not folder and path.suffix.lower() not in _FORMATS:
        kinds = " ".join(_FORMATS)
        raise OutputError(
            f"cannot write {path.suffix or 'a file without extension'!r}; writable: {kinds}", path
        )
    parent = path.resolve().parent
    if parent.exists() and not parent.is_dir():
        raise OutputError("cannot write here (not a folder)", parent)


def _run(
    folder: Path,
    target: Path,
    per_scan: Path | None,
    voxel: float | None,
    choice: _Choice,
    quiet: bool,
) -> dict:
    """Export the selected scans of the result; what was written, as a JSON-ready dict."""
    from ndt_cli.errors import InputError
    from ndt_cli.io.export import export
    from ndt_cli.io.points import check_readable
    from ndt_cli.pipeline import result_folder

    scans, anchor = result_folder.result_scans(folder)
    cfg = result_folder.result_config(folder)
    # another cluster is in its first scan's frame, not the control's: its header's CRS
    crs = result_folder.result_crs(folder) if choice.cluster == 0 else None
    names = None if choice.names is None else choice.names.split(",")
    keep, left = result_folder.select(scans, names, choice.include_suspect, choice.cluster)
    for line in left:
        log.warning("left out %s", line)
    if not keep:
        raise InputError("no scan of the result can be exported (see the lines above)", folder)
    for k in keep:
        check_readable(scans[k].file)
    result_folder.check_scan_files(scans, keep)
    chosen = result_folder.export_scans(keep, scans, anchor, cfg)
    with _Bar(not quiet) as progress:
        res = export(
            chosen,
            target,
            voxel=voxel,
            per_scan_dir=per_scan,
            progress=progress,
            protect=[s.file for s in scans],
            crs=crs,
        )
    return {
        "files": [str(p) for p in res.paths],
        "scans": [scans[k].name for k in keep],
        "left_out": left,
        "points_read": res.points_read,
        "points_written": res.points_written,
        "points_thinned": res.points_thinned,
        "points_dropped": res.points_dropped,
        "point_format": res.point_format,
    }


class _Choice(NamedTuple):
    """Which scans of the result to export: ``--scans``, ``--include-suspect``, ``--cluster``."""

    names: str | None
    include_suspect: bool
    cluster: int


class _Bar:
    """A progress bar on a terminal; a line per tenth of the points in a log."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bar, self.task, self.tenth = None, None, -1

    def __enter__(self) -> Callable[[int, int], None]:
        import sys

        if self.enabled and sys.stderr.isatty():
            from rich.progress import Progress

            self.bar = Progress(transient=True)
            self.bar.start()
            self.task = self.bar.add_task("points", total=None)
        return self.update

    def update(self, done: int, total: int) -> None:
        if self.bar is not None:
            self.bar.update(self.task, completed=done, total=total)
        elif self.enabled and total and (tenth := 10 * done // total) > self.tenth:
            self.tenth = tenth
            log.info("exported %d of %d points (%d %%)", done, total, 100 * done // total)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()
