"""``ndt-watch``: register each scan that lands in a folder into the campaign, at once."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ndt_cli.cli.common import (
    EXIT_CODES,
    FORMATS,
    ConfigOpt,
    ControlOpt,
    CrsOpt,
    DebugOpt,
    JobsOpt,
    NeighboursOpt,
    OneLineCommand,
    PrintConfigOpt,
    QuietOpt,
    RadiusOpt,
    VerboseOpt,
    VersionOpt,
    check_out,
    command_line,
    load_config,
    new_app,
    setup_logging,
    user_errors,
)
from ndt_cli.errors import EXIT_REGISTRATION

if TYPE_CHECKING:
    from ndt_cli.config import Config
    from ndt_cli.pipeline.campaign import Campaign, NetworkOptions
    from ndt_cli.pipeline.result import ChainResult, ScanReport
    from ndt_cli.pipeline.watch import Landed

watch_app = new_app()

_HELP = "\n\n".join(
    [
        "Field mode: watch a folder and register each scan into the campaign once it has "
        "landed (completely written, in place or renamed in). Each scan gets one line: where "
        "it is, which scans it links to, its status and the time it took; a scan that fits "
        "nowhere is said so at once, so that it can be scanned again before the tripod moves. "
        "The outputs (as ndt-chain's) are published again after each scan, all together. "
        "Ctrl-C or SIGTERM leave a consistent result; started again on the same folders, it "
        "continues (finished links are reused).",
        FORMATS,
        EXIT_CODES + " With --exit-when-idle: 0 when every scan is ok, else 1.",
        "Example:\n\n  ndt-watch /media/usb/scans --out street/ --exit-when-idle 600",
    ]
)
_STOPPED = "stopped: the outputs hold every scan registered so far; start again to continue"


@watch_app.command(help=_HELP, cls=OneLineCommand)
def watch(
    folder: Annotated[Path, typer.Argument(help="Folder the scans land in.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("ndt_field"),
    config: ConfigOpt = None,
    jobs: JobsOpt = None,
    neighbours: NeighboursOpt = 4,
    radius: RadiusOpt = None,
    control: ControlOpt = None,
    crs: CrsOpt = None,
    exit_when_idle: Annotated[
        float | None,
        typer.Option(
            help="Exit once no scan has landed for this many seconds (0 if all are ok, else 1).",
            show_default="never",
        ),
    ] = None,
    interval: Annotated[float, typer.Option(help="Seconds between looks at the folder.")] = 0.2,
    settle: Annotated[
        float, typer.Option(help="Seconds a file must stay unchanged to count as written.")
    ] = 0.5,
    print_config: PrintConfigOpt = False,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
    version: VersionOpt = None,
) -> None:
    setup_logging(quiet, verbose)
    _one_line_per_scan()
    with user_errors("ndt-watch", debug, _STOPPED):
        cfg = load_config(config, print_config)
        net = _network(neighbours, radius, control, crs)
        opts = _check(folder, out, jobs, net, exit_when_idle, interval, settle, control)
        from ndt_cli.io.outlock import output_lock

        with output_lock(out, "ndt-watch"):
            ok = _run(cfg, opts)
    if not ok:
        raise typer.Exit(EXIT_REGISTRATION)


def _one_line_per_scan() -> None:
    """The log holds a line per scan: not the stages of each update."""
    import logging

    from ndt_cli.core.logs import PROGRESS

    logging.getLogger(PROGRESS).setLevel(logging.WARNING)


@dataclass(frozen=True)
class _Options:
    folder: Path
    out: Path
    jobs: int | None
    net: NetworkOptions
    idle: float | None
    interval: float
    settle: float


def _network(
    neighbours: int, radius: float | None, control: Path | None, crs: str | None
) -> NetworkOptions:
    """The network's options, checked; the control stations wait for their scans to land."""
    from ndt_cli.pipeline.inputs import network_options

    return network_options(neighbours, True, radius, None, None, control, crs)


