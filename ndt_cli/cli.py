"""Command-line entry points. They only parse options and call the library.

Exit codes: 0 success, 1 registration failed (no overlap, not converged), 2 bad input or config.
Heavy modules are imported inside the commands so that ``--help`` stays fast.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated, Any

import typer

from ndt_cli.errors import EXIT_INPUT, EXIT_REGISTRATION, NdtError, UserInterruptError

register_app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)

# options shared by the commands
ConfigOpt = Annotated[Path | None, typer.Option("--config", "-c", help="YAML config file.")]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="Print errors only.")]
VerboseOpt = Annotated[bool, typer.Option("--verbose", "-v", help="More log messages.")]
DebugOpt = Annotated[bool, typer.Option(help="Show tracebacks of errors.")]

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
    # libraries log their own failures, which reach the user as one InputError line instead
    for name in ("laspy", "numba", "matplotlib", "pye57"):
        logging.getLogger(name).setLevel(logging.DEBUG if verbose else logging.CRITICAL)
    for name in ("distributed", "dask"):
        logging.getLogger(name).setLevel(logging.DEBUG if verbose else logging.ERROR)


def _fail(exc: NdtError, prog: str) -> typer.Exit:
    typer.echo(f"{prog}: error: {exc}", err=True)
    return typer.Exit(exc.exit_code)


@contextlib.contextmanager
def _user_errors(prog: str, debug: bool, interrupted: str = "interrupted") -> Iterator[None]:
    """Turn user errors and Ctrl-C into one line on stderr and the documented exit code."""
    try:
        yield
    except KeyboardInterrupt:
        raise _fail(UserInterruptError(interrupted), prog) from None
    except NdtError as exc:
        if debug:
            raise
        raise _fail(exc, prog) from None


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
    _setup_logging(quiet or json_out, verbose)
    with _user_errors("ndt-register", debug):
        from ndt_cli import config as config_mod
        from ndt_cli import register as run
        from ndt_cli import report
        from ndt_cli.transforms import read_matrix

        cfg = config_mod.load(config)
        T_init = read_matrix(init) if init is not None else None
        result = run(target, source, cfg, init=T_init)
        report.write_register_outputs(out, result, cfg)
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


chain_app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)

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
        str, typer.Option(help="local (processes here) or dask (a Dask cluster).")
    ] = "local",
    scheduler: Annotated[
        str | None,
        typer.Option(help="Dask scheduler address, tcp://HOST:PORT [default: a LocalCluster]."),
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
    debug: DebugOpt = False,
) -> None:
    _setup_logging(quiet or json_out, verbose)
    resume_hint = "interrupted: finished links are kept; run again with --resume to continue"
    with _user_errors("ndt-chain", debug, resume_hint):
        import time

        from ndt_cli import config as config_mod
        from ndt_cli import e57
        from ndt_cli.chain import natural_sort, run_chain
        from ndt_cli.chain_report import summary, write_chain_outputs, write_topview
        from ndt_cli.errors import ConfigError, InputError, OutputError

        cfg = config_mod.load(config)
        paths = e57.expand(natural_sort(scans))
        if len(paths) < 2:
            raise InputError("ndt-chain needs at least two scans")
        if not 0 <= anchor < len(paths):
            raise ConfigError(f"--anchor {anchor} is not a scan index (0..{len(paths) - 1})")
        if jobs is not None and jobs < 1:
            raise ConfigError("--jobs must be >= 1")
        if executor not in ("local", "dask"):
            raise ConfigError(f"--executor must be local or dask, got {executor!r}")
        if scheduler is not None and executor != "dask":
            raise ConfigError("--scheduler needs --executor dask")
        if out.exists() and not out.is_dir():
            raise OutputError("output path exists and is not a folder", out)
        t0 = time.perf_counter()
        with _Progress(len(paths) - 1, enabled=not (quiet or json_out)) as advance:
            result = run_chain(
                paths, cfg, out, jobs=jobs, resume=resume, anchor=anchor, on_progress=advance,
                executor=executor, scheduler=scheduler,
            )  # fmt: skip
        runtime = time.perf_counter() - t0
        write_chain_outputs(out, result, cfg, runtime)
        write_topview(out, result, cfg)
    if json_out:
        from ndt_cli.report import to_json

        typer.echo(to_json(summary(result, runtime)), nl=False)
    elif not quiet:
        from rich.console import Console

        from ndt_cli.chain_report import print_chain_summary

        print_chain_summary(result, Console())
        typer.echo(f"written to {out}/")
    if not result.ok:
        raise typer.Exit(EXIT_REGISTRATION)


def _log_link(link: Any) -> None:
    """At --verbose, one line per finished link with its per-level progress."""
    log = logging.getLogger("ndt_cli.chain")
    log.debug("link %s (%s): %s", link.index, link.status, link.levels or link.reason)


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


analyze_app = typer.Typer(
    add_completion=False,
    pretty_exceptions_enable=False,
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
    from ndt_cli import config as config_mod
    from ndt_cli.analyze import Pair
    from ndt_cli.prepare import load_and_prepare
    from ndt_cli.transforms import read_matrix

    cfg = config_mod.load(config)
    T = read_matrix(at) if at is not None else None
    pair = Pair.make(load_and_prepare(target, cfg), load_and_prepare(source, cfg), cfg, T)
    return cfg, pair


def _write_csv(path: Path, rows: list[dict]) -> None:
    from ndt_cli import atomic
    from ndt_cli.report import csv_text

    atomic.write_text(path, csv_text(rows, tuple(rows[0]) if rows else ()))
    typer.echo(f"wrote {path}")


def _run_analysis(fn: Callable[[], None], prog: str, debug: bool) -> None:
    _setup_logging(False, False)
    with _user_errors(prog, debug):
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
        from ndt_cli import analyze, plots

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
        from ndt_cli import analyze, plots

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
        from ndt_cli import analyze, plots

        cfg, pair = _analysis(target, source, config, at)
        cells = cfg.grid.cell_sizes
        lm_cells = cells[1:] if len(cells) > 1 else cells
        schedules = {"newton": cells, "lm_fixed": lm_cells, "lm": lm_cells}
        rows = analyze.optimizer_traces(pair, cfg, start, schedules)
        _write_csv(out / "optimizers.csv", rows)
        plots.optimizer_plot(rows, out / "optimizers.png")

    _run_analysis(run, "ndt-analyze", debug)


eval_app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


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
    _setup_logging(json_out, False)
    with _user_errors("ndt-eval", debug):
        from ndt_cli import atomic
        from ndt_cli.evaluate import evaluate
        from ndt_cli.report import csv_text, to_json

        ev = evaluate(result_dir, gt)
        columns = ("target", "source", "rotation_error_deg", "translation_error_m")
        atomic.write_text(result_dir / "eval.csv", csv_text(ev.links, columns))
        atomic.write_text(result_dir / "eval.json", to_json(ev.to_dict()))
    if json_out:
        typer.echo(to_json(ev.to_dict()), nl=False)
        return
    from rich.console import Console
    from rich.table import Table

    table = Table("target", "source", "rotation error (deg)", "translation error (cm)",
                  title="ndt-eval")  # fmt: skip
    for row in ev.links:
        table.add_row(row["target"], row["source"], f"{row['rotation_error_deg']:.4f}",
                      f"{100 * row['translation_error_m']:.2f}")  # fmt: skip
    console = Console()
    console.print(table)
    for s in ev.success:
        console.print(f"success at {s['max_rotation_deg']:g} deg / {100 * s['max_translation_m']:g}"
                      f" cm: {100 * s['success_rate']:.0f} %")  # fmt: skip
    if ev.drift:
        d = ev.drift
        console.print(
            f"end-of-chain drift ({d['to']} in the frame of {d['from']}): "
            f"{d['rotation_error_deg']:.4f} deg, {100 * d['translation_error_m']:.2f} cm"
        )
