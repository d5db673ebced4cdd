"""The water shaders in WGSL (WebGPU): the export's OpenGL SPIR-V translated by naga.

naga, the shader translator of wgpu (npm ``naga-wasm``, pinned in ``package.json``, run by
Node.js through ``naga_wgsl.mjs``), reads Vulkan SPIR-V only, while the export's SPIR-V is
OpenGL's: loose (block-less) uniforms, combined image samplers, GL clip space. :func:`translate`
therefore takes a module through

1. ``spirv-cross --vulkan-semantics --version 450``: the module as Vulkan GLSL;
2. :func:`vulkan_source`: that text made valid for Vulkan and WebGPU (below);
3. ``glslangValidator -V`` and ``spirv-val --target-env vulkan1.0``: Vulkan SPIR-V;
4. naga (:func:`naga`): the module read, validated and written as WGSL, the text tidied
   (``tidy`` of ``naga_wgsl.mjs``: naga's mangled function names shortened, override defaults
   as plain literals, the fragment shader's ``diagnostic`` directive, below), then parsed back
   and validated as it is written;
5. :func:`reflection`: what the WGSL binds (read from its text and from ``spirv-cross
   --reflect`` of the Vulkan SPIR-V), every uniform member with its byte offset.

Step 4 takes every file of an export in one Node.js process (:func:`of_vulkan`): Node's
start-up costs more than a translation. :func:`check` validates WGSL text alone.

What step 2 changes, all in ``@group(0)``:

* the loose uniforms of a stage become one std140 uniform block, ``FragUniforms`` at
  ``@binding(32)`` (:data:`BLOCK_BINDINGS`) read as ``frag_uniforms.<name>`` in the fragment
  shader, ``VertUniforms`` at ``@binding(33)`` (``vert_uniforms``) in the vertex shader;
* each combined sampler (``sampler2D normalMap``) becomes a texture keeping its GL binding and its
  name and a sampler ``_<name>_sampler`` at that binding + :data:`SAMPLER_OFFSET` (16); a block
  the shader declares itself keeps its GL binding; every GL binding must be below 16;
* the fitted constants stay specialization constants, which naga writes as WGSL ``override``
  declarations with ``@id(<constant_id>)`` and the fitted value as default. Every read of one
  passes through an identity function (``spec_float(BumptexMult)``), and a constant built from
  them (``const vec4 waterColor = vec4(waterColor_r, ...)``) becomes a macro: glslang would
  otherwise fold an expression of them (``vec2(chromaticDispersion)``) into a
  specialization-constant instruction, which naga refuses;
* the vertex shader's ``main`` becomes ``_glMain``, called by a ``main`` that moves the GL clip
  z in [-w, w] to WebGPU's [0, w] and negates y, undoing the flip naga's SPIR-V reader makes
  (it assumes Vulkan's y-down clip space): the WGSL's clip space is WebGPU's, y up;
* a fragment shader reading ``gl_FragCoord`` gets GL's window y (origin at the bottom) from
  the member ``glFramebufferHeight`` (:data:`FRAMEBUFFER_HEIGHT`) of its uniform block, and
  ``dFdy`` keeps GL's sign (WebGPU's framebuffer y points down);
* (in the WGSL, step 5) a fragment shader opens with ``diagnostic(off,
  derivative_uniformity);``: the raymarch samples textures (implicit derivatives) in loops that a
  texel's value ends, which GLSL accepts and WGSL's uniformity analysis refuses (Chrome's
  compiler, Tint, does; naga does not check it).

Every tool failure raises RuntimeError with the tool's log (as ``tools``), naming the file.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from . import tools as S

REPO = Path(__file__).resolve().parents[2]
NAGA_SCRIPT = Path(__file__).with_name("naga_wgsl.mjs")
NAGA_PACKAGE = REPO / "node_modules" / "naga-wasm"
GROUP = 0
SAMPLER_OFFSET = 16  # the sampler of the texture at binding b is at b + 16
MAX_GL_BINDING = 16  # a texture's or block's GL binding must be below this
BLOCK_BINDINGS = {"frag": 32, "vert": 33}
BLOCK_NAMES = {"frag": "FragUniforms", "vert": "VertUniforms"}
BLOCK_VARS = {"frag": "frag_uniforms", "vert": "vert_uniforms"}
FRAMEBUFFER_HEIGHT = "glFramebufferHeight"
SPEC_HELPER = "spec_{}"  # identity function per type: no folding of specialization constants

_LAYOUT = re.compile(r"^layout\((?P<args>[^)]*)\)\s*")
_SPEC = re.compile(r"^layout\(constant_id\s*=\s*\d+\)\s*const\s+(\w+)\s+(\w+)\s*=")
_CONST = re.compile(r"^const\s+(?P<type>\w+)\s+(?P<name>\w+)\s*=\s*(?P<expr>.+);$", re.S)
_UNIFORM = re.compile(
    r"^uniform\s+(?:(?:highp|mediump|lowp)\s+)?(?P<type>\w+)\s+(?P<name>\w+)\s*"
    r"(?P<array>\[[^\]]*\])?\s*;$"
)
_COMBINED = re.compile(
    r"^(?P<kind>[iu]?)sampler(?P<dim>1D|2D|3D|Cube|2DRect|1DArray|2DArray|CubeArray|2DMS|"
    r"2DMSArray|Buffer)(?P<shadow>Shadow)?$"
)
_OPAQUE = re.compile(r"^[iu]?(sampler|texture|image|subpassInput)|^atomic_uint$")
_FUNCTION_START = re.compile(r"^[A-Za-z_][\w\s]*\s+[A-Za-z_]\w*\s*\(.*\)$")
_NOT_FUNCTIONS = ("layout", "uniform", "struct", "in ", "out ", "const ")
_GLSL_IO = {"float": "f32", "int": "i32", "uint": "u32", "bool": "bool"}


# -- the tools -------------------------------------------------------------------------------------
def missing_tools() -> list[str]:
    """What the WGSL target needs and this machine lacks (Node.js, the npm package naga-wasm),
    each with how to install it."""
    out = []
    if shutil.which("node") is None:
        out.append("node (apt-get install nodejs; bash scripts/setup.sh)")
    if not (NAGA_PACKAGE / "package.json").is_file():
        out.append(f"{NAGA_PACKAGE.relative_to(REPO)} (bash scripts/setup.sh: npm ci)")
    return out


def _node(mode: str, files: list[tuple[bytes, str]], suffix: str) -> list[dict]:
    """``node naga_wgsl.mjs <mode>`` on ``files`` ((content, label) pairs) in one process: its
    answer per file; RuntimeError with naga's report naming the first file that fails."""
    node = shutil.which("node")
    if node is None or not (NAGA_PACKAGE / "package.json").is_file():
        raise RuntimeError(f"the WGSL target needs {', '.join(missing_tools())}")
    if not files:
        return []
    with tempfile.TemporaryDirectory(prefix="wgsl.") as d:
        paths = []
        for k, (data, _) in enumerate(files):
            paths.append(Path(d) / f"{k}{suffix}")
            paths[-1].write_bytes(data)
        res = subprocess.run([node, str(NAGA_SCRIPT), mode, *map(str, paths)],
                             capture_output=True, text=True, timeout=600, check=False)  # fmt: skip
    if res.returncode != 0:
        raise RuntimeError(f"naga failed on {files[0][1]}:\n{res.stdout}{res.stderr}".rstrip())
    out = json.loads(res.stdout)
    for (_, label), r in zip(files, out):
        if "error" in r:
            raise RuntimeError(f"naga failed on {label}:\n{r['error']}".rstrip())
    return out


