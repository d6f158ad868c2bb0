"""``ndt-chain``: register a sequence of scans and chain them into one frame."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from ndt_cli.cli.common import (
    ConfigOpt,
    DebugOpt,
    QuietOpt,
    VerboseOpt,
    new_app,
    setup_logging,
    user_errors,
)
from ndt_cli.errors import EXIT_REGISTRATION
from ndt_cli.pipeline.executors import ExecutorKind

chain_app = new_app()

_CHAIN_HELP = "\n\n".join(
    [
        "Register a sequence of scans along a street and chain them into one frame.",
        "Scans are sorted in natural order of their names (scan_2 before scan_10); each scan is "
        "registered against the previous readable one. The first scan (or --anchor K) defines "
        "the world frame; poses.txt holds T_world_scan of every scan.",
        "Exit codes: 0 every link ok, 1 a link failed or is suspect (see pairs.csv), "
        "2 bad input or config.",
        "Examples:",
        "  ndt-chain scans/*.laz --out street/ --jobs 2",
        "  ndt-chain scans/*.laz --out street/ --resume   (after an interruption)",
    ]
)


@chain_app.command(help=_CHAIN_HELP, no_args_is_help=True)
def chain(
    scans: Annotated[list[Path], typer.Argument(help="Scan files (at least two).")],
    config: ConfigOpt = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("ndt_chain"),
    jobs: Annotated[
        int | None, typer.Option("--jobs", "-j", help="Parallel processes [default: cores].")
    ] = None,
    resume: Annotated[
        bool, typer.Option(help="Reuse finished links whose inputs and config are unchanged.")
    ] = False,
    anchor: Annotated[int, typer.Option(help="Index of the scan that defines the world.")] = 0,
    executor: Annotated[
        ExecutorKind, typer.Option(help="local (processes here) or dask (a Dask cluster).")
    ] = ExecutorKind.LOCAL,
    scheduler: Annotated[
        str | None,
        typer.Option(help="Dask scheduler address, tcp://HOST:PORT [default: a LocalCluster]."),
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
) -> None:
    setup_logging(quiet or json_out, verbose)
    resume_hint = "interrupted: finished links are kept; run again with --resume to continue"
    with user_errors("ndt-chain", debug, resume_hint):
        import time

        from ndt_cli.config import load
        from ndt_cli.errors import ConfigError, InputError, OutputError
        from ndt_cli.io.e57 import expand
        from ndt_cli.pipeline.chain import run_chain
        from ndt_cli.pipeline.executors import make_executor
        from ndt_cli.pipeline.scans import natural_sort
        from ndt_cli.report.chain_outputs import write_chain_outputs
        from ndt_cli.report.topview import write_topview

        cfg = load(config)
        paths = expand(natural_sort(scans))
        if len(paths) < 2:
            raise InputError("ndt-chain needs at least two scans")
        if not 0 <= anchor < len(paths):
            raise ConfigError(f"--anchor {anchor} is not a scan index (0..{len(paths) - 1})")
        if jobs is not None and jobs < 1:
            raise ConfigError("--jobs must be >= 1")
        if scheduler is not None and executor is not ExecutorKind.DASK:
            raise ConfigError("--scheduler needs --executor dask")
        if out.exists() and not out.is_dir():
            raise OutputError("output path exists and is not a folder", out)
        t0 = time.perf_counter()
        pool = make_executor(executor, jobs, scheduler)
        with _Progress(len(paths) - 1, enabled=not (quiet or json_out)) as advance:
            result = run_chain(
                paths, cfg, out, executor=pool, resume=resume, anchor=anchor, on_progress=advance
            )
        runtime = time.perf_counter() - t0
        write_chain_outputs(out, result, cfg, runtime)
        write_topview(out, result)
    if json_out:
        from ndt_cli.io.serialize import to_json
        from ndt_cli.report.chain_outputs import summary

        typer.echo(to_json(summary(result, runtime)), nl=False)
    elif not quiet:
        from rich.console import Console

        from ndt_cli.report.console import print_chain_summary

        print_chain_summary(result, Console())
        typer.echo(f"written to {out}/")
    if not result.ok:
        raise typer.Exit(EXIT_REGISTRATION)


def _log_link(link: Any) -> None:
    """At --verbose, one line per finished link with its per-level progress."""
    log = logging.getLogger("ndt_cli.pipeline.chain")
    log.debug("link %s (%s): %s", link.index, link.status, link.describe_levels() or link.reason)


class _Progress:
    """A rich progress bar over links, shown only on a terminal; yields the advance callback."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total = total
        self.enabled = enabled and sys.stdout.isatty()
        self.bar = None

    def __enter__(self):
        if not self.enabled:
            return _log_link
        from rich.progress import Progress

        self.bar = Progress()
        self.bar.start()
        task = self.bar.add_task("links", total=self.total)
        return lambda link: (self.bar.advance(task), _log_link(link))

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()
