"""``ndt-watch``: register each scan that lands in a folder into the campaign, at once."""

from __future__ import annotations

from dataclasses import dataclass, replace
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
    RadiusOpt,
    VerboseOpt,
    VersionOpt,
    check_out,
    command_line,
    ignore_stop_signals,
    load_config,
    new_app,
    setup_logging,
    user_errors,
)

if TYPE_CHECKING:
    from ndt_cli.cli.watch_screen import Screen
    from ndt_cli.config import Config
    from ndt_cli.pipeline.executors import Executor
    from ndt_cli.pipeline.field import FieldCampaign
    from ndt_cli.pipeline.field_events import Started
    from ndt_cli.pipeline.options import NetworkOptions
    from ndt_cli.pipeline.result import ChainResult

watch_app = new_app()

_HELP = "\n\n".join(
    [
        "Field mode: watch a folder and register each scan into the campaign once it has "
        "landed (completely written, in place or renamed in). It says when a scan landed, then "
        "where it is, its links (checked by a cycle or not, with overlap and residual), its "
        "status and the tally; a scan that fits nowhere is said so at once, so that it can be "
        "scanned again before the tripod moves, and an earlier scan whose verdict changes is "
        "said again. A file cut short or unreadable is read again once it changes; a file "
        "replaced in place is registered anew; a file that is no scan is named once and left "
        "alone. The outputs (as ndt-chain's) are published again after each scan, all "
        "together. Ctrl-C or SIGTERM end with a summary and leave a consistent result; "
        "started again on the same folders, it continues (finished links are reused).",
        FORMATS,
        EXIT_CODES + " With --exit-when-idle: 0 when every scan is ok and no file waits to be "
        "read whole, else 1.",
        "Example:\n\n  ndt-watch /media/usb/scans --out street/ --exit-when-idle 600",
    ]
)
MAX_IDLE_S = 1e6
HOLD_SETTLES = 5  # a file changing all the time holds an idle watch at least this many settles


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
            help="Exit once this many seconds pass with no scan landing and no file being "
            "written (a file that keeps changing holds it that long, or 5 settle times): 0 if "
            "every scan is ok, else 1.",
            show_default="never",
        ),
    ] = None,
    interval: Annotated[float, typer.Option(help="Seconds between looks at the folder.")] = 0.2,
    settle: Annotated[
        float, typer.Option(help="Seconds a file must stay unchanged to count as written.")
    ] = 0.5,
    print_config: PrintConfigOpt = False,
    json_out: Annotated[
        bool,
        typer.Option(
            "--json", help="Print one JSON object per line and event on stdout (nothing else)."
        ),
    ] = False,
    quiet: Annotated[
        bool,
        typer.Option(
            "--quiet",
            "-q",
            help="Print only what needs you: scans that are not ok, files that cannot be "
            "read, the folder gone, the closing lines, and errors.",
        ),
    ] = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
    version: VersionOpt = None,
) -> None:
    from ndt_cli.cli.watch_screen import Screen

    setup_logging(quiet or json_out, verbose)
    _one_line_per_scan()
    with user_errors("ndt-watch", debug):
        cfg = load_config(config, print_config)
        net = _network(neighbours, radius, control, crs)
        opts = _check(folder, out, jobs, net, exit_when_idle, interval, settle, control)
        opts = replace(opts, config=config or "default", crs=crs)
        from ndt_cli.io.outlock import output_lock

        with output_lock(out, "ndt-watch"):
            code = _run(cfg, opts, Screen(json_out, quiet))
    if code:
        raise typer.Exit(code)


def _one_line_per_scan() -> None:
    """The log holds the watch's lines: not the stages of each update."""
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
    control: Path | None
    config: str = "default"  # as given: a file or a shipped config's name
    crs: str | None = None  # as given


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
    if idle is not None and not 0 < idle <= MAX_IDLE_S:
        raise ConfigError(
            f"--exit-when-idle must be above 0 and at most {MAX_IDLE_S:g} s, got {idle}"
        )
    check_out(out, folder, control)
    return _Options(folder, out, jobs, net, idle, interval, settle, control)