def naga(modules: list[tuple[bytes, str]]) -> list[str]:
    """WGSL of each Vulkan SPIR-V module of ``modules`` ((binary, label) pairs) by naga, all in
    one Node.js process (``naga_wgsl.mjs --json``: each module read, validated and written);
    RuntimeError with naga's report, naming the first that fails."""
    return [r["wgsl"] for r in _node("--json", modules, ".spv")]


def check(texts: list[tuple[str, str]]) -> None:
    """Each WGSL text of ``texts`` ((text, label) pairs) parsed and validated by naga, in one
    Node.js process (``naga_wgsl.mjs --check``); RuntimeError naming the first refused."""
    _node("--check", [(t.encode("utf-8"), label) for t, label in texts], ".wgsl")


def vulkan_spirv(source: str, stage: str, label: str = "<source>") -> bytes:
    """Vulkan SPIR-V 1.0 of a Vulkan GLSL source (``glslangValidator -V``), validated by
    ``spirv-val --target-env vulkan1.0``."""
    with tempfile.TemporaryDirectory(prefix="wgsl.") as d:
        src, spv = Path(d) / f"shader.{stage}", Path(d) / "shader.spv"
        src.write_text(source, encoding="utf-8")
        S._run(
            ["glslangValidator", "-V", "--target-env", "vulkan1.0", "-S", stage, "-o", str(spv),
             str(src)], label,
        )  # fmt: skip
        S._run(["spirv-val", "--target-env", "vulkan1.0", str(spv)], f"the SPIR-V of {label}")
        return spv.read_bytes()


