"""GLSL sources of the water shaders: paths, dialects, the tunable-constants block, compile checks.

Shaders (see ``shaders_port/README.md``): ``water`` (vertex), ``water_refraction`` and
``water_reflection`` (fragment). Two dialects:

* ``"compat"``: GLSL 1.20 with the compatibility built-ins, as documented in the seed;
  files ``shaders_port/glsl/<name>.<vert|frag>``.
* ``"core"``: ``#version 330 core``; files ``shaders_port/glsl/core/<name>.<vert|frag>``.
  Each core file is exactly ``compat_to_core(<compat file>)``; ``CORE_SUBSTITUTIONS`` is the
  whole difference.

Every fragment shader carries a block of tunable constants between ``BEGIN_MARKER`` and
``END_MARKER``; ``write_constants`` rewrites only the declarations inside it.
"""

from __future__ import annotations

import math
import numbers
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from .inputs import CONSTANT_SPECS, Constants

GLSL_DIR = Path(__file__).parent / "glsl"
SHADER_NAMES = ("water", "water_refraction", "water_reflection", "water_baseline")
DIALECTS = ("compat", "core")
BEGIN_MARKER = "// ---- BEGIN TUNABLE CONSTANTS (written by `study export`) ----"
END_MARKER = "// ---- END TUNABLE CONSTANTS ----"

_GLSL_TO_PY = {glsl: py for py, (glsl, _, _, _) in CONSTANT_SPECS.items()}
_DECL_RE = re.compile(
    r"^(?P<indent>\s*)(?P<kind>const float|const int|uniform float|uniform vec4)\s+"
    r"(?P<name>[A-Za-z_]\w*)\s*=\s*(?P<value>[^;]*);(?P<tail>.*)$"
)

# compat -> core, applied in this order (regex, replacement per stage, why)
CORE_SUBSTITUTIONS: tuple[tuple[str, dict[str, str], str], ...] = (
    (
        r"^#version 120$",
        {"vert": "#version 330 core", "frag": "#version 330 core"},
        "core profile; the declarations of the replaced built-ins follow this line",
    ),
    (r"^varying ", {"vert": "out ", "frag": "in "}, "varying -> out / in (line start only)"),
    (r"\btexture2D\(", {"vert": "texture(", "frag": "texture("}, "overloaded texture()"),
    (r"\btextureCube\(", {"vert": "texture(", "frag": "texture("}, "overloaded texture()"),
    (
        r"\bgl_TextureMatrix\[(\d)\]",
        {"vert": r"uTextureMatrix\1", "frag": r"uTextureMatrix\1"},
        "texture matrices become uniforms",
    ),
    (
        r"\bgl_TexCoord\[(\d)\]",
        {"vert": r"vTexCoord\1", "frag": r"vTexCoord\1"},
        "texture coordinate varyings become vec4 in/out",
    ),
    (
        r"\bgl_ModelViewProjectionMatrix\b",
        {"vert": "uModelViewProjectionMatrix", "frag": "uModelViewProjectionMatrix"},
        "uniform",
    ),
    (
        r"\bgl_ModelViewProjectionMatrixInverse\b",
        {"vert": "uModelViewProjectionMatrixInverse", "frag": "uModelViewProjectionMatrixInverse"},
        "uniform",
    ),
    (r"\bgl_NormalMatrix\b", {"vert": "uNormalMatrix", "frag": "uNormalMatrix"}, "uniform"),
    (r"\bgl_Vertex\b", {"vert": "aVertex", "frag": "aVertex"}, "vertex attribute"),
    (
        r"\bgl_MultiTexCoord0\b",
        {"vert": "aMultiTexCoord0", "frag": "aMultiTexCoord0"},
        "vertex attribute",
    ),
    (r"\bgl_FragColor\b", {"vert": "fragColor", "frag": "fragColor"}, "fragment output"),
)


def _check_name(name: str, stage: str, dialect: str) -> None:
    if name not in SHADER_NAMES:
        raise ValueError(f"unknown shader {name!r}; known: {SHADER_NAMES}")
    if stage not in ("vert", "frag"):
        raise ValueError(f"stage must be 'vert' or 'frag', got {stage!r}")
    if dialect not in DIALECTS:
        raise ValueError(f"dialect must be one of {DIALECTS}, got {dialect!r}")


