"""The documentation says only what is so: every command and option the README names exists,
as the commands themselves declare them (their Typer apps, as ``pyproject.toml`` installs
them), and every relative link of the documentation leads to a file, and a heading, that
exist."""

from __future__ import annotations

import re
import tomllib
from importlib import import_module
from pathlib import Path

import click
import pytest
import typer

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = [README, ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]
CODE_SPAN = re.compile(r"`([^`\n]+)`")
COMMAND = re.compile(r"ndt-(?!cli\b)[a-z]+")  # a command's name (ndt-cli is the package)
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _options(cmd: click.Command, name: str) -> set[str]:
    ctx = cmd.make_context(name, [], resilient_parsing=True)
    return {o for p in cmd.get_params(ctx) for o in (*p.opts, *p.secondary_opts) if o[0] == "-"}


def _commands() -> dict[str, set[str]]:
    """Option strings by command: each console script, and ``ndt-analyze SUB`` for each of the
    group's commands."""
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    out: dict[str, set[str]] = {}
    for name, target in scripts.items():
        module, attr = target.split(":")
        cmd = typer.main.get_command(getattr(import_module(module), attr))
        out[name] = _options(cmd, name)
        for sub, child in getattr(cmd, "commands", {}).items():
            out[f"{name} {sub}"] = _options(child, sub)
    return out


COMMANDS = _commands()
ALL_OPTIONS = set().union(*COMMANDS.values())


def _option_words(text: str) -> list[str]:
    """The options a piece of code names: ``-o/--out DIR`` names -o and --out."""
    words = [w for part in text.split() for w in part.split("/")]
    return [w.rstrip(",.:;)") for w in words if re.match(r"--?[A-Za-z]", w)]


def _invocations(path: Path) -> list[tuple[str, str]]:
    """(command, its text) of every code span and code-block line that runs a command."""
    text = path.read_text(encoding="utf-8")
    blocks = re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S)
    lines = [line for block in blocks for line in block.splitlines()]
    found = []
    for piece in [*CODE_SPAN.findall(re.sub(r"```.*?```", "", text, flags=re.S)), *lines]:
        words = piece.split()
        if words and COMMAND.fullmatch(words[0].rstrip(":")):
            name = words[0].rstrip(":")
            sub = f"{name} {words[1]}" if len(words) > 1 else ""
            found.append((sub if sub in COMMANDS else name, piece))
    return found


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_every_command_the_documentation_runs_exists_with_its_options(path):
    for name, piece in _invocations(path):
        assert name in COMMANDS, f"{path.name}: {piece!r} runs no command"
        unknown = [o for o in _option_words(piece) if o not in COMMANDS[name]]
        assert unknown == [], f"{path.name}: {piece!r}: {name} has no {unknown}"


def _sections(text: str) -> dict[str, str]:
    parts = re.split(r"^## (.+)$", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


def _blocks(section: str) -> tuple[str, dict[str, str]]:
    """The text before the first command, and the text about each command (from the line that
    names it in bold to the next such line)."""
    parts = re.split(r"^(?=\*\*`ndt-[a-z]+)", section, flags=re.M)
    return parts[0], {re.match(r"\*\*`(ndt-[a-z]+)", p)[1]: p for p in parts[1:]}


def test_the_readme_names_every_command_and_only_each_one_s_options():
    preamble, blocks = _blocks(_sections(README.read_text(encoding="utf-8"))["Commands"])
    tops = {name for name in COMMANDS if " " not in name}
    assert set(blocks) == tops
    for name, text in blocks.items():
        mine = set().union(*(o for c, o in COMMANDS.items() if c.split()[0] == name))
        named = {o for span in CODE_SPAN.findall(text) for o in _option_words(span)}
        assert named and named - mine == set(), f"{name}: {sorted(named - mine)}"
    every = {"-h", "--help", "-V", "--version", "--install-completion", "--show-completion"}
    assert every <= {o for span in CODE_SPAN.findall(preamble) for o in _option_words(span)}
    assert all(every <= COMMANDS[name] for name in tops)


def test_every_option_the_readme_names_exists():
    spans = CODE_SPAN.findall(README.read_text(encoding="utf-8"))
    named = {o for span in spans for o in _option_words(span)}
    assert {"--out", "--per-scan", "--include-suspect"} <= named
    assert named - ALL_OPTIONS == set()


def _anchors(path: Path) -> set[str]:
    """The anchors of a Markdown file's headings, as GitHub makes them."""
    headings = re.findall(r"^#+ (.+)$", path.read_text(encoding="utf-8"), flags=re.M)
    return {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-") for h in headings}


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_every_relative_link_resolves(path):
    for target in LINK.findall(path.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target):
            continue  # http, https, mailto
        file, _, anchor = target.partition("#")
        where = (path.parent / file).resolve() if file else path
        assert where.exists(), f"{path.name}: {target} names no file"
        if anchor and where.suffix == ".md":
            assert anchor in _anchors(where), f"{path.name}: {target} names no heading"


def test_the_readme_is_read_in_ten_minutes():
    assert len(README.read_bytes()) <= 12_000
    assert {p.name for p in DOCS} >= {
        "method.md",
        "network.md",
        "deliverables.md",
        "performance.md",
        "architecture.md",
        "configuration.md",
        "trust.md",
    }