# -- OpenGL GLSL (spirv-cross's) to Vulkan GLSL for naga -------------------------------------------
def split_source(text: str) -> tuple[list[str], list[str]]:
    """spirv-cross's GLSL cut into its global declarations (each a whole statement: a
    preprocessor line, a one-line declaration, or a struct or block with its braces) and the
    functions (every line from the first function's signature on: spirv-cross writes all
    declarations first, each function as a signature line followed by a ``{`` line)."""
    lines = text.split("\n")
    items, current, depth = [], [], 0
    for k, line in enumerate(lines):
        s = line.strip()
        if depth == 0 and not current:
            nxt = lines[k + 1].strip() if k + 1 < len(lines) else ""
            if not s:
                continue
            if s.startswith("#"):
                items.append(s)
                continue
            if nxt == "{" and _FUNCTION_START.match(s) and not s.startswith(_NOT_FUNCTIONS):
                return items, lines[k:]
        current.append(line)
        depth += line.count("{") - line.count("}")
        if depth == 0 and s.endswith(";"):
            items.append("\n".join(current).strip())
            current = []
    if current:
        raise RuntimeError(f"unfinished declaration in spirv-cross's output: {current[0]!r}")
    return items, []


def layout_args(text: str) -> dict:
    """``layout(a = 1, b, c = 2)``'s arguments as ``{'a': '1', 'b': None, 'c': '2'}``."""
    out = {}
    for part in (p.strip() for p in text.split(",")):
        if part:
            key, eq, value = part.partition("=")
            out[key.strip()] = value.strip() if eq else None
    return out


def _layout_text(args: dict) -> str:
    return "layout(" + ", ".join(k if v is None else f"{k} = {v}" for k, v in args.items()) + ")"


def _binding(args: dict, what: str, label: str) -> int:
    """The GL binding of a resource's layout arguments, checked against the WGSL numbering."""
    b = args.get("binding")
    if b is None or not b.isdigit() or int(b) >= MAX_GL_BINDING:
        raise RuntimeError(
            f"WGSL translation of {label}: {what} has GL binding {b}; the WGSL numbering "
            f"(sampler = texture + {SAMPLER_OFFSET}) needs a binding below {MAX_GL_BINDING}"
        )
    return int(b)


def _uniform(item: str, stage: str, label: str, out: dict) -> None:
    """One ``uniform`` declaration of spirv-cross's GLSL into ``out``: a combined sampler split
    into texture and sampler (``out['decls']``, ``out['renames']``), a block of the shader's own
    kept in ``@group(0)``, a plain uniform made a member of the stage's block
    (``out['members']``)."""
    m = _LAYOUT.match(item)
    args = layout_args(m["args"]) if m else {}
    rest = item[m.end() :] if m else item
    if "{" in rest:  # a block the shader declares: same binding, in group 0
        args.pop("location", None)
        args["set"] = str(GROUP)
        _binding(args, f"the block {rest.split()[1]}", label)
        out["decls"].append(f"{_layout_text(args)} {rest}")
        return
    u = _UNIFORM.match(rest)
    if u is None:
        raise RuntimeError(f"WGSL translation of {label}: cannot read the declaration {item!r}")
    gtype, name, array = u["type"], u["name"], u["array"] or ""
    if not _OPAQUE.match(gtype):
        out["members"].append(f"    {gtype} {name}{array};")
        out["renames"][name] = f"{BLOCK_VARS[stage]}.{name}"
        return
    c = _COMBINED.match(gtype)
    if c is None or array:
        raise RuntimeError(
            f"WGSL translation of {label}: the uniform {gtype} {name}{array} has no WGSL form "
            "here (combined samplers only, no arrays of them)"
        )
    b = _binding(args, f"the texture {name}", label)
    sampler = "samplerShadow" if c["shadow"] else "sampler"
    smp = f"_{name}_sampler"
    out["decls"].append(
        f"layout(set = {GROUP}, binding = {b}) uniform {c['kind']}texture{c['dim']} {name};"
    )
    out["decls"].append(
        f"layout(set = {GROUP}, binding = {b + SAMPLER_OFFSET}) uniform {sampler} {smp};"
    )
    out["renames"][name] = f"{gtype}({name}, {smp})"


