"""``ndt-analyze``: the paper's experiments on the user's own scans."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from ndt_cli.cli.common import (
    ConfigOpt,
    DebugOpt,
    OneLineCommand,
    VersionOpt,
    check_out,
    new_app,
    setup_logging,
    user_errors,
)

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
Files = dict[str, str | bytes]


@analyze_app.callback()
def _group(version: VersionOpt = None) -> None:
    """The paper's experiments on your own scans."""


def _analysis(target: Path, source: Path, config: str | None, at: Path | None, out: Path) -> tuple:
    """The config and the prepared, aligned pair, after checking the output folder."""
    from ndt_cli.analysis.experiments import Pair
    from ndt_cli.config import load
    from ndt_cli.io.matrices import read_matrix
    from ndt_cli.ndt.prepare import load_and_prepare

    check_out(out, target, source, at, config)
    cfg = load(config)
    T = read_matrix(at) if at is not None else None
    pair = Pair.make(load_and_prepare(target, cfg), load_and_prepare(source, cfg), cfg, T)
    return cfg, pair


MAX_SHIFT = 1e4  # m: the largest shift or range an experiment takes
MAX_POSES = 200_000  # poses an experiment evaluates at most


def _within(option: str, value: float, lo: float, hi: float, above: bool = False) -> None:
    """Raise a ConfigError unless ``lo <= value <= hi`` (``lo < value`` with ``above``)."""
    from ndt_cli.errors import ConfigError

    low_ok = value > lo if above else value >= lo
    if not (low_ok and value <= hi):  # NaN fails both
        side = "above" if above else "at least"
        raise ConfigError(f"--{option} must be {side} {lo:g} and at most {hi:g}, got {value}")


def _grid(option: str, span: tuple[float, float], step: float, step_option: str) -> int:
    """The number of values from ``span[0]`` to ``span[1]`` in ``step``, checked."""
    from ndt_cli.errors import ConfigError

    for v in span:
        _within(option, v, -MAX_SHIFT, MAX_SHIFT)
    if not span[0] <= span[1]:
        raise ConfigError(f"--{option} must go from low to high, got {span[0]} {span[1]}")
    _within(step_option, step, 0.0, MAX_SHIFT, above=True)
    return int((span[1] - span[0]) / step) + 1


def _at_most(poses: int) -> None:
    from ndt_cli.errors import ConfigError

    if poses > MAX_POSES:
        raise ConfigError(f"the options ask for {poses} poses, at most {MAX_POSES}: larger steps")


def _table(rows: list[dict]) -> str:
    from ndt_cli.io.serialize import csv_text

    return csv_text(rows, tuple(rows[0]) if rows else ())


def _add(files: Files, name: str, content: str | bytes | None) -> None:
    if content is not None:
        files[name] = content


def _run_analysis(fn: Callable[[], Files], out: Path, debug: bool) -> None:
    """Run an experiment and publish its files together into ``out`` (the files of the other
    experiments already there are kept)."""
    setup_logging(False, False)
    with user_errors("ndt-analyze", debug):
        from ndt_cli.io.outdir import publish

        files = fn()
        publish(out, files, keep_others=True)
    for name in files:
        typer.echo(f"wrote {out / name}")


@analyze_app.command("score-profile", cls=OneLineCommand)
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

    def run() -> Files:
        from ndt_cli.analysis import experiments as analyze
        from ndt_cli.report import plots

        _within("cell", cell, 0.1, 100.0)
        _within("step-deg", step_deg, 0.0, 180.0, above=True)
        if translate:
            nx = _grid("x-range", x_range, step, "step")
            _at_most(nx * _grid("y-range", y_range, step, "step"))
        cfg, pair = _analysis(target, source, config, at, out)
        files: Files = {}
        if rotate:
            rows = analyze.rotation_profile(pair, cfg, cell, step_deg)
            files["score_rotation.csv"] = _table(rows)
            _add(files, "score_rotation.png", plots.rotation_plot(rows, cell))
        if translate:
            rows = analyze.translation_profile(pair, cfg, cell, x_range, y_range, step)
            files["score_translation.csv"] = _table(rows)
            _add(files, "score_translation.png", plots.translation_plot(rows, cell))
        return files

    _run_analysis(run, out, debug)


@analyze_app.command("basin", cls=OneLineCommand)
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

    def run() -> Files:
        from ndt_cli.analysis import experiments as analyze
        from ndt_cli.report import plots

        n = _grid("max-translation", (0.0, max_translation), translation_step, "translation-step")
        _within("max-yaw", max_yaw, 0.0, 180.0)
        _within("yaw-step", yaw_step, 0.0, 360.0, above=True)
        _at_most((2 * n - 1) ** 2 * (2 * int(max_yaw / yaw_step) + 1))
        if jobs is not None:
            _within("jobs", jobs, 1, 1e9)
        cfg, pair = _analysis(target, source, config, at, out)
        offsets = analyze.basin_offsets(max_translation, translation_step, max_yaw, yaw_step)
        rows = analyze.basin(pair, cfg, offsets, jobs=jobs)
        rates = analyze.success_rates(rows, max(translation_step, 1.0))
        files: Files = {"basin.csv": _table(rows), "basin_success.csv": _table(rates)}
        _add(files, "basin.png", plots.basin_plot(rows, rates))
        return files

    _run_analysis(run, out, debug)


@analyze_app.command("optimizers", cls=OneLineCommand)
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

    def run() -> Files:
        from ndt_cli.analysis import experiments as analyze
        from ndt_cli.report import plots

        limits = (("start dx", MAX_SHIFT), ("start dy", MAX_SHIFT), ("start dyaw", 360.0))
        for (option, limit), value in zip(limits, start, strict=True):
            _within(option, value, -limit, limit)
        cfg, pair = _analysis(target, source, config, at, out)
        cells = cfg.grid.cell_sizes
        lm_cells = cells[1:] if len(cells) > 1 else cells
        schedules = {"newton": cells, "lm_fixed": lm_cells, "lm": lm_cells}
        rows = analyze.optimizer_traces(pair, cfg, start, schedules)
        files: Files = {"optimizers.csv": _table(rows)}
        _add(files, "optimizers.png", plots.optimizer_plot(rows))
        return files

    _run_analysis(run, out, debug)