def glsl_path(name: str, stage: str | None = None, dialect: str = "compat") -> Path:
    """Path of a shipped shader file, e.g. ``glsl_path("water", "vert", "core")``.

    ``stage`` defaults to 'vert' for ``water`` and 'frag' for the two pixel shaders.
    """
    stage = stage or ("vert" if name == "water" else "frag")
    _check_name(name, stage, dialect)
    d = GLSL_DIR if dialect == "compat" else GLSL_DIR / "core"
    p = d / f"{name}.{stage}"
    if not p.is_file():
        raise FileNotFoundError(f"no {dialect} {stage} shader {name!r} at {p}")
    return p


def read_source(name: str, stage: str | None = None, dialect: str = "compat") -> str:
    """Text of a shipped shader file (UTF-8, newlines kept)."""
    return glsl_path(name, stage, dialect).read_text(encoding="utf-8")


def _core_declarations(source: str, stage: str) -> list[str]:
    """Declarations of the core-profile names that replace the built-ins used in ``source``."""
    decls = []
    io = "out" if stage == "vert" else "in"
    if re.search(r"\bgl_Vertex\b", source):
        decls.append("in vec4 aVertex;")
    if re.search(r"\bgl_MultiTexCoord0\b", source):
        decls.append("in vec4 aMultiTexCoord0;")
    if re.search(r"\bgl_ModelViewProjectionMatrix\b", source):
        decls.append("uniform mat4 uModelViewProjectionMatrix;")
    if re.search(r"\bgl_ModelViewProjectionMatrixInverse\b", source):
        decls.append("uniform mat4 uModelViewProjectionMatrixInverse;")
    if re.search(r"\bgl_NormalMatrix\b", source):
        decls.append("uniform mat3 uNormalMatrix;")
    for k in sorted(set(re.findall(r"\bgl_TextureMatrix\[(\d)\]", source))):
        decls.append(f"uniform mat4 uTextureMatrix{k};")
    for k in sorted(set(re.findall(r"\bgl_TexCoord\[(\d)\]", source))):
        decls.append(f"{io} vec4 vTexCoord{k};")
    if re.search(r"\bgl_FragColor\b", source):
        decls.append("out vec4 fragColor;")
    return decls


def compat_to_core(source: str, stage: str) -> str:
    """Translate a GLSL 1.20 source of this package into ``#version 330 core``.

    Applies ``CORE_SUBSTITUTIONS`` line by line and declares, right after the
    ``#version`` line, the uniforms / ins / outs that replace the built-ins used.
    """
    if stage not in ("vert", "frag"):
        raise ValueError(f"stage must be 'vert' or 'frag', got {stage!r}")
    lines = source.split("\n")
    if not lines or lines[0] != "#version 120":
        raise ValueError("compat_to_core: the source must start with the line '#version 120'")
    decls = _core_declarations(source, stage)
    out = []
    for line in lines:
        for pattern, repl, _ in CORE_SUBSTITUTIONS:
            line = re.sub(pattern, repl[stage], line)
        out.append(line)
    header = ["// core-profile names replacing GLSL 1.20 built-ins (see shaders_port/README.md)"]
    return "\n".join(out[:1] + header + decls + out[1:])


def with_define(source: str, define: str) -> str:
    """``source`` with ``#define <define>`` inserted right after its ``#version`` line."""
    if not re.fullmatch(r"[A-Za-z_]\w*", define):
        raise ValueError(f"not a preprocessor name: {define!r}")
    first, sep, rest = source.partition("\n")
    if not first.startswith("#version"):
        raise ValueError("with_define: the source must start with a #version line")
    return f"{first}\n#define {define}\n{rest}"


def _block_span(lines: list[str]) -> tuple[int, int]:
    begins = [i for i, ln in enumerate(lines) if ln.strip() == BEGIN_MARKER]
    ends = [i for i, ln in enumerate(lines) if ln.strip() == END_MARKER]
    if len(begins) != 1 or len(ends) != 1 or ends[0] < begins[0]:
        raise ValueError(
            "the source needs exactly one tunable-constants block delimited by\n"
            f"  {BEGIN_MARKER}\n  {END_MARKER}"
        )
    return begins[0], ends[0]


