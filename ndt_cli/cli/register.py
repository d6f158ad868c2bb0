"""``ndt-register``: register one scan onto another."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

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

register_app = new_app()

_REGISTER_HELP = "\n\n".join(
    [
        "Register SOURCE onto TARGET with multi-slice 2D NDT; no initial guess is needed.",
        "TARGET stays fixed and SOURCE is moved: the result T_target_source (4x4, written to "
        "T_target_source.txt) maps source points into the target frame, p_target = T @ p_source.",
        "Formats: PLY, LAS, LAZ, PCD, xyz/txt/csv (first three columns are x y z, metres). "
        "Exit codes: 0 ok, 1 registration failed (no overlap, not converged), "
        "2 bad input or config.",
        "Examples:",
        "  ndt-register scan_00.laz scan_01.laz --out results/",
        "  ndt-register a.ply b.ply --config configs/default.yaml --json > result.json",
    ]
)


@register_app.command(help=_REGISTER_HELP, no_args_is_help=True)
def register(
    target: Annotated[Path, typer.Argument(help="Fixed scan (its frame is the result's frame).")],
    source: Annotated[Path, typer.Argument(help="Moving scan.")],
    config: ConfigOpt = None,
    init: Annotated[
        Path | None, typer.Option(help="Initial guess of T_target_source: a 4x4 text file.")
    ] = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("ndt_results"),
    json_out: Annotated[
        bool, typer.Option("--json", help="Print the result as JSON on stdout.")
    ] = False,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
) -> None:
    setup_logging(quiet or json_out, verbose)
    with user_errors("ndt-register", debug):
        from ndt_cli.config import load
        from ndt_cli.io.matrices import read_matrix
        from ndt_cli.io.serialize import to_json
        from ndt_cli.ndt.register import register as run
        from ndt_cli.report.console import print_summary
        from ndt_cli.report.register_outputs import write_register_outputs

        cfg = load(config)
        T_init = read_matrix(init) if init is not None else None
        result = run(target, source, cfg, init=T_init)
        write_register_outputs(out, result, cfg)
    if json_out:
        typer.echo(to_json(result.to_dict()), nl=False)
    elif not quiet:
        from rich.console import Console

        print_summary(result, Console())
        typer.echo(f"written to {out}/")
    if not result.ok:
        reasons = "; ".join(result.warnings)
        typer.echo(
            f"ndt-register: registration {result.status.value}{': ' + reasons if reasons else ''}",
            err=True,
        )
        raise typer.Exit(EXIT_REGISTRATION)
