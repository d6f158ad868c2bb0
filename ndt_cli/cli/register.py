"""``ndt-register``: register one scan onto another."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ndt_cli.cli.common import (
    EXIT_CODES,
    FORMATS,
    ConfigOpt,
    DebugOpt,
    InitSigmaOpt,
    JsonOpt,
    OneLineCommand,
    PrintConfigOpt,
    QuietOpt,
    VerboseOpt,
    VersionOpt,
    check_out,
    command_line,
    console,
    load_config,
    new_app,
    setup_logging,
    user_errors,
)
from ndt_cli.errors import EXIT_REGISTRATION, InputError

register_app = new_app()

_HELP = "\n\n".join(
    [
        "Register SOURCE onto TARGET with multi-slice 2D NDT; no initial guess is needed.",
        "TARGET stays fixed and SOURCE is moved: the result T_target_source (4x4, written to "
        "T_target_source.txt) maps source points into the target frame, p_target = T @ p_source.",
        FORMATS,
        EXIT_CODES,
        "Examples:\n\n"
        "  ndt-register scan_00.laz scan_01.laz --out results/\n\n"
        "  ndt-register a.ply b.ply --config paper --json > result.json\n\n"
        "  ndt-register --print-config --config 3dtk > my.yaml",
    ]
)


@register_app.command(help=_HELP, cls=OneLineCommand)
def register(
    target: Annotated[
        Path | None, typer.Argument(help="Fixed scan (its frame is the result's frame).")
    ] = None,
    source: Annotated[Path | None, typer.Argument(help="Moving scan.")] = None,
    config: ConfigOpt = None,
    init: Annotated[
        Path | None, typer.Option(help="Initial guess of T_target_source: a 4x4 text file.")
    ] = None,
    init_sigma: InitSigmaOpt = "1,5",
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("ndt_results"),
    print_config: PrintConfigOpt = False,
    json_out: JsonOpt = False,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
    version: VersionOpt = None,
) -> None:
    setup_logging(quiet or json_out, verbose)
    with user_errors("ndt-register", debug):
        cfg = load_config(config, print_config)
        if target is None or source is None:
            raise InputError("give TARGET and SOURCE (see ndt-register --help)")
        from ndt_cli.pipeline.guesses import parse_sigma

        sigma = parse_sigma(init_sigma)
        check_out(out, target, source, init, config)
        result = _run(target, source, cfg, init, sigma, out)
    _show(result, out, json_out, quiet)
    if not result.ok:
        reasons = "; ".join(result.warnings)
        typer.echo(
            f"ndt-register: registration {result.status.value}{': ' + reasons if reasons else ''}",
            err=True,
        )
        raise typer.Exit(EXIT_REGISTRATION)


def _run(
    target: Path,
    source: Path,
    cfg: object,
    init: Path | None,
    sigma: tuple[float, float],
    out: Path,
) -> object:
    """Check every input before the work (the output is checked), register, publish the
    outputs."""
    from ndt_cli.io.matrices import read_matrix
    from ndt_cli.io.points import check_readable

    check_readable(target)
    check_readable(source)
    T_init = read_matrix(init) if init is not None else None

    from ndt_cli.ndt.register import Guess
    from ndt_cli.ndt.register import register as run  # the kernels: only once inputs are good
    from ndt_cli.pipeline.scans import hash_ahead
    from ndt_cli.report.register_outputs import write_register_outputs

    guess = None if T_init is None else Guess(T_init, *sigma)
    hashing = hash_ahead([target, source])  # the outputs name the files by their SHA-256
    result = run(target, source, cfg, init=guess)
    hashing.join()
    write_register_outputs(out, result, cfg, command_line())
    return result


def _show(result: object, out: Path, json_out: bool, quiet: bool) -> None:
    if json_out:
        from ndt_cli.io.serialize import to_json

        typer.echo(to_json(result.to_dict()), nl=False)
    elif not quiet:
        from ndt_cli.report.console import print_summary

        print_summary(result, console())
        typer.echo(f"written to {out}/")
