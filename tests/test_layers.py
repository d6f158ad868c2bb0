"""The package's imports point down its layers, and no two modules import each other in a
circle, counting every import a module runs (at its top or inside a function) but not those
only a type checker reads (``if TYPE_CHECKING:``)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "ndt_cli"

# each subpackage's layer: a module imports from its own layer and the layers below only
LAYERS = {
    "errors": 0,
    "core": 0,
    "config": 1,
    "io": 2,
    "sim": 2,
    "ndt": 3,
    "pipeline": 4,
    "analysis": 5,
    "report": 6,
    "cli": 7,
}
KNOWN_CIRCLES: list[set[str]] = []


def _module(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_only(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(tree: ast.AST, modules: set[str]) -> set[str]:
    """The ``modules`` that ``tree`` imports when it runs (not under ``if TYPE_CHECKING``);
    ``from PACKAGE import MODULE`` counts as importing the module, not the package's face."""
    out: set[str] = set()
    todo = [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.If) and _type_only(node):
            todo.extend(node.orelse)
            continue
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            base = node.module
            named = (f"{base}.{a.name}" for a in node.names)
            out |= {m if m in modules else base for m in named}
        todo.extend(ast.iter_child_nodes(node))
    return out & modules


def _graph() -> dict[str, set[str]]:
    files = {_module(p): p for p in PACKAGE.rglob("*.py")}
    return {
        name: _imports(ast.parse(path.read_text(encoding="utf-8")), set(files)) - {name}
        for name, path in files.items()
    }


def _layer(module: str) -> int | None:
    parts = module.split(".")
    return LAYERS.get(parts[1]) if len(parts) > 1 else None


def test_every_import_points_down_the_layers():
    up = [
        f"{a} -> {b}"
        for a, targets in sorted(_graph().items())
        for b in sorted(targets)
        if _layer(a) is not None and _layer(b) is not None and _layer(b) > _layer(a)
    ]
    assert up == []
    assert set(LAYERS) <= {p.stem for p in PACKAGE.iterdir() if not p.name.startswith("_")}


def _circles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = set()
            while True:
                w = stack.pop()
                part.add(w)
                if w == v:
                    break
            if len(part) > 1:
                out.append(part)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_modules_import_each_other_in_a_circle():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]
    found = _circles(_graph())
    assert [c for c in found if c not in KNOWN_CIRCLES] == []
