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
    ControlOpt,
    CrsOpt,
    DebugOpt,
    InitPosesOpt,
    InitSigmaOpt,
    JobsOpt,
    JsonOpt,
    NeighboursOpt,
    OneLineCommand,
    PairsOpt,
    PrintConfigOpt,
    QuietOpt,
    RadiusOpt,
    VerboseOpt,
    VersionOpt,
    check_out,
    command_line,
    console,
    load_config,
    new_app,
    setup_logging,
    stop_on_sigterm,
    user_errors,
)
from ndt_cli.errors import EXIT_REGISTRATION
from ndt_cli.pipeline.workers import ExecutorKind

if TYPE_CHECKING:
    from ndt_cli.config import Config
    from ndt_cli.pipeline.inputs import ChainInputs
    from ndt_cli.pipeline.result import ChainResult

chain_app = new_app()

_HELP = "\n\n".join(
    [
        "Register a campaign of scans as a network of links and adjust it into one frame.",
        "The scans may come in any order: the links are found, not assumed. Each scan is "
        "matched coarsely against the scans next to it in the natural order of the names "
        "(a hint), and against every scan when those do not fit; once scans are placed, each "
        "is registered to its --neighbours nearest scans within --radius, and to the pairs of "
        "--pairs. The network is adjusted globally: a link that disagrees with the others is "
        "rejected, and every scan gets a status (ok, suspect, unposed) and a pose with its "
        "uncertainty. The first scan (or --anchor) defines the world frame; poses.txt holds "
        "T_world_scan of the ok scans. --neighbours 1 --no-adjust is the classic chain in the "
        "order of the names. --control gives stations of known coordinates (GNSS, a survey): "
        "the world is then their coordinate system (--crs), and a station that disagrees "
        "with the network is rejected and reported.",
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
    jobs: JobsOpt = None,
    resume: Annotated[
        bool,
        typer.Option(
            "--resume", help="Reuse finished links whose inputs and config are unchanged."
        ),
    ] = False,
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Replace a result in --out that shares no scan with this campaign (another "
            "campaign's); without it that is refused.",
        ),
    ] = False,
    anchor: Annotated[
        str, typer.Option(help="The scan that defines the world: its index or its name.")
    ] = "0",
    executor: Annotated[
        ExecutorKind, typer.Option(help="local (processes here) or dask (a Dask cluster).")
    ] = ExecutorKind.LOCAL,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Dask scheduler address, tcp://HOST:PORT.", show_default="a LocalCluster"
        ),
    ] = None,
    neighbours: NeighboursOpt = 4,
    adjust: Annotated[
        bool,
        typer.Option(
            "--adjust/--no-adjust",
            help="Adjust the network globally and verify every link by the others.",
        ),
    ] = True,
    radius: RadiusOpt = None,
    pairs: PairsOpt = None,
    init_poses: InitPosesOpt = None,
    init_sigma: InitSigmaOpt = "1,5",
    control: ControlOpt = None,
    crs: CrsOpt = None,
    print_config: PrintConfigOpt = False,
    json_out: JsonOpt = False,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
    version: VersionOpt = None,
) -> None:
    setup_logging(quiet or json_out, verbose)
    stop_on_sigterm()
    opts = _Options(out, jobs, resume, executor, scheduler, not (quiet or json_out))
    with user_errors("ndt-chain", debug, _RESUME_HINT):
        from ndt_cli.io.outlock import output_lock
        from ndt_cli.pipeline.inputs import chain_inputs, refuse_another_campaign

        cfg = load_config(config, print_config)
        _check(opts)
        guesses = {"init_poses": init_poses, "init_sigma": init_sigma}
        network = {"neighbours": neighbours, "adjust": adjust, "radius": radius, "pairs": pairs}
        inputs = chain_inputs(
            scans or [], anchor=anchor, control=control, crs=crs, **network, **guesses
        )
        check_out(out, *inputs.paths, pairs, config, control, init_poses)
        with output_lock(out, "ndt-chain"):
            if not overwrite:
                refuse_another_campaign(out, inputs.paths)
            result, runtime = _run(inputs, cfg, opts)
    _show(result, runtime, out, json_out, quiet)
    if not result.ok:
        raise typer.Exit(EXIT_REGISTRATION)


@dataclass(frozen=True)
class _Options:
    """How the chain runs (the command's options)."""

    out: Path
    jobs: int | None
    resume: bool
    executor: ExecutorKind
    scheduler: str | None
    progress: bool


def _check(opts: _Options) -> None:
    from ndt_cli.errors import ConfigError

    if opts.jobs is not None and opts.jobs < 1:
        raise ConfigError("--jobs must be >= 1")
    if opts.scheduler is not None and opts.executor is not ExecutorKind.DASK:
        raise ConfigError("--scheduler needs --executor dask")


def _run(inputs: ChainInputs, cfg: Config, opts: _Options) -> tuple[ChainResult, float]:
    """Run the chain with a progress display and publish its outputs; (result, seconds)."""
    import time

    from ndt_cli.cli.progress import ChainProgress
    from ndt_cli.pipeline.chain import run_chain
    from ndt_cli.pipeline.executors import make_executor
    from ndt_cli.report.chain_outputs import write_chain_outputs
    from ndt_cli.report.reasons import with_named_reasons

    t0 = time.perf_counter()
    pool = make_executor(opts.executor, opts.jobs, opts.scheduler)
    try:  # closed whatever stops the run (run_chain closes it too)
        pool.start()  # before this process starts threads of its own
        with ChainProgress(inputs.names, enabled=opts.progress) as progress:
            result = run_chain(
                inputs.paths,
                cfg,
                opts.out,
                executor=pool,
                resume=opts.resume,
                anchor=inputs.anchor,
                network=inputs.network,
                on_progress=progress.link_done,
            )
            progress.stage("writing the outputs")
            runtime = time.perf_counter() - t0
            result = with_named_reasons(result)
            write_chain_outputs(opts.out, result, cfg, runtime, command_line())
    finally:
        pool.close()
    return result, runtime


def _show(result: ChainResult, runtime: float, out: Path, json_out: bool, quiet: bool) -> None:
    if json_out:
        from ndt_cli.io.serialize import to_json
        from ndt_cli.report.chain_outputs import pose_records, summary

        record = {**summary(result, runtime), "poses": pose_records(result)}
        typer.echo(to_json(record), nl=False)
    elif not quiet:
        from ndt_cli.report.console import print_chain_summary

        print_chain_summary(result, console())
        typer.echo(f"written to {out}/")