def _run(cfg: Config, opts: _Options, screen: Screen) -> int:
    """Watch until idle or stopped, showing each event; the exit code."""
    import signal

    from ndt_cli.errors import EXIT_INTERRUPTED, UserInterruptError, caused_by_interrupt
    from ndt_cli.pipeline.executors import ExecutorKind, make_executor

    pool = make_executor(ExecutorKind.LOCAL, opts.jobs)
    stop = _Stop()
    field, why = None, "idle"
    try:
        pool.start()  # before this process starts threads of its own
        signal.signal(signal.SIGTERM, stop.terminate)  # after the workers started: theirs stays
        field = _field(cfg, opts, pool)
        screen.show(_started(opts, pool))
        _loop(field, opts, screen)
    except BaseException as exc:
        if not (caused_by_interrupt(exc) or isinstance(exc, UserInterruptError)):
            raise
        why = "terminated" if stop.terminated else "interrupted"
    finally:
        _close(pool)
    if why != "idle":  # stopped: a further Ctrl-C adds nothing to the summary that follows
        ignore_stop_signals()
    if field is None:  # stopped before the watch began
        return EXIT_INTERRUPTED
    stopped = field.stopped(why, opts.out)
    if field.result is not None:
        from ndt_cli.report.world import closing_lines

        stopped = replace(stopped, world=tuple(closing_lines(field.result)))
    screen.show(stopped)
    return stopped.exit_code


def _close(pool: Executor) -> None:
    """Close the worker pool; a second Ctrl-C while it waits for the workers' tasks makes it
    kill them instead (see ``WorkerPool.close``), and the summary still follows."""
    import contextlib

    with contextlib.suppress(KeyboardInterrupt):
        pool.close()


class _Stop:
    """SIGTERM stops the watch as Ctrl-C does, and is remembered."""

    terminated = False

    def terminate(self, signum: int, frame: object) -> None:
        self.terminated = True
        raise KeyboardInterrupt


def _field(cfg: Config, opts: _Options, pool: Executor) -> FieldCampaign:
    """The field campaign over the folder, publishing into ``opts.out``."""
    import logging
    import time

    from ndt_cli.io import SUPPORTED_SUFFIXES
    from ndt_cli.pipeline.campaign import Campaign
    from ndt_cli.pipeline.chain import scene_of
    from ndt_cli.pipeline.field import FieldCampaign, Publisher
    from ndt_cli.pipeline.watch import FolderWatch
    from ndt_cli.report.chain_outputs import write_chain_outputs
    from ndt_cli.report.reasons import with_named_reasons
    from ndt_cli.report.world import first_scan_role

    t0 = time.perf_counter()
    settled: list[Config] = []  # the config for the scene the first scan sees

    def make(first: Path | None) -> Campaign:
        if first is not None and not settled:
            settled.append(scene_of(cfg, [first], logging.DEBUG))  # the screen: events only
        used = settled[0] if settled else cfg
        return Campaign(used, opts.out, pool, network=opts.net, resume=True)

    def write(result: ChainResult) -> None:
        used = settled[0] if settled else cfg
        write_chain_outputs(opts.out, result, used, time.perf_counter() - t0, command_line())

    skip = tuple(p for p in (opts.control,) if p is not None)
    hold = float("inf") if opts.idle is None else max(opts.idle, HOLD_SETTLES * opts.settle)
    watch = FolderWatch(opts.folder, SUPPORTED_SUFFIXES, opts.settle, skip, hold)
    publisher = Publisher(with_named_reasons, write, first_scan_role)
    return FieldCampaign(make, watch, publisher, stations=bool(opts.net.stations))


def _started(opts: _Options, pool: Executor) -> Started:
    from ndt_cli.pipeline.field_events import Started

    control = None if opts.control is None else str(opts.control)
    jobs = int(getattr(pool, "jobs", opts.jobs or 1))
    return Started(
        str(opts.folder),
        str(opts.out),
        opts.config,
        jobs,
        opts.settle,
        opts.idle,
        control,
        opts.crs,
    )


def _loop(field: FieldCampaign, opts: _Options, screen: Screen) -> None:
    """Look, register, show; until idle (``opts.idle``) or stopped. Idle counts from the last
    event that is activity, or the last file seen changing."""
    import time

    from ndt_cli.pipeline.field_events import EventKind

    quiet = (EventKind.SKIPPED, EventKind.FOLDER)  # no activity: the idle clock runs on
    last = time.monotonic()
    while True:
        active = False
        for event in field.step():
            screen.show(event)
            active |= event.kind not in quiet
        if active or field.busy:
            last = time.monotonic()
        if opts.idle is not None and time.monotonic() - last >= opts.idle:
            return
        time.sleep(opts.interval)
