"""Command-line entry points. They only parse options and call the library.

Exit codes: 0 success, 1 registration failed (no overlap, not converged), 2 bad input or config.
Heavy modules are imported inside the commands so that ``--help`` stays fast.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Annotated

import typer

from ndt_cli.errors import EXIT_INPUT, EXIT_REGISTRATION, NdtError

register_app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)

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


def _setup_logging(quiet: bool, verbose: bool) -> None:
    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    logging.basicConfig(
        level=level, format="%(levelname)s: %(message)s", stream=sys.stderr, force=True
    )


def _fail(exc: NdtError, prog: str) -> typer.Exit:
    typer.echo(f"{prog}: error: {exc}", err=True)
    return typer.Exit(exc.exit_code)


@register_app.command(help=_REGISTER_HELP, no_args_is_help=True)
def register(
    target: Annotated[Path, typer.Argument(help="Fixed scan (its frame is the result's frame).")],
    source: Annotated[Path, typer.Argument(help="Moving scan.")],
    config: Annotated[Path | None, typer.Option("--config", "-c", help="YAML config file.")] = None,
    init: Annotated[
        Path | None, typer.Option(help="Initial guess of T_target_source: a 4x4 text file.")
    ] = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("ndt_results"),
    json_out: Annotated[
        bool, typer.Option("--json", help="Print the result as JSON on stdout.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print errors only.")] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="More log messages.")] = False,
    debug: Annotated[bool, typer.Option(help="Show tracebacks of errors.")] = False,
) -> None:
    _setup_logging(quiet or json_out, verbose)
    try:
        from ndt_cli import config as config_mod
        from ndt_cli import register as run
        from ndt_cli import report
        from ndt_cli.transforms import read_matrix

        cfg = config_mod.load(config)
        T_init = read_matrix(init) if init is not None else None
        result = run(target, source, cfg, init=T_init)
        report.write_register_outputs(out, result, cfg)
    except NdtError as exc:
        if debug:
            raise
        raise _fail(exc, "ndt-register") from None
    if json_out:
        typer.echo(report.to_json(result.to_dict()), nl=False)
    elif not quiet:
        from rich.console import Console

        report.print_summary(result, Console())
        typer.echo(f"written to {out}/")
    if not result.ok:
        reasons = "; ".join(result.warnings)
        typer.echo(
            f"ndt-register: registration {result.status}{': ' + reasons if reasons else ''}",
            err=True,
        )
        raise typer.Exit(EXIT_REGISTRATION)


__all__ = ["EXIT_INPUT", "EXIT_REGISTRATION", "register_app"]
