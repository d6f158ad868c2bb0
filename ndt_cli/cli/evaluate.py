"""``ndt-eval``: accuracy of results against reference poses."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ndt_cli.cli.common import (
    DebugOpt,
    JsonOpt,
    OneLineCommand,
    QuietOpt,
    ResultDirArg,
    VersionOpt,
    check_out,
    console,
    new_app,
    setup_logging,
    user_errors,
)

eval_app = new_app()

_HELP = "\n\n".join(
    [
        "Errors of an ndt-chain or ndt-register result against reference poses: per link its "
        "T_target_source, per scan its pose relative to the anchor (so that any world frame "
        "compares), as rotation (degrees) and translation (printed in centimetres; metres in "
        "eval.csv, eval_scans.csv and the JSON). Success rates at 2 deg / 10 cm and 0.1 deg / "
        "2 cm judge the links the network kept (confirmed, used) and every scan of the "
        "reference in the result: a scan without an ok pose in the anchor's frame (unposed, "
        "suspect, another cluster) fails. The reference's scans the result lacks are named; "
        "the end-of-chain drift follows. The result folder is only read; --out writes "
        "eval.csv, eval_scans.csv and eval.json into a folder of their own.",
        "Exit codes: 0 success; 2 bad input (no result folder, a reference that names no scan "
        "of the result, a bad reference line) or an unwritable --out.",
        "Example:\n\n  ndt-eval street/ --gt poses_T_world_scan.txt --out street_eval/",
    ]
)


@eval_app.command(help=_HELP, cls=OneLineCommand)
def evaluate_cmd(
    result_dir: ResultDirArg = None,
    gt: Annotated[
        Path | None,
        typer.Option(
            help="Reference: 'name' + 16 numbers (T_world_scan) or 'target source' + "
            "16 numbers (T_target_source) per line."
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "--out", "-o", help="Write eval.csv, eval_scans.csv and eval.json into this folder."
        ),
    ] = None,
    json_out: JsonOpt = False,
    quiet: QuietOpt = False,
    debug: DebugOpt = False,
    version: VersionOpt = None,
) -> None:
    setup_logging(quiet or json_out, False)
    with user_errors("ndt-eval", debug):
        from ndt_cli.analysis.accuracy import compare_with_reference
        from ndt_cli.errors import InputError

        if result_dir is None or gt is None:
            raise InputError("give RESULT_DIR and --gt POSES (see ndt-eval --help)")
        if out is not None:
            check_out(out, result_dir, gt)
        ev = compare_with_reference(result_dir, gt)
        if out is not None:
            _publish(ev, out)
    if json_out:
        from ndt_cli.io.serialize import to_json

        typer.echo(to_json(ev.to_dict()), nl=False)
    elif not quiet:
        from ndt_cli.report.console import print_evaluation

        print_evaluation(ev, console())


def _publish(ev: object, out: Path) -> None:
    from ndt_cli.io.outdir import publish
    from ndt_cli.io.serialize import csv_text, to_json

    columns = ["target", "source", "rotation_error_deg", "translation_error_m"]
    if any("network" in row for row in ev.links):  # links of a chain carry the network's verdict
        columns.append("network")
    scans = ["scan", "status", "rotation_error_deg", "translation_error_m"]
    publish(
        out,
        {
            "eval.csv": csv_text(ev.links, columns),
            "eval_scans.csv": csv_text(ev.scans, scans),
            "eval.json": to_json(ev.to_dict()),
        },
    )
