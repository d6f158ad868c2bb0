"""``ndt-eval``: accuracy of results against reference poses."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ndt_cli.cli.common import DebugOpt, new_app, setup_logging, user_errors

eval_app = new_app()


@eval_app.command(no_args_is_help=True)
def evaluate_cmd(
    result_dir: Annotated[Path, typer.Argument(help="Output folder of ndt-chain or ndt-register.")],
    gt: Annotated[
        Path,
        typer.Option(
            help="Reference: 'name' + 16 numbers (T_world_scan) or 'target source' + "
            "16 numbers (T_target_source) per line."
        ),
    ],
    json_out: Annotated[bool, typer.Option("--json", help="Print the evaluation as JSON.")] = False,
    debug: DebugOpt = False,
) -> None:
    """Rotation (deg) and translation (m) error of every link against a reference, success rates
    at 2 deg / 10 cm and 0.1 deg / 2 cm, and the end-of-chain drift. Writes eval.csv and
    eval.json into RESULT_DIR."""
    setup_logging(json_out, False)
    with user_errors("ndt-eval", debug):
        from ndt_cli.analysis.accuracy import compare_with_reference
        from ndt_cli.io import atomic
        from ndt_cli.io.serialize import csv_text, to_json

        ev = compare_with_reference(result_dir, gt)
        columns = ("target", "source", "rotation_error_deg", "translation_error_m")
        atomic.write_text(result_dir / "eval.csv", csv_text(ev.links, columns))
        atomic.write_text(result_dir / "eval.json", to_json(ev.to_dict()))
    if json_out:
        typer.echo(to_json(ev.to_dict()), nl=False)
        return
    from rich.console import Console

    from ndt_cli.report.console import print_evaluation

    print_evaluation(ev, Console())
