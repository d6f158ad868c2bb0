"""``ndt-analyze``: the paper's experiments on the user's own scans."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from ndt_cli.cli.common import ConfigOpt, DebugOpt, new_app, setup_logging, user_errors

analyze_app = new_app(
    no_args_is_help=True,
    help="The paper's experiments on your own scans: score profiles, convergence basin and "
    "optimiser traces. Each writes a CSV (every plotted number, units in the column names) and, "
    "with matplotlib, a PNG into --out.",
)
AtOpt = Annotated[
    Path | None,
    typer.Option("--at", help="Aligned T_target_source (4x4 text); default: register first."),
]
AnalyzeOut = Annotated[Path, typer.Option("--out", "-o", help="Output folder.")]


def _analysis(target: Path, source: Path, config: Path | None, at: Path | None) -> tuple:
    from ndt_cli.analysis.experiments import Pair
    from ndt_cli.config import load
    from ndt_cli.io.matrices import read_matrix
    from ndt_cli.ndt.prepare import load_and_prepare

    cfg = load(config)
    T = read_matrix(at) if at is not None else None
    pair = Pair.make(load_and_prepare(target, cfg), load_and_prepare(source, cfg), cfg, T)
    return cfg, pair


def _write_csv(path: Path, rows: list[dict]) -> None:
    from ndt_cli.io import atomic
    from ndt_cli.io.serialize import csv_text

    atomic.write_text(path, csv_text(rows, tuple(rows[0]) if rows else ()))
    typer.echo(f"wrote {path}")


def _run_analysis(fn: Callable[[], None], prog: str, debug: bool) -> None:
    setup_logging(False, False)
    with user_errors(prog, debug):
        fn()


@analyze_app.command("score-profile")
def score_profile(
    target: Annotated[Path, typer.Argument(help="Fixed scan.")],
    source: Annotated[Path, typer.Argument(help="Moving scan.")],
    rotate: Annotated[
        bool, typer.Option(help="Rotate through -180..180 deg (figs. 3, 11).")
    ] = True,
    translate: Annotated[bool, typer.Option(help="Shift over an x-y grid (figs. 4, 12).")] = False,
    cell: Annotated[float, typer.Option(help="Cell size (m).")] = 5.0,
    step_deg: Annotated[float, typer.Option(help="Rotation step (deg).")] = 2.0,
    x_range: Annotated[tuple[float, float], typer.Option(help="Shift range in x (m).")] = (
        -100.0,
        100.0,
    ),
    y_range: Annotated[tuple[float, float], typer.Option(help="Shift range in y (m).")] = (
        -30.0,
        40.0,
    ),
    step: Annotated[float, typer.Option(help="Shift grid step (m).")] = 2.0,
    config: ConfigOpt = None,
    at: AtOpt = None,
    out: AnalyzeOut = Path("ndt_analysis"),
    debug: DebugOpt = False,
) -> None:
    """Score of the aligned pair as the source is rotated or shifted, for 1..k slices."""

    def run() -> None:
        from ndt_cli.analysis import experiments as analyze
        from ndt_cli.report import plots

        cfg, pair = _analysis(target, source, config, at)
        if rotate:
            rows = analyze.rotation_profile(pair, cfg, cell, step_deg)
            _write_csv(out / "score_rotation.csv", rows)
            plots.rotation_plot(rows, out / "score_rotation.png", cell)
        if translate:
            rows = analyze.translation_profile(pair, cfg, cell, x_range, y_range, step)
            _write_csv(out / "score_translation.csv", rows)
            plots.translation_plot(rows, out / "score_translation.png", cell)

    _run_analysis(run, "ndt-analyze", debug)


@analyze_app.command("basin")
def basin_cmd(
    target: Annotated[Path, typer.Argument(help="Fixed scan.")],
    source: Annotated[Path, typer.Argument(help="Moving scan.")],
    max_translation: Annotated[float, typer.Option(help="Largest start shift (m).")] = 30.0,
    translation_step: Annotated[float, typer.Option(help="Start shift grid step (m).")] = 10.0,
    max_yaw: Annotated[float, typer.Option(help="Largest start rotation (deg).")] = 30.0,
    yaw_step: Annotated[float, typer.Option(help="Start rotation step (deg).")] = 15.0,
    jobs: Annotated[int | None, typer.Option("--jobs", "-j", help="Processes.")] = None,
    config: ConfigOpt = None,
    at: AtOpt = None,
    out: AnalyzeOut = Path("ndt_analysis"),
    debug: DebugOpt = False,
) -> None:
    """Register from many start offsets (no search) and record where each ends (fig. 17):
    one slice vs all slices, a single start per level vs restarts from +-1/2 and +-1 cell."""

    def run() -> None:
        from ndt_cli.analysis import experiments as analyze
        from ndt_cli.report import plots

        cfg, pair = _analysis(target, source, config, at)
        offsets = analyze.basin_offsets(max_translation, translation_step, max_yaw, yaw_step)
        rows = analyze.basin(pair, cfg, offsets, jobs=jobs)
        rates = analyze.success_rates(rows, max(translation_step, 1.0))
        _write_csv(out / "basin.csv", rows)
        _write_csv(out / "basin_success.csv", rates)
        plots.basin_plot(rows, rates, out / "basin.png")

    _run_analysis(run, "ndt-analyze", debug)


@analyze_app.command("optimizers")
def optimizers_cmd(
    target: Annotated[Path, typer.Argument(help="Fixed scan.")],
    source: Annotated[Path, typer.Argument(help="Moving scan.")],
    start: Annotated[
        tuple[float, float, float],
        typer.Option(help="Start offset from the aligned pose: dx (m), dy (m), dyaw (deg)."),
    ] = (3.0, -2.0, 10.0),
    config: ConfigOpt = None,
    at: AtOpt = None,
    out: AnalyzeOut = Path("ndt_analysis"),
    debug: DebugOpt = False,
) -> None:
    """Score and pose per iteration for newton, lm_fixed and lm (figs. 14-16). Newton runs the
    config's cell schedule; as in the paper, the Levenberg-Marquardt variants start one level
    finer."""

    def run() -> None:
        from ndt_cli.analysis import experiments as analyze
        from ndt_cli.report import plots

        cfg, pair = _analysis(target, source, config, at)
        cells = cfg.grid.cell_sizes
        lm_cells = cells[1:] if len(cells) > 1 else cells
        schedules = {"newton": cells, "lm_fixed": lm_cells, "lm": lm_cells}
        rows = analyze.optimizer_traces(pair, cfg, start, schedules)
        _write_csv(out / "optimizers.csv", rows)
        plots.optimizer_plot(rows, out / "optimizers.png")

    _run_analysis(run, "ndt-analyze", debug)
