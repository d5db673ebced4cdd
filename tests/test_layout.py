"""The house: imports point one way (no module imports one that imports it back, and none
imports a stage above its own, function-local imports included), the project's imports sit at
the top of their modules (the few that cannot say why), a module imported from outside its
package has a public name, no private name crosses a module line, the experiment is read typed
outside its package, and every process-wide cache is listed in docs/process-state.md."""

from __future__ import annotations

import ast
import re
from fnmatch import fnmatchcase
from pathlib import Path

from helpers import REPO

PACKAGES = ("study", "shaders_port")

# The stages, bottom to top: a module may import its own layer and those below, never one above.
# ``pkg.*`` is everything under ``pkg``; a module in no layer fails the test (place it).
LAYERS = (
    ("shaders_port", "shaders_port.*"),
    # helpers of every stage
    ("study._backend", "study._io", "study._kernels", "study._metrics", "study._progress"),
    # the experiment: its keys and their checks, its files, read typed by section
    ("study.config", "study.config.*"),
    ("study.scene", "study.scene.*"),
    # report writers and the export, used by the fit, the studies and the jobs
    ("study.report", "study.report.*", "study.export", "study.export.*"),
    ("study.fit", "study.fit.*"),
    ("study.sweep", "study.sweep.*"),
    # the calibration pipeline: frames, shader handle, fit, score, export, result
    ("study.calibration", "study.calibration.*"),
    ("study.studies", "study.studies.*"),
    # the commands the command line runs
    ("study.commands", "study.commands.*"),
    # the command line and the package's face (study/__init__.py)
    ("study.cli", "study"),
)


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
    """(edges: module -> the modules it imports, private: (importer, module, private name))."""
    modules = {_module_name(p): p for pkg in PACKAGES for p in (REPO / pkg).rglob("*.py")}
    edges, private = {}, []
    for name, path in modules.items():
        out = set()
        for mod, names in _imports(path, name):
            # ``from pkg import a, b``: the submodules named, and ``pkg`` for any other name
            subs = [f"{mod}.{n}" for n in names if f"{mod}.{n}" in modules]
            if mod in modules and (not names or len(subs) < len(names)):
                subs.append(mod)
            out.update(t for t in subs if t != name)
            if (
                mod in modules and mod != name
            ):  # a private module (``study._io``) is plumbing, not a name
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


def _layer(module: str, layers=LAYERS) -> int | None:
    for i, patterns in enumerate(layers):
        if any(fnmatchcase(module, p) for p in patterns):
            return i
    return None


def _upward(edges: dict, layers=LAYERS) -> list[str]:
    """Every import of a module in a higher layer than the importer's, named."""
    found = []
    for a, outs in sorted(edges.items()):
        for b in sorted(outs):
            la, lb = _layer(a, layers), _layer(b, layers)
            if la is not None and lb is not None and lb > la:
                found.append(f"{a} imports {b} (layer {layers[lb][0]} is above {layers[la][0]})")
    return found


def _private_from_outside(edges: dict) -> list[str]:
    """Every import of a module whose own name is private from outside that module's package."""
    found = []
    for a, outs in sorted(edges.items()):
        for b in sorted(outs):
            package, _, own = b.rpartition(".")
            if own.startswith("_") and not (a == package or a.startswith(package + ".")):
                found.append(f"{a} imports {b}")
    return found


def test_every_module_has_a_layer():
    edges, _ = _graph()
    assert [m for m in sorted(edges) if _layer(m) is None] == []


def test_no_import_points_up_the_stages():
    edges, _ = _graph()
    assert _upward(edges) == []


def test_the_layer_check_finds_an_upward_import():
    # a scene module that imports the fit is named with both layers
    planted = {
        "study.config.experiment": {"study.fit.model", "study._io"},
        "study.fit.model": set(),
    }
    assert _upward(planted) == [
        "study.config.experiment imports study.fit.model (layer study.fit is above study.config)"
    ]