def _declarations(lines: list[str]) -> dict[str, tuple[int, re.Match]]:
    """Python constant name -> (line index, match) of every declaration in the block."""
    b, e = _block_span(lines)
    found = {}
    for i in range(b + 1, e):
        s = lines[i].strip()
        if not s or s.startswith("//"):
            continue
        m = _DECL_RE.match(lines[i])
        if m is None:
            raise ValueError(
                f"line {i + 1} inside the constants block is not a declaration "
                f"'<kind> NAME = value;': {lines[i]!r}"
            )
        glsl = m["name"]
        if glsl not in _GLSL_TO_PY:
            raise ValueError(
                f"line {i + 1}: {glsl} is not a tunable constant; known: {sorted(_GLSL_TO_PY)}"
            )
        py = _GLSL_TO_PY[glsl]
        if m["kind"] != CONSTANT_SPECS[py][1]:
            raise ValueError(
                f"line {i + 1}: {glsl} is declared '{m['kind']}', expected "
                f"'{CONSTANT_SPECS[py][1]}'"
            )
        if py in found:
            raise ValueError(f"line {i + 1}: {glsl} is declared twice in the constants block")
        found[py] = (i, m)
    return found


def _float_literal(x: float) -> str:
    # The shortest text that reads back as the same float32 (GLSL's float). Nine digits of the
    # float64 value can round to the neighbouring float32 (double rounding).
    s = np.format_float_positional(np.float32(x), unique=True, trim="0")
    if not any(c in s for c in ".eE"):
        s += ".0"
    return s


def _checked_scalar(name: str, x) -> float:
    glsl, kind, _, (lo, hi) = CONSTANT_SPECS[name]
    rng = f"allowed range [{lo}, {hi}]"
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
        raise ValueError(
            f"constant {name} ({glsl}) = {x!r}: not a plain number "
            f"({type(x).__name__}); {rng}. Convert it with float() first"
        )
    v = float(x)
    if not math.isfinite(v):
        raise ValueError(f"constant {name} ({glsl}) = {x!r} is not finite; {rng}")
    if kind.endswith("int") and v != int(v):
        raise ValueError(f"constant {name} ({glsl}) = {x!r} must be an integer; {rng}")
    if not lo <= v <= hi:
        raise ValueError(f"constant {name} ({glsl}) = {x!r} is outside the {rng}")
    return v


def _literal(name: str, value) -> str:
    glsl, kind, _, _ = CONSTANT_SPECS[name]
    if kind == "uniform vec4":
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 4:
            raise ValueError(
                f"constant {name} ({glsl}) = {value!r}: needs 4 components (linear RGBA)"
            )
        return "vec4(" + ", ".join(_float_literal(_checked_scalar(name, x)) for x in value) + ")"
    v = _checked_scalar(name, value)
    return str(int(v)) if kind == "const int" else _float_literal(v)


def write_constants(source: str, constants: Constants) -> str:
    """``source`` with the values of the declarations in its constants block replaced.

    Only the value text of those declaration lines changes; every other byte is kept.
    Raises ValueError (naming constant, value and allowed range) for non-numeric, bool,
    non-finite, non-integer (``const int``) or out-of-range values.
    """
    if not isinstance(constants, Constants):
        raise TypeError(
            f"constants must be a shaders_port.Constants, got {type(constants).__name__}"
        )
    literals = {name: _literal(name, getattr(constants, name)) for name in CONSTANT_SPECS}
    constants.validate()
    lines = source.split("\n")
    for py, (i, m) in _declarations(lines).items():
        lines[i] = f"{m['indent']}{m['kind']} {m['name']} = {literals[py]};{m['tail']}"
    return "\n".join(lines)


def _parse_value(name: str, text: str):
    kind = CONSTANT_SPECS[name][1]
    try:
        if kind == "uniform vec4":
            m = re.fullmatch(r"\s*vec4\s*\(([^()]*)\)\s*", text)
            if m is None:
                raise ValueError
            vals = tuple(float(t) for t in m[1].split(","))
            if len(vals) != 4:
                raise ValueError
            return vals
        return int(text) if kind == "const int" else float(text)
    except ValueError:
        raise ValueError(
            f"cannot parse the value of {CONSTANT_SPECS[name][0]} ({kind}): {text.strip()!r}"
        ) from None


def declared_constants(source: str) -> list[str]:
    """Python names (``CONSTANT_SPECS`` keys) declared in the source's constants block."""
    return list(_declarations(source.split("\n")))


def read_constants(source: str) -> Constants:
    """Parse the constants block; names the shader does not declare keep their defaults."""
    lines = source.split("\n")
    kw = {py: _parse_value(py, m["value"]) for py, (_, m) in _declarations(lines).items()}
    return Constants(**kw).validate()


