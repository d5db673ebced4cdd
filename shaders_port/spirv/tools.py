"""The water shaders through SPIR-V: glslang, SPIRV-Tools and SPIRV-Cross, driven as programs.

The core GLSL of a shader goes to SPIR-V with ``glslangValidator -G --aml --amb`` (OpenGL
semantics, locations and bindings mapped automatically), is validated with ``spirv-val`` and
is translated by ``spirv-cross`` into the engine targets of :data:`TARGET_ARGS`: GLSL ES 3.00
(WebGL2), HLSL shader model 5.0, the Metal Shading Language, and the SPIR-V itself.

The tunable constants must survive the translation. The GLSL keeps some of them as uniforms
with initializers (``uniform float BumptexMult = 0.9797;``); HLSL and GLSL ES ignore or refuse
uniform initializers, so a literal translation would ship the wrong values. Before glslang
sees the shader, :func:`specialize_constants` turns every declaration of the constants block
into a *specialization constant* with the value as its default (a colour into four scalar ones,
``waterColor_r`` ... ``waterColor_a``, and a ``const vec4`` made of them). SPIRV-Cross writes
each as a named constant holding the fitted value: ``#define SPIRV_CROSS_CONSTANT_ID_<id>
<value>`` in HLSL and GLSL ES (an engine may override it by defining the macro), a
``[[function_constant(<id>)]]`` with the value as its fallback in Metal, and ``OpSpecConstant``
in SPIR-V (``VkSpecializationInfo`` may override it). The ids are :data:`SPEC_IDS`, the same for
every shader.

:func:`hlsl_round_trip` compiles the HLSL back with glslang's HLSL front end (``-D -V``) and
translates that SPIR-V into GLSL 330 for OpenGL, renaming the stage inputs back to the names of
the vertex shader's outputs (read from ``spirv-cross --reflect``), so the HLSL can run on
llvmpipe beside the port.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from ..glsl_text import BEGIN_MARKER, END_MARKER, read_source
from ..inputs import CONSTANT_SPECS
from .module import without_bool_uniforms

# program -> Debian package that ships it
TOOLS = {
    "glslangValidator": "glslang-tools",
    "spirv-val": "spirv-tools",
    "spirv-cross": "spirv-cross",
}
# target -> spirv-cross arguments ('spirv' is the validated SPIR-V binary itself)
TARGET_ARGS = {
    "gles300": ("--es", "--version", "300"),
    "hlsl": ("--hlsl", "--shader-model", "50"),
    "msl": ("--msl",),
    "spirv": (),
}
COLOR_SUFFIXES = ("r", "g", "b", "a")


def _spec_ids() -> dict[str, int]:
    """GLSL name of each scalar specialization constant -> its constant_id (a colour takes four
    consecutive ids, ``<name>_r`` ... ``<name>_a``), in ``CONSTANT_SPECS`` order."""
    ids, k = {}, 0
    for glsl, kind, _, _ in CONSTANT_SPECS.values():
        names = [f"{glsl}_{c}" for c in COLOR_SUFFIXES] if kind.endswith("vec4") else [glsl]
        for n in names:
            ids[n], k = k, k + 1
    return ids


SPEC_IDS = _spec_ids()
_BLOCK_DECL = re.compile(
    r"^(?P<indent>\s*)(?:const|uniform) (?P<type>float|int|vec4)\s+(?P<name>[A-Za-z_]\w*)\s*=\s*"
    r"(?P<value>[^;]*);(?P<tail>.*)$"
)


def missing_tools(names=tuple(TOOLS)) -> list[str]:
    """The programs of ``names`` not on PATH, each with the Debian package that ships it."""
    return [f"{n} (apt-get install {TOOLS[n]})" for n in names if shutil.which(n) is None]


def _tool(name: str) -> str:
    exe = shutil.which(name)
    if exe is None:
        raise RuntimeError(
            f"{name} not found on PATH; install it with `apt-get install {TOOLS[name]}` "
            "(scripts/setup.sh does)"
        )
    return exe


def _run(args: list[str], label: str) -> subprocess.CompletedProcess:
    """Run a tool; RuntimeError with its log (and what was being done) if it fails."""
    res = subprocess.run(
        [_tool(args[0]), *args[1:]], capture_output=True, text=True, timeout=120, check=False
    )
    if res.returncode != 0:
        raise RuntimeError(f"{args[0]} failed on {label}:\n{res.stdout}{res.stderr}".rstrip())
    return res


def specialize_constants(source: str) -> str:
    """``source`` with each declaration of its constants block made a specialization constant
    holding its value (uniform initializers included); the rest of the text is kept."""
    lines, inside, out = source.split("\n"), False, []
    for line in lines:
        s = line.strip()
        if s in (BEGIN_MARKER, END_MARKER):
            inside = s == BEGIN_MARKER
            out.append(line)
            continue
        m = _BLOCK_DECL.match(line) if inside else None
        if m is None:
            out.append(line)
            continue
        ind, name, value = m["indent"], m["name"], m["value"].strip()
        if m["type"] != "vec4":
            out.append(
                f"{ind}layout(constant_id = {SPEC_IDS[name]}) const {m['type']} {name} = {value};"
                f"{m['tail']}"
            )
            continue
        parts = re.fullmatch(r"vec4\s*\(([^()]*)\)", value)
        comps = [c.strip() for c in parts[1].split(",")] if parts else []
        if len(comps) != 4:
            raise ValueError(f"specialize_constants: {name} needs vec4(r, g, b, a), got {value!r}")
        for c, v in zip(COLOR_SUFFIXES, comps):
            spec_id = SPEC_IDS[f"{name}_{c}"]
            out.append(f"{ind}layout(constant_id = {spec_id}) const float {name}_{c} = {v};")
        members = ", ".join(f"{name}_{c}" for c in COLOR_SUFFIXES)
        out.append(f"{ind}const vec4 {name} = vec4({members});{m['tail']}")
    return "\n".join(out)


# a declaration's leading blanks (a preprocessed file keeps its indentation) and its
# interpolation qualifiers
_QUALIFIERS = r"[ \t]*((?:(?:flat|noperspective|smooth|centroid)\s+)*)"


def _varying_locations(vertex_source: str | None = None) -> dict[str, int]:
    """Name -> location of each output of the vertex shader (``vertex_source``, by default the
    core ``water.vert``), in declaration order: the one numbering both stages use, so that
    stages link by location (HLSL semantics ``TEXCOORD<n>``, Metal ``[[user(locn<n>)]]``,
    Vulkan) as they link by name in GLSL."""
    text = read_source("water", "vert", "core") if vertex_source is None else vertex_source
    decl = re.compile(rf"^{_QUALIFIERS}out\s+\w+\s+([A-Za-z_]\w*)\s*;", re.M)
    return {m[2]: k for k, m in enumerate(decl.finditer(text))}


def link_locations(source: str, stage: str, vertex_source: str | None = None) -> str:
    """``source`` with ``layout(location = n)`` on each varying (the vertex shader's ``out``, the
    fragment shader's ``in`` lines, interpolation qualifiers kept) by
    :func:`_varying_locations` of ``vertex_source`` (None: the study's ``water.vert``);
    ValueError for a varying the vertex shader does not write."""
    io = "out" if stage == "vert" else "in"
    locs = _varying_locations(vertex_source if stage == "frag" else source)
    what = "water.vert" if vertex_source is None else "it runs after"

    def put(m: re.Match) -> str:
        if m[2] not in locs:
            raise ValueError(f"varying {m[2]!r} is not an output of the vertex shader {what}")
        return f"layout(location = {locs[m[2]]}) {m[0]}"

    out = re.sub(rf"^{_QUALIFIERS}{io}\s+\w+\s+([A-Za-z_]\w*)\s*;", put, source, flags=re.M)
    first, _, rest = out.partition("\n")  # GLSL 330 takes varying locations with this extension
    return f"{first}\n#extension GL_ARB_separate_shader_objects : require\n{rest}"


def glsl_to_spirv(source: str, stage: str, label: str = "<source>") -> bytes:
    """SPIR-V of a GLSL source (``glslangValidator -G --aml --amb``; an unread ``uniform
    bool`` declared ``int``, ``spirv.dialects.without_bool_uniforms``), validated by
    spirv-val."""
    with tempfile.TemporaryDirectory(prefix="spirv.") as d:
        src, spv = Path(d) / f"shader.{stage}", Path(d) / "shader.spv"
        src.write_text(without_bool_uniforms(source, label), encoding="utf-8")
        _run(["glslangValidator", "-G", "--aml", "--amb", "-o", str(spv), str(src)], label)
        _run(["spirv-val", str(spv)], f"the SPIR-V of {label}")
        return spv.read_bytes()


def hlsl_to_spirv(source: str, stage: str, label: str = "<source>") -> bytes:
    """SPIR-V of an HLSL source by glslang's HLSL front end (``-D -e main -S <stage> -V``),
    validated by spirv-val."""
    with tempfile.TemporaryDirectory(prefix="spirv.") as d:
        src, spv = Path(d) / "shader.hlsl", Path(d) / "shader.spv"
        src.write_text(source, encoding="utf-8")
        _run(
            ["glslangValidator", "-D", "-e", "main", "-S", stage, "-V", "-o", str(spv), str(src)],
            label,
        )
        _run(["spirv-val", str(spv)], f"the SPIR-V of {label}")
        return spv.read_bytes()


def es_compile_check(source: str, stage: str, label: str = "<source>") -> None:
    """Compile a ``#version 300 es`` source with glslang's ES profile; RuntimeError if refused."""
    if not source.startswith("#version 300 es"):
        raise ValueError(f"{label}: a GLSL ES 3.00 source starts with '#version 300 es'")
    with tempfile.TemporaryDirectory(prefix="spirv.") as d:
        src = Path(d) / f"shader.{stage}"
        src.write_text(source, encoding="utf-8")
        _run(["glslangValidator", str(src)], label)


def cross(spirv: bytes, args, label: str = "<spirv>") -> str:
    """``spirv-cross <spirv> <args>``: the translated text (or the JSON of ``--reflect``)."""
    with tempfile.TemporaryDirectory(prefix="spirv.") as d:
        spv = Path(d) / "shader.spv"
        spv.write_bytes(spirv)
        return _run(["spirv-cross", str(spv), *args], label).stdout


def reflect(spirv: bytes, label: str = "<spirv>") -> dict:
    """``spirv-cross --reflect`` of a module: its entry point, inputs, outputs, textures,
    samplers, uniform blocks and specialization constants, as JSON."""
    return json.loads(cross(spirv, ["--reflect"], label))


def translate(core_source: str, stage: str, label: str = "<source>") -> dict:
    """The core GLSL ``core_source`` of one stage in every target of :data:`TARGET_ARGS`:
    ``{'spirv': bytes, 'gles300': str, 'hlsl': str, 'msl': str}`` (its constants block made
    specialization constants first, see :func:`specialize_constants`)."""
    spv = glsl_to_spirv(link_locations(specialize_constants(core_source), stage), stage, label)
    out = {"spirv": spv}
    for target, args in TARGET_ARGS.items():
        if target != "spirv":
            out[target] = cross(spv, args, f"{label} -> {target}")
    return out


def hlsl_round_trip(hlsl: str, stage: str = "frag", label: str = "<hlsl>") -> tuple[str, dict]:
    """GLSL 330 (OpenGL) of an HLSL shader by way of glslang's HLSL front end, and the
    reflection of that SPIR-V. The stage inputs and the outputs get back the plain names the
    HLSL gives them (``stage_input.vTexCoord0`` -> ``vTexCoord0``), so they link with the core
    vertex shader by name."""
    spv = hlsl_to_spirv(hlsl, stage, label)
    refl = reflect(spv, label)
    args = ["--version", "330", "--no-es"]
    for io, key in (("in", "inputs"), ("out", "outputs")):
        for var in refl.get(key, []):
            plain = var["name"].rsplit(".", 1)[-1]
            # an element of an output array (Urho3D's `out vec4 fragData[1]`): `fragData_0`
            plain = re.sub(r"\[(\d+)\]$", r"_\1", plain) if io == "out" else plain
            # a GLSL identifier (a leading _ too: the dialect translation's colour output),
            # not one GLSL reserves (gl_ prefix, a double underscore)
            if not re.fullmatch(r"(?!gl_)[A-Za-z_]\w*", plain) or "__" in plain:
                raise RuntimeError(f"{label}: cannot name the stage {io}put {var['name']!r}")
            args += ["--rename-interface-variable", io, str(var["location"]), plain]
    return cross(spv, args, f"{label} -> GLSL 330"), refl
