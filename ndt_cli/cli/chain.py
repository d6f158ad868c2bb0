"""``ndt-chain``: register a sequence of scans and chain them into one frame."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ndt_cli.cli.common import (
    EXIT_CODES,
    FORMATS,
    ConfigOpt,
    DebugOpt,
    JsonOpt,
    OneLineCommand,
    PrintConfigOpt,
    QuietOpt,
    VerboseOpt,
    VersionOpt,
    check_out,
    console,
    load_config,
    new_app,
    setup_logging,
    user_errors,
)
from ndt_cli.errors import EXIT_REGISTRATION
from ndt_cli.pipeline.workers import ExecutorKind

if TYPE_CHECKING:
    from ndt_cli.config import Config
    from ndt_cli.pipeline.chain import ChainResult, NetworkOptions

chain_app = new_app()

_HELP = "\n\n".join(
    [
        "Register a campaign of scans as a network of links and adjust it into one frame.",
        "Scans are sorted in natural order of their names (scan_2 before scan_10); each scan is "
        "registered to its --neighbours predecessors, to the pairs of --pairs, and to the scans "
        "a first adjustment puts within --loop-radius (loop closures). The network is adjusted "
        "globally: a link that disagrees with the others is rejected, and every scan gets a "
        "status (ok, suspect, unposed) and a pose with its uncertainty. The first scan (or "
        "--anchor K) defines the world frame; poses.txt holds T_world_scan of the ok scans. "
        "--neighbours 1 --no-adjust is the classic chain.",
        FORMATS,
        EXIT_CODES,
        "Examples:\n\n"
        "  ndt-chain scans/*.laz --out street/ --jobs 2\n\n"
        "  ndt-chain scans/*.laz --out street/ --resume   (after an interruption)",
    ]
)
_RESUME_HINT = "interrupted: finished links are kept; run again with --resume to continue"


@chain_app.command(help=_HELP, cls=OneLineCommand)
def chain(
    scans: Annotated[list[Path] | None, typer.Argument(help="Scan files (at least two).")] = None,
    config: ConfigOpt = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("ndt_chain"),
    jobs: Annotated[
        int | None,
        typer.Option("--jobs", "-j", help="Parallel processes.", show_default="all cores"),
    ] = None,
    resume: Annotated[
        bool,
        typer.Option(
            "--resume", help="Reuse finished links whose inputs and config are unchanged."
        ),
    ] = False,
    anchor: Annotated[int, typer.Option(help="Index of the scan that defines the world.")] = 0,
    executor: Annotated[
        ExecutorKind, typer.Option(help="local (processes here) or dask (a Dask cluster).")
    ] = ExecutorKind.LOCAL,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Dask scheduler address, tcp://HOST:PORT.", show_default="a LocalCluster"
        ),
    ] = None,
    neighbours: Annotated[
        int, typer.Option("--neighbours", "-k", help="Predecessors each scan is registered to.")
    ] = 2,
    adjust: Annotated[
        bool,
        typer.Option(
            "--adjust/--no-adjust",
            help="Adjust the network globally, verify every link by the others, close loops.",
        ),
    ] = True,
    loop_radius: Annotated[
        float | None,
        typer.Option(
            help="Register scans the network puts this close (m) as loop closures; 0: none.",
            show_default="2 x the median adjacent link",
        ),
    ] = None,
    pairs: Annotated[
        Path | None,
        typer.Option(help="CSV of target,source rows: more pairs to register (scan names)."),
    ] = None,
    print_config: PrintConfigOpt = False,
    json_out: JsonOpt = False,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
    version: VersionOpt = None,
) -> None:
    setup_logging(quiet or json_out, verbose)
    opts = _Options(out, jobs, resume, anchor, executor, scheduler, not (quiet or json_out))
    with user_errors("ndt-chain", debug, _RESUME_HINT):
        cfg = load_config(config, print_config)
        paths = _scans(scans or [], opts)
        net = _network(paths, neighbours, adjust, loop_radius, pairs)
        check_out(out)
        result, runtime = _run(paths, cfg, opts, net)
    _show(result, runtime, out, json_out, quiet)
    if not result.ok:
        raise typer.Exit(EXIT_REGISTRATION)


@dataclass(frozen=True)
class _Options:
    """How the chain runs (the command's options)."""

    out: Path
    jobs: int | None
    resume: bool
    anchor: int
    executor: ExecutorKind
    scheduler: str | None
    progress: bool


def _scans(scans: list[Path], opts: _Options) -> list[Path]:
    """The scans in chain order, after checking the options and that every scan can be read."""
    from ndt_cli.errors import ConfigError, InputError
    from ndt_cli.io.e57 import expand
    from ndt_cli.pipeline.scans import natural_sort

    paths = expand(natural_sort(scans))
    if len(paths) < 2:
        raise InputError("ndt-chain needs at least two scans")
    if not 0 <= opts.anchor < len(paths):
        raise ConfigError(f"--anchor {opts.anchor} is not a scan index (0..{len(paths) - 1})")
    if opts.jobs is not None and opts.jobs < 1:
        raise ConfigError("--jobs must be >= 1")
    if opts.scheduler is not None and opts.executor is not ExecutorKind.DASK:
        raise ConfigError("--scheduler needs --executor dask")
    return paths


def _network(
    paths: list[Path], neighbours: int, adjust: bool, radius: float | None, pairs: Path | None
) -> NetworkOptions:
    """The network's options, checked."""
    from ndt_cli.errors import ConfigError
    from ndt_cli.pipeline.chain import NetworkOptions
    from ndt_cli.pipeline.network import read_pairs
    from ndt_cli.pipeline.scans import scan_names

    if not 1 <= neighbours <= 10:
        raise ConfigError(f"--neighbours must be between 1 and 10, got {neighbours}")
    if radius is not None and not 0 <= radius <= 1e4:
        raise ConfigError(f"--loop-radius must be between 0 and 10000 m, got {radius}")
    user = tuple(read_pairs(pairs, scan_names(paths))) if pairs is not None else ()
    return NetworkOptions(neighbours, adjust, radius, user)


def _run(
    paths: list[Path], cfg: Config, opts: _Options, net: NetworkOptions
) -> tuple[ChainResult, float]:
    """Run the chain with a progress display and publish its outputs; (result, seconds)."""
    import time

    from ndt_cli.cli.progress import ChainProgress
    from ndt_cli.pipeline.chain import run_chain
    from ndt_cli.pipeline.executors import make_executor
    from ndt_cli.pipeline.scans import scan_names
    from ndt_cli.report.chain_outputs import write_chain_outputs

    t0 = time.perf_counter()
    pool = make_executor(opts.executor, opts.jobs, opts.scheduler)
    pool.start()  # before this process starts threads of its own
    names = tuple(scan_names(paths))
    total = len(paths) * net.neighbours - net.neighbours * (net.neighbours + 1) // 2
    with ChainProgress(names, max(total, 1) + len(net.pairs), enabled=opts.progress) as advance:
        result = run_chain(
            paths,
            cfg,
            opts.out,
            executor=pool,
            resume=opts.resume,
            anchor=opts.anchor,
            network=net,
            on_progress=advance,
        )
    runtime = time.perf_counter() - t0
    write_chain_outputs(opts.out, result, cfg, runtime)
    return result, runtime


def _show(result: ChainResult, runtime: float, out: Path, json_out: bool, quiet: bool) -> None:
    if json_out:
        from ndt_cli.io.serialize import to_json
        from ndt_cli.report.chain_outputs import summary

        typer.echo(to_json(summary(result, runtime)), nl=False)
    elif not quiet:
        from ndt_cli.report.console import print_chain_summary

        print_chain_summary(result, console())
        typer.echo(f"written to {out}/")
