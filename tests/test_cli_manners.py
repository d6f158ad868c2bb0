"""What a person at a terminal and a shell script expect of the commands: versions, help texts,
completion, config printing and selection, logs without a terminal, tables that are not cut."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import during_ctrl_c
from typer.testing import CliRunner

from ndt_cli import __version__
from ndt_cli.cli import analyze_app, chain_app, eval_app, register_app
from ndt_cli.config import Config, load
from ndt_cli.config.loading import PRESETS, preset_names
from ndt_cli.config.printing import commented_yaml
from ndt_cli.io.matrices import read_matrix

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
runner = CliRunner()
APPS = {
    "ndt-register": register_app,
    "ndt-chain": chain_app,
    "ndt-eval": eval_app,
    "ndt-analyze": analyze_app,
}
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}


@pytest.mark.parametrize("name", sorted(APPS))
@pytest.mark.parametrize("flag", ["--version", "-V"])
def test_every_command_tells_its_version(name, flag):
    res = runner.invoke(APPS[name], [flag], prog_name=name)
    assert res.exit_code == 0 and res.stdout.strip() == f"{name} {__version__}"


@pytest.mark.parametrize("name", sorted(APPS))
def test_help_shows_flags_as_flags_and_completion(name):
    res = runner.invoke(APPS[name], ["--help"], prog_name=name)
    assert res.exit_code == 0
    two_way = ("--no-rotate", "--no-adjust")  # true two-way switches
    text = res.stdout
    for name in two_way:
        text = text.replace(name, "")
    assert "<bool>" not in text and "--no-" not in text
    assert "--install-completion" in res.stdout and "-V, --version" in res.stdout


@pytest.mark.parametrize("name", ["ndt-register", "ndt-chain"])
def test_help_lists_every_exit_code_and_format(name):
    text = " ".join(runner.invoke(APPS[name], ["--help"], prog_name=name).stdout.split())
    for code in ("0 success", "1 a result is not trustworthy", "2 bad input", "130 stopped"):
        assert code in text
    for word in ("suspect", "degenerate", "not converged", "no overlap", "failed"):
        assert word in text
    for fmt in ("PLY", "LAS", "LAZ", "E57", "PCD", "xyz", "csv"):
        assert re.search(rf"\b{fmt}\b", text), fmt


def test_help_shows_the_defaults():
    text = " ".join(runner.invoke(chain_app, ["--help"]).stdout.split())
    assert "Parallel processes (at most one per core). [default: (all cores)]" in text
    assert "[default: ndt_chain]" in text and "[default: local]" in text


COMPLETE_IN_BASH = """
eval "$(ndt-register --show-completion)"
COMP_WORDS=(ndt-register --ou); COMP_CWORD=1
_ndt_register_completion ndt-register
echo "${COMPREPLY[@]}"
"""


def test_the_shell_completion_script_completes_options_in_bash():
    # --show-completion detects the calling shell: run it from a real bash, source the script
    # and ask it to complete "--ou" as bash would on a Tab
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    res = subprocess.run(["bash", "-c", COMPLETE_IN_BASH], capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["--out"], res.stdout


@pytest.mark.parametrize("name", ["ndt-register", "ndt-chain"])
@pytest.mark.parametrize("config", [None, "paper", "3dtk"])
def test_print_config_is_commented_yaml_that_loads_back(name, config, tmp_path):
    args = ["--print-config"] + ([] if config is None else ["--config", config])
    res = runner.invoke(APPS[name], args, prog_name=name)
    assert res.exit_code == 0, res.output
    printed = tmp_path / "printed.yaml"
    printed.write_text(res.stdout)
    assert load(printed) == load(config)  # the effective config, whole
    assert res.stdout.count("\n#") + res.stdout.count("\n  #") > 40  # every key explained
    assert yaml.safe_load(res.stdout)["grid"]["cell_sizes"] == list(load(config).grid.cell_sizes)


def test_the_shipped_default_config_is_the_printed_defaults():
    assert (PRESETS / "default.yaml").read_text() == commented_yaml(Config())
    assert {"default", "paper", "lm", "3dtk", "noisy_sensor"} <= set(preset_names())
    assert (ROOT / "configs" / "paper.yaml").resolve() == (PRESETS / "paper.yaml").resolve()


def test_the_surveyor_keys_are_named_and_the_rest_are_internals():
    text = " ".join(commented_yaml(Config()).replace("# ", "").split())
    assert "Keys a surveyor sets: scene.kind, input.scale, input.axes" in text
    assert "slices.heights" in text.split("Every other key")[0]
    assert "method internal" in text


def _log_run(args: list[str], tmp_path: Path) -> tuple[int, list[str], str]:
    """Run ndt-chain as a script would: stderr into a file, stdout into a pipe."""
    log = tmp_path / "run.log"
    code = "from ndt_cli.cli import chain_app; chain_app(prog_name='ndt-chain')"
    with open(log, "w") as err:
        run = subprocess.run(
            [sys.executable, "-c", code, *args],
            stdout=subprocess.PIPE,
            stderr=err,
            text=True,
            env=ENV,
            cwd=tmp_path,
            check=False,
        )
    return run.returncode, log.read_text().splitlines(), run.stdout


@pytest.mark.slow
def test_without_a_terminal_every_link_is_a_log_line_and_the_table_is_whole(tmp_path):
    scans = [str(SAMPLE / f"scan_0{k}.laz") for k in range(3)]
    code, lines, stdout = _log_run([*scans, "-o", "out", "-j", "1", "-v"], tmp_path)
    assert code == 0, lines
    links = [ln for ln in lines if ln.startswith("link ")]
    # every registration the campaign ran (its neighbours, and a link registered both ways
    # when the first came out doubted), whose status the data decide
    n = len(links)
    pattern = (
        r"link (\d+)/(\d+) scan_0[012]\.laz <- scan_0[012]\.laz: (ok|suspect|rejected), \d+\.\d s"
    )
    counts = [re.match(pattern, ln) for ln in links]
    assert n >= 3 and all(counts), lines
    # counted as announced: the k-th of the registrations announced so far, the last k/n
    assert [int(m[1]) for m in counts] == list(range(1, n + 1)), lines
    assert all(int(m[1]) <= int(m[2]) for m in counts) and int(counts[-1][2]) == n, lines
    assert sum(": ok, " in ln for ln in links) >= 2, lines
    debug = [ln for ln in lines if ln.startswith("debug:")]
    # ndt-cli's own debug lines: the links' levels, how the workers started, the first scan
    # read to see its scene
    assert sum("levels" in ln for ln in debug) == n, lines
    own = ("levels", "worker process(es) by", "scan_00.laz: read ")
    assert all(any(word in ln for word in own) for ln in debug), lines
    foreign = [ln for ln in lines if re.search(r"findfont|numba|matplotlib|distributed", ln)]
    assert foreign == []
    assert "scan_00.laz" in stdout and "scan_02.laz" in stdout and "…" not in stdout
    rows = [ln for ln in stdout.splitlines() if "scan_00.laz" in ln and "scan_01.laz" in ln]
    pair = next((tmp_path / "out").glob("T_scan_0[01]_scan_0[01].txt"))  # either direction
    tx = read_matrix(pair)[0, 3]
    cells = rows[0].split()  # a number is a word of its row
    shown = next(float(c) for c in cells if re.fullmatch(r"-?\d+\.\d{4,}", c))
    assert abs(shown - tx) < 1e-4  # the link's tx, in full, not cut to the terminal's width


def test_quiet_means_nothing_but_errors(tmp_path):
    res = runner.invoke(
        register_app,
        [
            str(SAMPLE / "scan_00.laz"),
            str(tmp_path / "missing.laz"),
            "-o",
            str(tmp_path / "o"),
            "-q",
        ],
    )
    assert res.exit_code == 2 and res.stdout == ""
    assert len(res.stderr.strip().splitlines()) == 1


def test_usage_errors_are_one_line(tmp_path):
    for args in (["a.laz", "b.laz", "--jobs", "many"], ["a.laz", "--bogus"], ["--anchor"]):
        res = runner.invoke(chain_app, args, prog_name="ndt-chain")
        lines = res.stderr.strip().splitlines()
        assert res.exit_code == 2 and len(lines) == 1 and lines[0].startswith("ndt-chain: error:")


def test_a_command_collects_rarely_and_restores_the_collector():
    import gc

    from ndt_cli.cli.common import OLD_COLLECTIONS, YOUNG_COLLECTION, collector_for_a_command

    before = gc.get_threshold()
    with collector_for_a_command():
        assert gc.get_threshold() == (YOUNG_COLLECTION, *OLD_COLLECTIONS)
        assert gc.isenabled()  # cycles are still collected
    assert gc.get_threshold() == before


def test_the_objects_left_at_exit_are_frozen_before_the_last_collection():
    """A handler registered before the command runs after the command's (atexit runs them last
    in, first out): by then every object is frozen, so the interpreter's last collection skips
    them. Without the command, nothing is frozen."""
    probe = (
        "import atexit, gc, sys\n"
        "atexit.register(lambda: print(gc.get_freeze_count()))\n"
        "from ndt_cli.cli.common import collector_for_a_command\n"
        "if sys.argv[1] == 'command':\n"
        "    with collector_for_a_command():\n"
        "        pass\n"
    )
    counts = {}
    for mode in ("command", "none"):
        run = subprocess.run(
            [sys.executable, "-c", probe, mode], capture_output=True, text=True, check=True
        )
        counts[mode] = int(run.stdout.strip())
    assert counts["none"] == 0
    assert counts["command"] > 10_000  # the imports' objects, at least


@pytest.mark.parametrize(
    "error",
    [
        KeyboardInterrupt(),
        during_ctrl_c(ImportError("initialization failed")),
        during_ctrl_c(OSError("a write in a cleanup"), direct=False),
    ],
)
def test_ctrl_c_at_any_step_is_one_line_and_exit_130(error, capsys):
    import typer

    from ndt_cli.cli.common import user_errors

    with pytest.raises(typer.Exit) as caught, user_errors("ndt-x", debug=False):
        raise error
    assert caught.value.exit_code == 130
    assert capsys.readouterr().err.splitlines() == ["ndt-x: error: interrupted"]


def test_a_bug_keeps_its_traceback():
    from ndt_cli.cli.common import user_errors

    with pytest.raises(ImportError, match="a bug"), user_errors("ndt-x", debug=False):
        raise ImportError("a bug")


@pytest.mark.parametrize("stopped", [False, True])
def test_the_progress_display_s_last_frame(stopped):
    """On a terminal, the progress display's last frame: the stage done with its bar, or,
    stopped by Ctrl-C, nothing (the link at work no longer drawn: the command's one line
    follows)."""
    from ndt_cli.cli.progress import ChainProgress

    progress = ChainProgress(("scan_0.laz", "scan_1.laz"), enabled=True)
    progress._start_bar()  # what a terminal gets (stderr is not one here)
    progress.at_work, progress.total = [(0, 1)], 1
    progress._describe()
    exc = KeyboardInterrupt() if stopped else None
    progress.__exit__(type(exc) if exc else None, exc, None)
    texts = [str(r) for r in progress._bar.get_renderables() if hasattr(r, "plain")]
    if stopped:
        assert list(progress._bar.get_renderables()) == []
    else:
        assert texts == ["done: 0 registration(s)"]
