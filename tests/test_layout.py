"""The house: ``study/`` imports point one way (no module imports one that imports it back,
function-local imports included), and no private name crosses a module line."""

from __future__ import annotations

import ast
from pathlib import Path

from helpers import REPO

PACKAGES = ("study", "shaders_port")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, name: str):
    """(imported module, imported names) of every import in ``path``, nested ones included."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            yield mod, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, []


def _graph():
    modules = {_module_name(p): p for pkg in PACKAGES for p in (REPO / pkg).rglob("*.py")}
    edges, private = {}, []
    for name, path in modules.items():
        out = set()
        for mod, names in _imports(path, name):
            for target in [f"{mod}.{n}" for n in names] + [mod]:
                if target in modules and target != name:
                    out.add(target)
                    break
            if (
                mod in modules and mod != name
            ):  # a private module (``_frame``) is plumbing, not a name
                private += [
                    (name, mod, n)
                    for n in names
                    if n.startswith("_") and f"{mod}.{n}" not in modules and n != "__version__"
                ]
        edges[name] = out
    return edges, private


def _cycles(edges: dict) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_circles():
    edges, _ = _graph()
    assert len(edges) > 50
    assert _cycles(edges) == []


def test_the_cycle_finder_finds_a_circle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_private_name_crosses_a_module_line():
    _, private = _graph()
    # a package's own face may hand on a private module's names (shaders_port/__init__)
    crossing = [(a, b, n) for a, b, n in private if not a.endswith("__init__") and "." in a]
    assert crossing == [], crossing


def test_modules_and_functions_stay_readable():
    # the house rules: a module of at most 600 lines, a function of at most 100
    long = []
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            text = path.read_text()
            if len(text.splitlines()) > 600:
                long.append(f"{path.relative_to(REPO)}: {len(text.splitlines())} lines")
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = node.end_lineno - node.lineno + 1
                    if n > 100:
                        long.append(f"{path.relative_to(REPO)}:{node.lineno} {node.name}: {n}")
    assert not long, "split these: " + "; ".join(long)
