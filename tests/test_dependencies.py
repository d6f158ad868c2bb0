"""Every third-party module the package imports is declared where an installed ndt-cli finds
it: in ``[project] dependencies``, or in an extra a user installs for that feature (e57, dask,
plot), never only in the developers' extras (dev, bench). The test environment has them all,
so a module missing from the runtime dependencies fails only for users: here it fails first."""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "ndt_cli"
DEVELOPERS = {"dev", "bench"}  # extras no user installs


def _name(requirement: str) -> str:
    """The normalised distribution name of a requirement such as ``dask[distributed]>=2024``."""
    head = re.match(r"[A-Za-z0-9._-]+", requirement.strip())
    assert head, requirement
    return re.sub(r"[-_.]+", "-", head.group(0)).lower()


def _declared() -> tuple[set[str], dict[str, set[str]]]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = {k: {_name(r) for r in v} for k, v in project["optional-dependencies"].items()}
    return {_name(r) for r in project["dependencies"]}, extras


def _guarded(node: ast.Try) -> bool:
    """Whether a ``try`` catches ImportError: what it imports is a fallback, not a need."""
    caught = [h.type for h in node.handlers if h.type is not None]
    names = {n.id for t in caught for n in ast.walk(t) if isinstance(n, ast.Name)}
    return bool(names & {"ImportError", "ModuleNotFoundError"})


def _imports(node: ast.AST) -> list[str]:
    """Modules imported under ``node``, leaving out a ``try`` that catches ImportError (its
    imports, and its handler's, are one choice among others)."""
    if isinstance(node, ast.Try) and _guarded(node):
        return [m for child in [*node.orelse, *node.finalbody] for m in _imports(child)]
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        return [node.module] if node.level == 0 and node.module else []
    return [m for child in ast.iter_child_nodes(node) for m in _imports(child)]


def _imported_roots() -> dict[str, str]:
    """Top-level module names the package imports unguarded (not its own, not the standard
    library), each with one module that imports it."""
    found: dict[str, str] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        for name in _imports(ast.parse(path.read_text())):
            root = name.split(".")[0]
            if root != "ndt_cli" and root not in sys.stdlib_module_names:
                found.setdefault(root, str(path.relative_to(ROOT)))
    return found


def test_every_imported_distribution_is_declared_for_users():
    runtime, extras = _declared()
    users = runtime.union(*(v for k, v in extras.items() if k not in DEVELOPERS))
    owners = packages_distributions()
    missing = []
    for root, where in sorted(_imported_roots().items()):
        dists = {_name(d) for d in owners.get(root, [])}
        assert dists, f"{root} (imported by {where}) is not installed in the test environment"
        if not dists & users:
            missing.append(f"{root} ({'/'.join(sorted(dists))}, imported by {where})")
    assert not missing, "imported but not declared for users: " + ", ".join(missing)


def test_the_check_sees_the_package_import_its_core_libraries():
    """The walk finds the package's imports, and leaves out a fallback in a ``try`` that
    catches ImportError (typer's vendored click first, the click package second)."""
    roots = _imported_roots()
    assert {"numpy", "laspy", "numba", "gtsam", "typer"} <= set(roots)
    assert "click" not in roots
    code = "try:\n    import a\nexcept ImportError:\n    import b\nimport c\n"
    assert _imports(ast.parse(code)) == ["c"]
    assert _name("dask[distributed]>=2024.1") == "dask"
    assert _name("PyYAML>=6") == "pyyaml"