def _replace_names(body: str, renames: dict) -> str:
    """``body`` with each identifier of ``renames`` (not a member access) replaced, once."""
    if not renames:
        return body
    pat = re.compile(r"(?<![.\w])(" + "|".join(map(re.escape, renames)) + r")\b")
    return pat.sub(lambda m: renames[m[1]], body)


def _wrap_calls(body: str, names, before: str, after: str) -> str:
    """``body`` with each call ``name(...)`` of ``names`` written ``before name(...) after``
    (parentheses balanced)."""
    pat = re.compile(r"(?<![.\w])(" + "|".join(names) + r")\s*\(")
    out, pos = [], 0
    for m in pat.finditer(body):
        if m.start() < pos:
            continue
        depth, k = 1, m.end()
        while depth:
            if k >= len(body):
                raise RuntimeError(f"unbalanced call of {m[1]} in spirv-cross's output")
            depth += {"(": 1, ")": -1}.get(body[k], 0)
            k += 1
        inner = _wrap_calls(body[m.end() : k - 1], names, before, after)
        out += [body[pos : m.start()], f"{before}{m[1]}({inner}){after}"]
        pos = k
    return "".join(out) + body[pos:]


def _derived_constant(item: str, spec: dict, macros: set, used: set) -> str:
    """A ``const`` declaration built from specialization constants (name -> GLSL type in
    ``spec``) or from such macros (``macros``) as a macro of its own (added to ``macros``), each
    specialization constant read through its identity function (its type added to ``used``);
    a declaration built from neither is returned as is."""
    c = _CONST.match(item)
    names = [*spec, *macros]
    if c is None or not re.search(r"(?<![.\w])(" + "|".join(names) + r")\b", c["expr"]):
        return item

    def through(m: re.Match) -> str:
        used.add(spec[m[1]])
        return f"{SPEC_HELPER.format(spec[m[1]])}({m[1]})"

    expr = re.sub(r"(?<![.\w])(" + "|".join(spec) + r")\b", through, c["expr"])
    macros.add(c["name"])
    return f"#define {c['name']} ({expr})"


def vulkan_source(glsl: str, stage: str, label: str = "<source>") -> str:
    """spirv-cross's Vulkan GLSL of an OpenGL module (``--vulkan-semantics``) rewritten as the
    module doc says (uniform block, split samplers, constants, clip space, window y): the GLSL
    that glslang turns into the SPIR-V naga reads. RuntimeError for a declaration it cannot
    carry over."""
    items, body_lines = split_source(glsl)
    body = "\n".join(body_lines)
    out = {"decls": [], "members": [], "renames": {}}
    spec = {m[2]: m[1] for m in (_SPEC.match(i) for i in items) if m}
    used, macros, block_at = set(), set(), None
    for item in items:
        arr = _OUT_ARRAY.match(item)
        if arr:  # WGSL's entry points take no arrays: one output per element
            decls, body = _split_output_array(arr, body, label)
            out["decls"] += decls
        elif re.match(r"^(layout\([^)]*\)\s*)?uniform\b", item):
            before = len(out["members"])
            _uniform(item, stage, label, out)
            if len(out["members"]) > before and block_at is None:
                block_at = len(out["decls"])
        elif spec and item.startswith("const "):
            out["decls"].append(_derived_constant(item, spec, macros, used))
        else:
            out["decls"].append(item)
    frag_coord = []
    if stage == "frag" and re.search(r"\bgl_FragCoord\b", body):
        out["members"].append(f"    float {FRAMEBUFFER_HEIGHT};")
        frag_coord.append(
            f"vec4 _glFragCoord()\n{{\n    return vec4(gl_FragCoord.x, {BLOCK_VARS[stage]}."
            f"{FRAMEBUFFER_HEIGHT} - gl_FragCoord.y, gl_FragCoord.zw);\n}}\n"
        )
        out["renames"]["gl_FragCoord"] = "_glFragCoord()"
    if out["members"]:
        block_at = len(out["decls"]) if block_at is None else block_at
        out["decls"].insert(
            block_at,
            f"layout(std140, set = {GROUP}, binding = {BLOCK_BINDINGS[stage]}) uniform "
            f"{BLOCK_NAMES[stage]}\n{{\n"
            + "\n".join(out["members"])
            + f"\n}} {BLOCK_VARS[stage]};",
        )
    # every read of a specialization constant through its identity function: glslang folds no
    # expression of them into a specialization-constant instruction naga would refuse
    for name, gtype in spec.items():
        out["renames"][name] = f"{SPEC_HELPER.format(gtype)}({name})"
        if re.search(rf"(?<![.\w]){name}\b", body):
            used.add(gtype)
    body = _stage_fixes(_replace_names(body, out["renames"]), stage, label)
    helpers = [f"{t} {SPEC_HELPER.format(t)}({t} x)\n{{\n    return x;\n}}\n" for t in sorted(used)]
    helpers += frag_coord
    head = [i for i in out["decls"] if i.startswith("#version")]
    rest = [i for i in out["decls"] if not i.startswith("#version")]
    return "\n".join([*head, "", *rest, "", *helpers, body.rstrip(), ""])