def _check(
    folder: Path,
    out: Path,
    jobs: int | None,
    net: NetworkOptions,
    idle: float | None,
    interval: float,
    settle: float,
    control: Path | None,
) -> _Options:
    """The options, checked before any work."""
    from ndt_cli.errors import ConfigError, InputError

    if not folder.is_dir():
        raise InputError("not a folder", folder)
    if jobs is not None and jobs < 1:
        raise ConfigError("--jobs must be >= 1")
    for name, value in (("--interval", interval), ("--settle", settle)):
        if not 0 < value <= 3600:
            raise ConfigError(f"{name} must be above 0 and at most 3600 s, got {value}")
    if idle is not None and not 0 < idle <= 1e6:
        raise ConfigError(f"--exit-when-idle must be above 0 s, got {idle}")
    check_out(out, folder, control)
    return _Options(folder, out, jobs, net, idle, interval, settle)


def _run(cfg: Config, opts: _Options) -> bool:
    """Watch until idle (or stopped); True when every scan is ok."""
    import signal
    import time

    from ndt_cli.io import SUPPORTED_SUFFIXES
    from ndt_cli.pipeline.campaign import Campaign
    from ndt_cli.pipeline.executors import ExecutorKind, make_executor
    from ndt_cli.pipeline.watch import FolderWatch
    from ndt_cli.report.world import closing_lines

    signal.signal(signal.SIGTERM, _interrupt)
    pool = make_executor(ExecutorKind.LOCAL, opts.jobs)
    pool.start()  # before this process starts threads of its own
    campaign = Campaign(
        cfg, opts.out, pool, network=opts.net, resume=True, on_interrupt="start ndt-watch again"
    )
    folder = FolderWatch(opts.folder, SUPPORTED_SUFFIXES, opts.settle)
    last, result = time.monotonic(), None
    try:
        while opts.idle is None or time.monotonic() - last < opts.idle:
            landed = folder.poll()
            for scan in landed:
                result = _add(campaign, scan, cfg, opts.out) or result
            if landed or folder.pending:  # idle counts from the end of the last update
                last = time.monotonic()
            time.sleep(opts.interval)
    finally:
        campaign.close()
    for line in closing_lines(result) if result is not None else ():
        typer.echo(line, err=True)
    return result is not None and result.ok


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def _add(campaign: Campaign, scan: Landed, cfg: Config, out: Path) -> ChainResult | None:
    """Register a landed scan, publish the outputs, print its line."""
    import time

    from ndt_cli.pipeline.scans import DuplicateScanError
    from ndt_cli.report.chain_outputs import write_chain_outputs
    from ndt_cli.report.reasons import with_named_reasons
    from ndt_cli.report.world import first_scan_role

    t0 = time.perf_counter()
    try:
        campaign.add_scans([scan.path])
    except DuplicateScanError as exc:  # registered once: the copy is left alone
        same = f"{scan.path.name}: the same content as {exc.original.name}: left alone"
        typer.echo(same, err=True)
        return None
    result = with_named_reasons(campaign.result())
    write_chain_outputs(out, result, cfg, time.perf_counter() - t0, command_line())
    report = campaign.report(len(result.scans) - 1, result)
    role = first_scan_role(result)
    typer.echo(_line(report, time.time() - scan.mtime, time.perf_counter() - t0, role), err=True)
    return result


def _line(report: ScanReport, since_landing: float, took: float, role: str) -> str:
    """One log line: the scan, where it is, what it links to, its status, the times; the first
    scan's ``role`` in the world frame."""
    from ndt_cli.pipeline.verify import NodeStatus

    name, status = report.name, report.status
    timing = f"{took:.1f} s ({since_landing:.1f} s since it landed)"
    if report.index == 0 and not report.linked:
        return f"{name}: the first scan, {role}; {timing}"
    if status is NodeStatus.UNPOSED and not report.linked:
        why = f": {report.reason}" if report.reason else ""
        return f"{name}: FITS NOWHERE{why}; scan again here? {timing}"
    x, y, z = report.position if report.position is not None else (float("nan"),) * 3
    links = ", ".join(report.linked) or "none"
    reason = f" ({report.reason})" if report.reason else ""
    return (
        f"{name}: {status.value}{reason} at ({x:.2f}, {y:.2f}, {z:.2f}) m, "
        f"linked to {links}; {timing}"
    )