def test_an_import_inside_a_function_is_an_edge(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from .fit import model\n")
    assert list(_imports(module, "study.m")) == [("study.fit", ["model"])]


def test_a_module_imported_from_outside_its_package_has_a_public_name():
    edges, _ = _graph()
    assert _private_from_outside(edges) == []


def test_the_public_name_check_finds_a_private_module_used_outside():
    planted = {
        "study.fit.model": {"shaders_port._hidden", "study._io"},
        "shaders_port.ports.planar": {"shaders_port._hidden"},
    }
    assert _private_from_outside(planted) == ["study.fit.model imports shaders_port._hidden"]


def _local_imports(text: str) -> list[tuple[int, str]]:
    """(line, the import's source) of every import of the project's own modules inside a
    function of ``text``."""
    tree, out = ast.parse(text), []
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            own = isinstance(node, ast.ImportFrom) and (
                node.level > 0 or (node.module or "").split(".")[0] in PACKAGES
            )
            own |= isinstance(node, ast.Import) and any(
                a.name.split(".")[0] in PACKAGES for a in node.names
            )
            if own:
                out.append((node.lineno, ast.get_source_segment(text, node)))
    return sorted(set(out))


def test_the_projects_imports_are_at_the_top():
    # an import of the project's own modules inside a function only where importing it at the
    # top costs what most users of the module never need (each says why in a `# local:`
    # comment on the line above it): at most 20
    found, unjustified = 0, []
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            text = path.read_text()
            lines = text.splitlines()
            for line, _ in _local_imports(text):
                found += 1
                if not lines[line - 2].strip().startswith("# local:"):
                    unjustified.append(f"{path.relative_to(REPO)}:{line}")
    assert not unjustified, "import these at the top, or say why not: " + ", ".join(unjustified)
    assert found <= 20, found


def test_the_local_import_finder_finds_one():
    text = "import numpy\n\ndef f():\n    import numpy\n    from .fit import model\n"
    assert _local_imports(text) == [(5, "from .fit import model")]


def test_the_experiment_is_read_typed_outside_its_package():
    # `exp.fit.shader`, not `exp["fit.shader"]`: the keys' strings stay in study/config
    reads = [
        f"{path.relative_to(REPO)}:{i}"
        for pkg in PACKAGES
        for path in sorted((REPO / pkg).rglob("*.py"))
        if "config" not in path.relative_to(REPO).parts
        for i, line in enumerate(path.read_text().splitlines(), 1)
        if re.search(r"\bexp\[[\"']", line)
    ]
    assert reads == [], reads


def _process_state() -> set[str]:
    """``module.name`` of every module-level cache, registry or lock (an empty dict, set or
    ordered dict, or a lock, bound at the top of a module) and every ``lru_cache`` function."""
    kinds = {"set", "dict", "OrderedDict", "RLock", "Lock"}
    found = set()
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            module = _module_name(path)
            for node in ast.parse(path.read_text()).body:
                if isinstance(node, (ast.Assign, ast.AnnAssign)):
                    target = node.targets[0] if isinstance(node, ast.Assign) else node.target
                    v = node.value
                    empty = isinstance(v, ast.Dict) and not v.keys
                    empty |= isinstance(v, ast.Set) and not v.elts
                    call = isinstance(v, ast.Call) and not v.args
                    call = call and getattr(v.func, "id", getattr(v.func, "attr", "")) in kinds
                    if isinstance(target, ast.Name) and (empty or call):
                        found.add(f"{module}.{target.id}")
                elif isinstance(node, ast.FunctionDef):
                    if any("cache" in ast.unparse(d) for d in node.decorator_list):
                        found.add(f"{module}.{node.name}")
    return found


def test_every_process_wide_state_is_listed():
    # docs/process-state.md lists what a process keeps between calls, why and how it is keyed
    page = (REPO / "docs" / "process-state.md").read_text()
    listed = set(re.findall(r"^\| `([\w.]+)` \|", page, re.M))
    assert _process_state() == listed
