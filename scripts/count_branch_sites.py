"""Count the places in ``study/`` that ask "is this a user's shader or one of the study's?".

A *site* is a line of ``study/`` holding one of these tests, however written:

* a call of a predicate: ``is_user_shader(...)``, ``is_user(...)``;
* an attribute read ``.is_user`` or ``.user_shader`` (not on ``self``), or
  ``getattr(x, "user_shader", ...)``, ``hasattr(x, "user_shader")``;
* ``x is None`` / ``x is not None`` on a name or attribute whose name holds ``user``;
* ``isinstance(x, C)`` with ``C`` one of the user-or-port classes (``SpirvModel``,
  ``UserShader``, ``ShaderModel``, ``UserFile``, ``PortShader``);
* a comparison with the string ``"user"`` (a kind field), or a result's user-only key read as
  a question: ``"shader_file" in d``, ``d.get("shader_file")``;
* a test (``if``, a conditional expression, ``while``, a comprehension's ``if``) that reads a
  name assigned from one of the above in the same function (a flag that carries the answer).

Lines of the shader handle (``study/calibration/shader.py``, the one place meant to ask) and the
predicates' own definitions are reported apart. Usage::

    python scripts/count_branch_sites.py              # the working tree
    python scripts/count_branch_sites.py --rev f59da82 # a commit (read with git show)
    python scripts/count_branch_sites.py --list        # every site, file:line
"""

from __future__ import annotations

import argparse
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PREDICATES = {"is_user_shader", "is_user"}
CLASSES = {"SpirvModel", "UserShader", "ShaderModel", "UserFile", "PortShader"}
ATTRIBUTES = {"is_user", "user_shader"}
KEYS = {"shader_file"}  # a result's key only a user's shader has
HANDLE = "study/calibration/shader.py"


def _name(node) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return ""


def _is_site(node) -> bool:
    if isinstance(node, ast.Call):
        fn = _name(node.func)
        if fn in PREDICATES:
            return True
        if fn == "get" and node.args and isinstance(node.args[0], ast.Constant):
            return node.args[0].value in KEYS
        if fn in ("getattr", "hasattr") and len(node.args) >= 2:
            a = node.args[1]
            return isinstance(a, ast.Constant) and a.value in ATTRIBUTES
        if fn == "isinstance" and len(node.args) == 2:
            kinds = node.args[1].elts if isinstance(node.args[1], ast.Tuple) else [node.args[1]]
            return any(_name(k) in CLASSES for k in kinds)
        return False
    if isinstance(node, ast.Attribute) and node.attr in ATTRIBUTES:
        return _name(node.value) != "self"  # an object's own field is no question
    if isinstance(node, ast.Compare):
        parts = [node.left, *node.comparators]
        if any(isinstance(op, (ast.Is, ast.IsNot)) for op in node.ops):
            if any(isinstance(p, ast.Constant) and p.value is None for p in parts):
                return any("user" in _name(p).lower() for p in parts)
        if any(isinstance(op, (ast.In, ast.NotIn)) for op in node.ops):
            if isinstance(node.left, ast.Constant) and node.left.value in KEYS:
                return True
        return any(isinstance(p, ast.Constant) and p.value == "user" for p in parts)
    return False


def _flag_tests(tree) -> set[int]:
    """Lines of tests that read a name assigned from a site, per function."""
    out = set()
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        flags = set()
        for node in ast.walk(fn):
            if isinstance(node, ast.Assign) and any(_is_site(n) for n in ast.walk(node.value)):
                flags |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        if not flags:
            continue
        tests = []
        for node in ast.walk(fn):
            if isinstance(node, (ast.If, ast.IfExp, ast.While)):
                tests.append(node.test)
            elif isinstance(node, ast.comprehension):
                tests += node.ifs
        for t in tests:
            if any(isinstance(n, ast.Name) and n.id in flags for n in ast.walk(t)):
                out.add(t.lineno)
    return out


def sites(files: dict[str, str]) -> dict[str, list[int]]:
    """{path: sorted line numbers holding a site} of ``files`` (path -> source text), without
    the lines of the predicates' own ``def``."""
    out = {}
    for path, text in files.items():
        tree = ast.parse(text, filename=path)
        defs = {
            n.lineno
            for n in ast.walk(tree)
            if isinstance(n, ast.FunctionDef) and n.name in PREDICATES
        }
        lines = {n.lineno for n in ast.walk(tree) if _is_site(n)} | _flag_tests(tree)
        lines -= defs
        if lines:
            out[path] = sorted(lines)
    return out


def read_tree(rev: str | None) -> dict[str, str]:
    """path -> text of every ``study/**.py`` in the working tree or at commit ``rev``."""
    if rev is None:
        return {str(p.relative_to(ROOT)): p.read_text() for p in sorted(ROOT.glob("study/**/*.py"))}
    names = subprocess.run(
        ["git", "ls-tree", "-r", "--name-only", rev, "study"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    return {
        n: subprocess.run(
            ["git", "show", f"{rev}:{n}"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout
        for n in names
        if n.endswith(".py")
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", help="a commit to count at (default: the working tree)")
    ap.add_argument("--list", action="store_true", help="print every site")
    args = ap.parse_args(argv)
    found = sites(read_tree(args.rev))
    outside = {p: ls for p, ls in found.items() if p != HANDLE}
    n_out = sum(map(len, outside.values()))
    n_in = len(found.get(HANDLE, []))
    if args.list:
        for p, ls in sorted(found.items()):
            for ln in ls:
                print(f"{p}:{ln}")
    print(f"user-or-port sites outside the shader handle: {n_out} in {len(outside)} files")
    print(f"inside the shader handle ({HANDLE}): {n_in}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
