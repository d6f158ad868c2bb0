"""What every command shares: logging set-up, the error guard, the shared options.

Only typer and the standard library are imported here: ``--help`` must stay fast. Heavy
modules are imported inside the commands.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated

import typer

from ndt_cli.errors import NdtError, UserInterruptError

ConfigOpt = Annotated[Path | None, typer.Option("--config", "-c", help="YAML config file.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="Print errors only.")]
VerboseOpt = Annotated[bool, typer.Option("--verbose", "-v", help="More log messages.")]
DebugOpt = Annotated[bool, typer.Option(help="Show tracebacks of errors.")]


def new_app(**kwargs: object) -> typer.Typer:
    """A Typer app with the project's settings (no pretty tracebacks: errors are one line)."""
    return typer.Typer(add_completion=False, pretty_exceptions_enable=False, **kwargs)


def setup_logging(quiet: bool, verbose: bool) -> None:
    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    logging.basicConfig(
        level=level, format="%(levelname)s: %(message)s", stream=sys.stderr, force=True
    )
    # libraries log their own failures, which reach the user as one InputError line instead
    for name in ("laspy", "numba", "matplotlib", "pye57"):
        logging.getLogger(name).setLevel(logging.DEBUG if verbose else logging.CRITICAL)
    for name in ("distributed", "dask"):
        logging.getLogger(name).setLevel(logging.DEBUG if verbose else logging.ERROR)


def fail(exc: NdtError, prog: str) -> typer.Exit:
    """Print the one-line error and return the exit to raise."""
    typer.echo(f"{prog}: error: {exc}", err=True)
    return typer.Exit(exc.exit_code)


@contextlib.contextmanager
def user_errors(prog: str, debug: bool, interrupted: str = "interrupted") -> Iterator[None]:
    """Turn user errors and Ctrl-C into one line on stderr and the documented exit code."""
    try:
        yield
    except KeyboardInterrupt:
        raise fail(UserInterruptError(interrupted), prog) from None
    except NdtError as exc:
        if debug:
            raise
        raise fail(exc, prog) from None