_OUT_ARRAY = re.compile(
    r"^layout\(location\s*=\s*(?P<loc>\d+)\)\s*out\s+(?P<type>\w+)\s+(?P<name>\w+)"
    r"\s*\[(?P<n>\d+)\];$"
)


def _split_output_array(m: re.Match, body: str, label: str) -> tuple[list[str], str]:
    """An output array (``layout(location = L) out vec4 fragData[N];``, as Urho3D's GL3 path
    writes its colour) as N outputs ``fragData_<k>`` at locations L + k, and ``body`` with each
    ``fragData[k]`` renamed; RuntimeError where an element is chosen by a variable."""
    name, n, loc = m["name"], int(m["n"]), int(m["loc"])
    if re.search(rf"\b{name}\s*\[(?!\s*\d+\s*\])", body):
        raise RuntimeError(
            f"WGSL translation of {label}: the output array {name} is indexed by a variable; "
            "WGSL's entry points take no arrays (index it by constants)"
        )
    decls = [f"layout(location = {loc + k}) out {m['type']} {name}_{k};" for k in range(n)]
    return decls, re.sub(rf"\b{name}\s*\[\s*(\d+)\s*\]", rf"{name}_\1", body)


def _stage_fixes(body: str, stage: str, label: str) -> str:
    """The functions of a stage with GL's conventions kept on WebGPU: in a fragment shader
    ``dFdy`` negated (WebGPU's framebuffer y points down); in a vertex shader ``main`` renamed
    ``_glMain`` and called by a ``main`` that moves the GL clip position to WebGPU's (z in
    [-w, w] -> [0, w]) and negates y, undoing the flip naga's SPIR-V reader adds."""
    if stage == "frag":
        return _wrap_calls(body, ("dFdy", "dFdyFine", "dFdyCoarse"), "(-", ")")
    if stage != "vert":
        return body
    if not re.search(r"^void main\(\)$", body, re.M):
        raise RuntimeError(f"WGSL translation of {label}: no `void main()` in the module")
    body = re.sub(r"^void main\(\)$", "void _glMain()", body, flags=re.M)
    return body.rstrip() + (
        "\n\nvoid main()\n{\n    _glMain();\n"
        "    gl_Position.z = (gl_Position.z + gl_Position.w) * 0.5;\n"
        "    gl_Position.y = -gl_Position.y;\n}\n"
    )


# -- naga's WGSL -----------------------------------------------------------------------------------
def vulkan_module(gl_spirv: bytes, stage: str, label: str = "<spirv>") -> bytes:
    """Steps 1 to 3 of the module doc: the Vulkan SPIR-V naga reads, made from the export's
    OpenGL SPIR-V of one stage (``stage`` 'vert' or 'frag')."""
    glsl = S.cross(gl_spirv, ["--vulkan-semantics", "--version", "450", "--no-es"], label)
    return vulkan_spirv(vulkan_source(glsl, stage, label), stage, label)