def compile_check(path_or_source, stage: str | None = None) -> None:
    """Compile one shader with the Khronos reference compiler ``glslangValidator``.

    ``path_or_source``: a Path / path string of an existing file, or GLSL source text.
    ``stage``: 'vert' or 'frag' (taken from the file suffix if omitted for a path).
    Raises RuntimeError with the compiler's log on failure.
    """
    exe = shutil.which("glslangValidator")
    if exe is None:
        raise RuntimeError(
            "glslangValidator not found on PATH; install it with `apt-get install glslang-tools`"
        )
    text = None
    if isinstance(path_or_source, Path) or (
        isinstance(path_or_source, str)
        and "\n" not in path_or_source
        and Path(path_or_source).is_file()
    ):
        p = Path(path_or_source)
        text, stage = p.read_text(encoding="utf-8"), stage or p.suffix.lstrip(".")
        label = str(p)
    else:
        text, label = str(path_or_source), "<source>"
    if stage not in ("vert", "frag"):
        raise ValueError(f"stage must be 'vert' or 'frag', got {stage!r}")
    res = subprocess.run(
        [exe, "--stdin", "-S", stage], input=text, capture_output=True, text=True, timeout=60
    )
    if res.returncode != 0:
        raise RuntimeError(
            f"glslangValidator rejected {label} ({stage}):\n{res.stdout}{res.stderr}"
        )


def _pp_condition(expr: str, defined: set) -> bool:
    """Value of a ``#if``/``#elif`` expression made of ``defined(NAME)``, ``!``, ``&&``, ``||`` and
    parentheses (the forms these shaders use); anything else is refused."""
    text = re.sub(
        r"defined\s*\(\s*([A-Za-z_]\w*)\s*\)",
        lambda m: " True " if m.group(1) in defined else " False ",
        expr,
    )
    text = text.replace("&&", " and ").replace("||", " or ").replace("!", " not ")
    if not re.fullmatch(r"[\s()]*((True|False|not|and|or)[\s()]*)+", text):
        raise ValueError(f"active_code: unsupported #if expression {expr!r}")
    return bool(eval(text, {"__builtins__": {}}, {}))


def active_code(source: str) -> str:
    """The source as the preprocessor leaves it: lines inside conditional branches not taken are
    dropped, given the ``#define NAME`` lines of the source. Directives: ``#ifdef``, ``#ifndef``,
    ``#if``/``#elif`` over ``defined(NAME)`` with ``!``, ``&&``, ``||``, ``#else``, ``#endif``
    (the only ones these shaders use; other ``#if`` expressions are refused)."""
    defined, out = set(), []
    stack = [(True, True)]  # (this branch is taken, some branch of this #if was taken)

    def live():
        return all(t for t, _ in stack)

    for line in source.split("\n"):
        s = line.strip()
        if s.startswith("#define ") and live():
            defined.add(s.split()[1])
        elif s.startswith(("#ifdef ", "#ifndef ")):
            take = (s.split()[1] in defined) == s.startswith("#ifdef ")
            stack.append((take, take))
        elif s.startswith("#if "):
            take = _pp_condition(s[4:], defined)
            stack.append((take, take))
        elif s.startswith("#elif"):
            _, taken = stack[-1]
            take = not taken and _pp_condition(s[5:], defined)
            stack[-1] = (take, taken or take)
        elif s.startswith("#else"):
            _, taken = stack[-1]
            stack[-1] = (not taken, True)
        elif s.startswith("#endif"):
            stack.pop()
        elif live():
            out.append(line)
    return "\n".join(out)


def switches_of(source: str) -> list[str]:
    """The preprocessor names ``source`` tests (``#ifdef``, ``#ifndef``, ``defined(NAME)``) and
    does not define itself: its variant switches, in order of first use."""
    code = "\n".join(ln.split("//")[0] for ln in source.split("\n"))
    own = set(re.findall(r"^\s*#define\s+([A-Za-z_]\w*)", code, re.M))
    tested = re.findall(
        r"^\s*#if(?:n?def)\s+([A-Za-z_]\w*)|defined\s*\(\s*([A-Za-z_]\w*)\s*\)", code, re.M
    )
    names = dict.fromkeys(a or b for a, b in tested)
    return [n for n in names if n not in own]


def constants_read(source: str) -> list[str]:
    """``CONSTANT_SPECS`` names declared in the constants block *and* used by the code the
    preprocessor keeps (comments removed; a use is any occurrence beyond the declaration):
    what the shader really reads."""
    code = active_code("\n".join(ln.split("//")[0] for ln in source.split("\n")))
    return [
        py
        for py in declared_constants(source)
        if len(re.findall(rf"\b{CONSTANT_SPECS[py][0]}\b", code)) >= 2
    ]
