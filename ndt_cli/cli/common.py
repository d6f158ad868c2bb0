"""What every command shares: the app settings, ``--version``, logging, the error guard, and the
texts and options that several commands show.

Only typer and the standard library are imported here, and help is plain click text (no rich
rendering): ``--help`` stays as fast as importing typer. Heavy modules are imported inside the
commands.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import logging
import os
import signal
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperCommand, TyperGroup

from ndt_cli.core.logs import PROGRESS
from ndt_cli.errors import EXIT_INTERRUPTED, NdtError, UserInterruptError, caused_by_interrupt

try:  # typer >= 0.2x vendors click
    from typer._click.exceptions import ClickException
except ImportError:  # pragma: no cover - typer on the standalone click package
    from click.exceptions import ClickException

EXIT_CODES = (
    "Exit codes: 0 success; 1 a result is not trustworthy (suspect, degenerate, not converged, "
    "no overlap, failed; ndt-chain: any scan not ok, or --control given and the campaign not "
    "georeferenced); 2 bad input, config or output path; "
    "130 stopped by Ctrl-C."
)
FORMATS = (
    "Formats: PLY, LAS, LAZ, E57 and PTX (FILE.e57#K, FILE.ptx#K name scan K), PCD, and text "
    "(xyz, txt, csv, 3d: "
    "the first three columns are x y z)."
)
CONFIG_HELP = (
    "YAML config file, or the name of a shipped one (default, paper, lm, 3dtk, noisy_sensor)."
)

ConfigOpt = Annotated[str | None, typer.Option("--config", "-c", help=CONFIG_HELP)]
PrintConfigOpt = Annotated[
    bool,
    typer.Option("--print-config", help="Print the effective config (commented YAML) and exit."),
]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="Print only warnings and errors.")]
VerboseOpt = Annotated[
    bool, typer.Option("--verbose", "-v", help="Debug messages of ndt-cli (never of libraries).")
]
DebugOpt = Annotated[bool, typer.Option("--debug", help="Show tracebacks of errors.")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the result as JSON on stdout.")]
NeighboursOpt = Annotated[
    int,
    typer.Option(
        "--neighbours", "-k", help="Nearest scans each scan is registered to (1: a chain)."
    ),
]
RadiusOpt = Annotated[
    float | None,
    typer.Option(
        help="Register no two scans farther apart than this (m).",
        show_default="2.2 x the median distance between nearest scans",
    ),
]
PairsOpt = Annotated[
    Path | None,
    typer.Option(
        help="CSV of target,source rows: more pairs to register (scan names); a row may add a "
        "guess of T_target_source: x,y,z,yaw_deg or a 4x4 file."
    ),
]
InitPosesOpt = Annotated[
    Path | None,
    typer.Option(
        "--init-poses",
        help="Approximate T_world_scan of scans: lines of a name and 16 numbers (as poses.txt) "
        "or x y z yaw_deg (GNSS and a compass, yesterday's campaign, a placement by hand). Links "
        "between them are registered from the guess too.",
    ),
]
InitSigmaOpt = Annotated[
    str,
    typer.Option(
        "--init-sigma",
        metavar="M,DEG",
        help="How far a guess may be from the truth: metres and degrees (a GNSS position or a "
        "placement by hand: 1,5). Registration from a guess starts at the smallest cell of at "
        "least twice the metres and searches the heading within the degrees.",
    ),
]
ControlOpt = Annotated[
    Path | None,
    typer.Option(
        help="CSV of scan,x,y,z,sigma_xy,sigma_z rows: stations of known coordinates (m; "
        "sigmas blank: 2 cm and 3 cm). The world is then their coordinate system.",
    ),
]
CrsOpt = Annotated[
    str | None,
    typer.Option(
        help="The coordinate system of --control: EPSG:NNNN, or a file holding WKT; written "
        "into the exported LAS/LAZ.",
    ),
]
JobsOpt = Annotated[
    int | None,
    typer.Option(
        "--jobs", "-j", help="Parallel processes (at most one per core).", show_default="all cores"
    ),
]
ResultDirArg = Annotated[
    Path | None, typer.Argument(help="Output folder of ndt-chain or ndt-register.")
]

_log = logging.getLogger("ndt_cli")


def _print_version(ctx: typer.Context, value: bool) -> None:
    if value:
        from ndt_cli import __version__

        typer.echo(f"{ctx.find_root().info_name} {__version__}")
        raise typer.Exit()


VersionOpt = Annotated[
    bool | None,
    typer.Option(
        "--version",
        "-V",
        callback=_print_version,
        is_eager=True,
        help="Print the version and exit.",
    ),
]


YOUNG_COLLECTION = 100_000  # allocations between two collections of the youngest generation
OLD_COLLECTIONS = (50, 1000)  # Python's defaults are 700, 10, 10


@contextlib.contextmanager
def collector_for_a_command() -> Iterator[None]:
    """Python's cyclic garbage collector set for one command, then restored.

    Start-up leaves several hundred thousand long-lived objects (the imports, Numba's typing
    registries). With the default thresholds the collector traverses them again and again
    while they are made, and the interpreter's last collection traverses them once more: in a
    fresh ``ndt-register`` about a tenth of the wall time, most of it at exit. During the
    command the young generation is collected every :data:`YOUNG_COLLECTION` allocations
    instead of 700 and full collections are rare (reference cycles are still collected); when
    the interpreter exits, every object left is frozen first (``gc.freeze``), so that its last
    collection skips them."""
    before = gc.get_threshold()
    gc.set_threshold(YOUNG_COLLECTION, *OLD_COLLECTIONS)
    atexit.unregister(gc.freeze)  # once, however many commands a process runs
    atexit.register(gc.freeze)
    try:
        yield
    finally:
        gc.set_threshold(*before)


def _one_line_main(main: Any, self: Any, args: Any, prog_name: Any, kw: dict) -> Any:
    """Run a click command; a usage error (bad option value, unknown option, unreadable path
    given to click) is one line on stderr and exit code 2, as every other user error. Warnings
    of libraries (numpy's RuntimeWarning on an overflow) are never shown: what they mean is
    checked and said in ndt-cli's own words."""
    standalone = kw.pop("standalone_mode", True)
    try:
        with collector_for_a_command(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            value = main(self, args, prog_name, standalone_mode=False, **kw)
    except ClickException as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # a bare group command: its help
            exc.show()
            sys.exit(2)
        ctx = getattr(exc, "ctx", None)
        prog = ctx.find_root().info_name if ctx is not None else (prog_name or "ndt-cli")
        typer.echo(f"{prog}: error: {' '.join(exc.format_message().split())}", err=True)
        sys.exit(exc.exit_code)
    except (typer.Abort, KeyboardInterrupt):  # a Ctrl-C outside the command's guard
        typer.echo("interrupted", err=True)
        value = EXIT_INTERRUPTED
    if value == EXIT_INTERRUPTED:
        _end_if_workers_abandoned()
    if standalone:
        sys.exit(value if isinstance(value, int) else 0)
    return value


def _end_if_workers_abandoned() -> None:
    """End the process now (exit 130) when a second Ctrl-C made the command kill its worker
    processes rather than wait for them: the interpreter's exit hooks would wait for the
    pool's manager thread, which may never end (see ``WorkerPool.close``)."""
    pool = sys.modules.get("ndt_cli.pipeline.local_pool")
    if pool is not None and pool.abandoned():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(EXIT_INTERRUPTED)


class OneLineCommand(TyperCommand):
    """A command whose usage errors are one line (see :func:`_one_line_main`)."""

    def main(self, args: Any = None, prog_name: str | None = None, **kw: Any) -> Any:
        return _one_line_main(TyperCommand.main, self, args, prog_name, kw)


class OneLineGroup(TyperGroup):
    """A group of commands whose usage errors are one line."""

    def main(self, args: Any = None, prog_name: str | None = None, **kw: Any) -> Any:
        return _one_line_main(TyperGroup.main, self, args, prog_name, kw)


def new_app(**kwargs: object) -> typer.Typer:
    """A Typer app with the project's settings: completion available, plain help, one-line
    errors instead of usage blocks or pretty tracebacks. Register its commands with
    ``cls=OneLineCommand``."""
    return typer.Typer(
        cls=OneLineGroup,
        add_completion=True,
        pretty_exceptions_enable=False,
        rich_markup_mode=None,
        context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
        **kwargs,
    )


class _Held(logging.Handler):
    """Holds the library's messages until the command ends; on a user error they are dropped,
    so that the error is the only line."""

    def __init__(self) -> None:
        super().__init__()
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


class _Format(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        text = record.getMessage()
        return text if record.levelno == logging.INFO else f"{record.levelname.lower()}: {text}"


_held = _Held()
_shown = logging.StreamHandler(sys.stderr)


def setup_logging(quiet: bool, verbose: bool) -> None:
    """ndt-cli's messages on stderr (INFO; DEBUG with ``verbose``; warnings only when
    ``quiet``); progress lines at once, other messages when the command ends; nothing from
    third-party libraries (they fail through one-line errors instead)."""
    logging.getLogger().setLevel(logging.CRITICAL + 1)
    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    global _shown
    _shown = logging.StreamHandler(sys.stderr)
    _shown.setFormatter(_Format())
    _held.records.clear()
    for name, handler in (("ndt_cli", _held), (PROGRESS, _shown)):
        logger = logging.getLogger(name)
        logger.handlers[:] = [handler]
        logger.setLevel(level)
        logger.propagate = False


def flush_messages() -> None:
    """Print the held messages (the command ended without a user error)."""
    for record in _held.records:
        if record.levelno >= _log.getEffectiveLevel():
            _shown.handle(record)
    _held.records.clear()


def fail(exc: NdtError, prog: str) -> typer.Exit:
    """Print the one-line error and return the exit to raise."""
    _held.records.clear()
    typer.echo(f"{prog}: error: {exc}", err=True)
    return typer.Exit(exc.exit_code)


def let_ctrl_c_in() -> None:
    """Unblock SIGINT in this thread. A process inherits its parent's signal mask: started by
    a program that had SIGINT blocked at that moment, a command would never see Ctrl-C (it ran
    to its end and exited 0). A SIGINT that is ignored (``nohup``, a background job) stays
    ignored: that is the user's choice."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def stop_on_sigterm() -> None:
    """SIGTERM (``kill``, ``timeout``, a service manager) stops the command as Ctrl-C does:
    what finished is kept, one line, exit 130 (worker processes ignore it and finish their
    tasks first)."""
    signal.signal(signal.SIGTERM, _interrupt)


def ignore_stop_signals() -> None:
    """Stopped: a second Ctrl-C or SIGTERM adds nothing. Ignored rather than left to Python's
    handlers, which the interpreter resets to the default as it exits (a signal then would
    kill the process, exit -2 instead of 130)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


@contextlib.contextmanager
def user_errors(prog: str, debug: bool, interrupted: str = "interrupted") -> Iterator[None]:
    """Turn user errors and Ctrl-C into one line on stderr and the documented exit code; print
    the held messages when the block ends without one."""
    let_ctrl_c_in()
    try:
        yield
    except NdtError as exc:
        if isinstance(exc, UserInterruptError):
            ignore_stop_signals()
        if debug:
            raise
        raise fail(exc, prog) from None
    except BaseException as exc:
        if not caused_by_interrupt(exc):
            raise
        ignore_stop_signals()
        raise fail(UserInterruptError(interrupted), prog) from None
    flush_messages()


def command_line() -> str:
    """The command line this process was started with, quoted as a shell reads it (for the
    report's header): the program's file name, then its arguments."""
    import shlex

    return shlex.join([sys.argv[0].rsplit("/", 1)[-1], *sys.argv[1:]])


def load_config(config: str | None, print_config: bool) -> object:
    """The effective config; with ``print_config`` it is printed (commented YAML) and the
    command ends."""
    from ndt_cli.config import load
    from ndt_cli.config.printing import commented_yaml

    cfg = load(config)
    if print_config:
        origin = "the defaults" if config is None else f"the defaults merged with {config}"
        typer.echo(commented_yaml(cfg, origin), nl=False)
        raise typer.Exit()
    return cfg


def console(stderr: bool = False) -> object:
    """A rich console: on a terminal as wide as it; otherwise never cutting a table."""
    from rich.console import Console

    stream = sys.stderr if stderr else sys.stdout
    return Console(file=stream, width=None if stream.isatty() else 10_000, soft_wrap=True)


def check_out(out: Path, *inputs: Path | str | None) -> Path:
    """The output folder, checked before any work: new, empty, or an earlier result, and
    neither one of the run's ``inputs`` (files and folders it reads; None and names that are
    no file, such as a shipped config's, are skipped) nor holding or inside one."""
    from ndt_cli.io.outdir import check_output_folder

    return check_output_folder(out, [Path(p) for p in inputs if p is not None])