def of_vulkan(jobs: list[tuple[bytes, str, str]]) -> list[tuple[str, dict]]:
    """Steps 4 and 5 of the module doc for each (Vulkan SPIR-V of :func:`vulkan_module`,
    stage, label) of ``jobs``, naga run once for all: the WGSL (checked as written) and its
    reflection (:func:`reflection`). RuntimeError with naga's report, naming the file
    (``label``)."""
    texts = naga([(vk, label) for vk, _, label in jobs])
    return [
        (wgsl, reflection(wgsl, S.reflect(vk, label), stage, label))
        for wgsl, (vk, stage, label) in zip(texts, jobs)
    ]


def translate_many(jobs: list[tuple[bytes, str, str]]) -> list[tuple[str, dict]]:
    """The WGSL and the reflection of each (OpenGL SPIR-V, stage, label) of ``jobs``
    (:func:`vulkan_module`, then :func:`of_vulkan`). RuntimeError with the log of the tool that
    failed, naming the file (``label``)."""
    return of_vulkan(
        [(vulkan_module(spv, stage, label), stage, label) for spv, stage, label in jobs]
    )


def translate(gl_spirv: bytes, stage: str, label: str = "<spirv>") -> tuple[str, dict]:
    """The WGSL of one stage of the export (its OpenGL SPIR-V, ``stage`` 'vert' or 'frag') and
    its reflection: :func:`translate_many` of one file."""
    return translate_many([(gl_spirv, stage, label)])[0]


# -- reflection ------------------------------------------------------------------------------------
_SCALARS = {"f32": 4, "i32": 4, "u32": 4, "f16": 2, "bool": 4}


def _round(x: int, a: int) -> int:
    return -(-x // a) * a


def type_layout(wgsl_type: str, structs: dict) -> tuple[int, int]:
    """(alignment, size) in bytes of a WGSL type in the uniform address space (the WGSL
    specification's rules; a struct of ``structs``, name -> members as :func:`_structs`)."""
    t = wgsl_type.replace(" ", "")
    if t in _SCALARS:
        return _SCALARS[t], _SCALARS[t]
    if m := re.fullmatch(r"vec([234])<(\w+)>", t):
        n, s = int(m[1]), _SCALARS[m[2]]
        return (2 if n == 2 else 4) * s, n * s
    if m := re.fullmatch(r"mat([234])x([234])<(\w+)>", t):
        a, s = type_layout(f"vec{m[2]}<{m[3]}>", structs)
        return a, int(m[1]) * _round(s, a)
    if m := re.fullmatch(r"array<(.+),(\d+)>", t):
        a, s = type_layout(m[1], structs)
        a = _round(a, 16)
        return a, int(m[2]) * _round(s, a)
    if t in structs:
        return struct_layout(t, structs)[:2]
    raise RuntimeError(f"no uniform layout for the WGSL type {wgsl_type!r}")


def struct_layout(name: str, structs: dict) -> tuple[int, int, list]:
    """(alignment, size, [(member, type, offset, size)]) of a WGSL struct in the uniform
    address space, ``@align`` / ``@size`` attributes honoured."""
    offset, align, rows = 0, 16, []
    for member, wtype, attrs in structs[name]:
        a, s = type_layout(wtype, structs)
        a, s = int(attrs.get("align", a)), int(attrs.get("size", s))
        offset = _round(offset, a)
        rows.append((member, wtype, offset, s))
        offset, align = offset + s, max(align, a)
    return align, _round(offset, align), rows


def _structs(wgsl: str) -> dict:
    """Name -> [(member, WGSL type, {attribute: value})] of every struct of naga's WGSL."""
    out = {}
    for m in re.finditer(r"^struct (\w+) \{\n(.*?)\n\}", wgsl, re.M | re.S):
        rows = []
        for line in m[2].split("\n"):
            f = re.fullmatch(r"\s*((?:@\w+(?:\([^)]*\))?\s+)*)(\w+): (.+),", line)
            if f is None:
                raise RuntimeError(f"cannot read the member {line.strip()!r} of struct {m[1]}")
            attrs = dict(re.findall(r"@(\w+)\(([^)]*)\)", f[1]))
            rows.append((f[2], f[3].strip(), attrs))
        out[m[1]] = rows
    return out


def _io(vk: dict, key: str, params: dict) -> list[dict]:
    """The stage inputs or outputs of the Vulkan reflection: GLSL name, WGSL name where the
    entry point has it (``params``: location -> name), WGSL type, location."""
    rows = []
    for v in sorted(vk.get(key, []), key=lambda v: v["location"]):
        m = re.fullmatch(r"([iu]?)vec([234])|(\w+)", v["type"])
        scalar = _GLSL_IO.get(m[3] or {"": "float", "i": "int", "u": "uint"}[m[1]], v["type"])
        wtype = f"vec{m[2]}<{scalar}>" if m[2] else scalar
        row = {"name": v["name"], "location": v["location"], "type": wtype}
        if v["location"] in params:
            row["wgsl_name"] = params[v["location"]]
        rows.append(row)
    return rows


def reflection(wgsl: str, vk: dict, stage: str, label: str = "<wgsl>") -> dict:
    """What the WGSL of one stage binds: ``bindings`` (group, binding, name, kind 'texture' |
    'sampler' | 'uniform', WGSL type, the GLSL name it comes from), ``uniform_blocks`` (each
    block's struct, binding, size and members: WGSL name, GLSL name, WGSL type, byte offset
    and size, a matrix's column stride), ``overrides`` (id, name, type, default), ``inputs``
    and ``outputs`` (locations). Read from naga's WGSL; the offsets checked against
    ``vk``, ``spirv-cross --reflect`` of the SPIR-V naga read (RuntimeError if they differ)."""
    structs = _structs(wgsl)
    vk_ubos = {u["binding"]: u for u in vk.get("ubos", [])}
    bindings, blocks = [], []
    decl = re.compile(r"@group\((\d+)\) @binding\((\d+)\)\s*var(?:<(\w+)>)?\s+(\w+):\s*([^;]+);")
    for g, b, space, name, wtype in decl.findall(wgsl):
        g, b, wtype = int(g), int(b), wtype.strip()
        kind = space or ("sampler" if wtype.startswith("sampler") else "texture")
        glsl = re.sub(r"^_(\w+)_sampler$", r"\1", name) if kind == "sampler" else name
        if kind == "uniform":
            glsl = vk_ubos[b]["name"]
        bindings.append({"group": g, "binding": b, "name": name, "kind": kind, "type": wtype,
                         "glsl": glsl})  # fmt: skip
        if kind == "uniform":
            blocks.append(_block(name, wtype, b, vk_ubos[b], vk, structs, label))
    overrides = [
        {
            "id": int(i),
            "name": n,
            "type": t,
            "default": json.loads(v) if t != "bool" else v == "true",
        }
        for i, n, t, v in re.findall(r"^@id\((\d+)\) override (\w+): (\w+) = ([^;]+);$", wgsl, re.M)
    ]
    entry = re.search(r"^@(vertex|fragment)\s*\nfn main\((.*?)\)\s*(?:->|\{)", wgsl, re.M | re.S)
    params = {}
    if entry:
        params = {int(loc): n for loc, n in re.findall(r"@location\((\d+)\)[^:]*?(\w+):", entry[2])}
    return {
        "stage": {"vert": "vertex", "frag": "fragment"}[stage],
        "entry_point": "main",
        "bindings": sorted(bindings, key=lambda r: (r["group"], r["binding"])),
        "uniform_blocks": blocks,
        "overrides": sorted(overrides, key=lambda o: o["id"]),
        "inputs": _io(vk, "inputs", params),
        "outputs": _io(vk, "outputs", {}),
    }


def _block(var: str, struct: str, binding: int, ubo: dict, vk: dict, structs, label) -> dict:
    """One uniform block of :func:`reflection`: naga's struct beside the SPIR-V block."""
    align, size, rows = struct_layout(struct, structs)
    members = vk["types"][ubo["type"]]["members"]
    if len(members) != len(rows) or any(r[2] != m["offset"] for r, m in zip(rows, members)):
        raise RuntimeError(
            f"WGSL translation of {label}: naga laid out {struct} differently from the SPIR-V "
            f"block: {[(r[0], r[2]) for r in rows]} against "
            f"{[(m['name'], m['offset']) for m in members]}"
        )
    out = []
    for (name, wtype, offset, msize), m in zip(rows, members):
        row = {"name": name, "glsl": m["name"], "type": wtype, "offset": offset, "size": msize}
        if mm := re.fullmatch(r"mat[234]x([234])<(\w+)>", wtype.replace(" ", "")):
            a, s = type_layout(f"vec{mm[1]}<{mm[2]}>", structs)
            row["matrix_stride"] = _round(s, a)
        out.append(row)
    return {"name": struct, "var": var, "group": GROUP, "binding": binding, "size": size,
            "members": out}  # fmt: skip
