"""The binding sheet of one engine target: what the application must bind, and what it means.

Built from ``spirv-cross --reflect`` of the shaders of the target (textures, samplers, uniforms,
their blocks and offsets, stage inputs and outputs with their locations, specialization
constants; for WGSL its own reflection, ``shaders_port.spirv.wgsl.reflection``: ``bindings``,
``uniform_blocks``, ``overrides``) and from :data:`MEANINGS`, the experiment's meaning and units
of each name (an engine input's, ``shaders_port.spirv.engine_inputs.ENGINE_INPUTS``, for the
names it adds).
"""

from __future__ import annotations

import re

import numpy as np

from shaders_port.spirv.engine_inputs import ENGINE_ALIASES, ENGINE_INPUTS
from shaders_port.spirv.engine_names import MEANINGS as VERTEX_MEANINGS

# name in the GLSL -> what the application binds there (units, conventions of the study)
MEANINGS = {
    "refractionTexture": "linear RGB of the ground under the water seen from straight above "
    "(orthographic top-down render); bilinear, clamp to edge",
    "worldYComponent": "world-space Y (height, world units) of the ground under the water, the "
    "same top-down view (R32F); nearest, clamp to edge",
    "normalMap": "world-space wave normals encoded 0.5 n + 0.5 (r = x, g = y, b = z) in the "
    "water plane; bilinear, repeat; ship `textures/normal_map.exr`",
    "reflectionTexture": "sky cube map, linear RGB, GL face order +X -X +Y -Y +Z -Z; bilinear",
    "fresnelLookup": "N x 1 Fresnel table indexed by cos(theta) in [0, 1]: r = transmission, "
    "g = reflection; nearest, clamp; ship `textures/fresnel_lut.exr`",
    "worldYComponentReflection": "world-space Y of the geometry above the water seen from below "
    "(top-down, R32F; below the water plane where empty); nearest, clamp",
    "reflectionBottom": "linear RGB of that geometry seen from below; bilinear, clamp",
    "sceneColor": "linear RGB of the scene without the water, this camera (screen space)",
    "sceneDepth": "window-space depth in [0, 1] of that view (the GL depth buffer, 1 where "
    "nothing was drawn)",
    "reflection_sampler": "linear RGB of the scene above the water seen by the mirrored camera",
    "boxReflectionTexture": "local cube map: the scene without the water (walls, sky without the "
    "sun) seen from boxCapturePosition, linear RGB, GL face order, the texel of d holding the "
    "scene in d * (1, -1, 1); bilinear, clamp",
    "boxMin": "lower corner of the box of the pool's walls, world units",
    "boxMax": "upper corner of that box, world units; its y is the walls' top (above it: sky)",
    "boxCapturePosition": "where boxReflectionTexture was captured, world units",
    "uTextureMatrix0": "world (x, y, z, 1) -> (s, t) of refractionTexture and worldYComponent "
    "(the top-down camera's texture matrix)",
    "uTextureMatrix1": "world -> (s, t) of worldYComponentReflection and reflectionBottom",
    "uModelViewProjectionMatrix": "object -> clip space of the camera (GL clip, z in [-w, w])",
    "uModelViewProjectionMatrixInverse": "its inverse",
    "uNormalMatrix": "normal matrix of the view (upper 3 x 3 of the view rotation)",
    "o2v_projection_reflection": "world -> clip space of the mirrored camera (clip plane y = 0)",
    "WaterTransformationMatrix": "object -> world of the water quad (must keep it in a plane "
    "y = const: the depth comparisons assume a horizontal water plane)",
    "viewpos": "camera position, world units",
    "lightpos": "light (sun) position, world units",
    "lightcolor": "linear RGB of the specular highlight",
    "screenSize": "framebuffer width, height in pixels",
    "wave1": "offset of normal-map layer 1 (texture units: the quad's texcoord is (x, z) / tile)",
    "wave2": "offset of normal-map layer 2",
    "wave3": "offset of normal-map layer 3",
    "wave4": "offset of normal-map layer 4",
    "aVertex": "vertex attribute: object-space position of the water quad (w = 1)",
    "aMultiTexCoord0": "vertex attribute: normal-map texcoord, (x, z) / normal tile",
    "vTexCoord0": "varying: normal-map coordinate of layer 1 (vertex -> fragment)",
    "vTexCoord1": "varying: layer 2",
    "vTexCoord2": "varying: layer 3",
    "vTexCoord3": "varying: layer 4",
    "varyingVecWorldPosition": "varying: world position on the water plane",
    "varyingVecEye": "varying: vector to the camera, world space",
    "varyingVecLight": "varying: vector to the light, world space",
    "fragColor": "output: linear RGB (+ alpha) of the water",
    "gl_Position": "output: clip-space position",
}
_NOTES = {
    "hlsl": [
        "Entry point `main`; stage inputs and outputs are `TEXCOORD<location>` semantics "
        "(the vertex outputs and the pixel inputs share the numbering), the colour `SV_Target0`.",
        "Each texture comes with a `SamplerState _<name>_sampler` in the same register number.",
        "The loose uniforms form each stage's `$Global` constant buffer (offsets above).",
        "Matrices: the HLSL multiplies `mul(v, M)` with default (column_major) packing, so upload "
        "each GL matrix by rows (its transpose in GL order). The HLSL round trip on llvmpipe "
        "checks exactly this layout.",
        "Constants: `#define SPIRV_CROSS_CONSTANT_ID_<id> <value>` before the source overrides "
        "one.",
        "Clip space: the vertex shader writes GL's clip position (z in [-w, w]). Direct3D and "
        "Unity take z in [0, w]: give it a projection made for them (Unity: "
        "`GL.GetGPUProjectionMatrix(P, renderIntoTexture)`), which is `z' = 0.5 (z + w)`.",
        "Rows: the shipped textures, uploaded row 0 first, are addressed alike in every API. A "
        "texture the engine renders itself (the top-down renders, a reflection or scene "
        "buffer) has its first row at the top in Direct3D, at the bottom in GL: flip t of its "
        "texture matrix (`t -> 1 - t`: `[[1,0,0,0],[0,-1,0,1],[0,0,1,0],[0,0,0,1]]` times "
        "`uTextureMatrix0`), or render it with the flipped projection Unity uses for "
        "`renderIntoTexture`.",
    ],
    "gles300": [
        "`#version 300 es` (WebGL2); uniforms and samplers are bound by name "
        "(`gl.getUniformLocation`; a sampler to the texture unit of your choice).",
        "Constants: `#define SPIRV_CROSS_CONSTANT_ID_<id> <value>` after `#version` overrides one.",
        "Precision: `precision mediump float` is the file's default, and every uniform, input "
        "and sampler the shader reads is declared `highp`; WebGL 2 then computes at 32 bits.",
        "Float textures: sampling a float texture (`RGB32F`, `R32F`) linearly needs "
        "`OES_texture_float_linear`; rendering into one needs `EXT_color_buffer_float`.",
        "`fragColor` is linear RGB: encode it (sRGB) for display.",
    ],
    "msl": [
        "Entry points `main0` (vertex and fragment); argument indices `[[texture(n)]]`, "
        "`[[sampler(n)]]`, `[[buffer(n)]]` as in the function signatures (read them there: "
        "SPIRV-Cross numbers them in declaration order).",
        "Varyings are `[[user(locn<location>)]]`, the same numbering in both stages.",
        "Constants are function constants `[[function_constant(<id>)]]` with the fitted value as "
        "fallback: set one with `MTLFunctionConstantValues` to override it.",
        "No Metal compiler runs here: this target is generated and reflected only.",
    ],
    "wgsl": [
        "Everything is in `@group(0)`: each texture at its GL binding (below 16), its sampler "
        "`_<texture>_sampler` at that binding + 16, the fragment shader's uniforms in one "
        "uniform buffer `FragUniforms` at `@binding(32)`, the vertex shader's in `VertUniforms` "
        "at `@binding(33)` (std140 offsets above; a matrix column by column, columns 16 bytes "
        "apart, a `mat3x3` too). naga appends `_` to a name ending in a digit (`wave1_`).",
        "Entry points `main` (`@vertex`, `@fragment`); the stages link by `@location`, the "
        "numbering of the other targets.",
        "Clip space is WebGPU's (y up, z in [0, w]): the vertex shader converts the GL clip "
        "position it computes, so the matrices are the GL ones above and row 0 of the target "
        "texture is the top of the image. A fragment shader reading `gl_FragCoord` takes the "
        "framebuffer's height in `glFramebufferHeight` (GL's window y, from the bottom).",
        "Constants are `override` declarations with `@id(<id>)`, the fitted values as "
        'defaults: set one per pipeline with `constants: {"<id>": value}` in the stage of '
        "`createRenderPipeline` (by id: WebGPU takes the name of an override without an id only).",
        "The linear float textures (`rgba32float`, `r32float` ...) need the device feature "
        "`float32-filterable`; every texture is sampled with `textureSample`, so bind them as "
        '`sampleType: "float"` with `filtering` samplers (nearest or linear as listed). '
        "WebGPU filters a cube map across its faces (seamless), desktop GL here each face on "
        "its own: a sky continuous at its seams looks the same.",
    ],
    "spirv": [
        "OpenGL-semantics SPIR-V (`glslangValidator -G`): bindings and locations as listed; "
        "loose uniforms are set by location (`glUniform*`, GL_ARB_gl_spirv).",
        "Constants are specialization constants (`VkSpecializationInfo` / "
        "`glSpecializeShader` override one by its id); the defaults are the fitted values.",
    ],
}


def _meaning(name: str) -> str:
    base = name.rsplit(".", 1)[-1]
    base = re.sub(r"^_(\w+)_sampler$", r"\1", base)
    m = MEANINGS.get(base, "")
    engine = ENGINE_ALIASES.get(base, (base,))[0]  # an engine input (docs/engine-inputs.md)
    if not m and engine in ENGINE_INPUTS:
        m = ENGINE_INPUTS[engine][1]
    return f"sampler of {base}" if not m and base != name else m


def _rows(title: str, header: str, rows: list[str]) -> list[str]:
    if not rows:
        return []
    cols = header.count("|") - 1
    return [f"**{title}**", "", header, "|" + "---|" * cols, *rows, ""]


def _shader_section(path: str, refl: dict) -> list[str]:
    """The tables of one shader file's reflection."""
    lines = [f"### `{path.rsplit('/', 1)[-1].removesuffix('.reflect.json')}`", ""]
    tex = [
        f"| `{t['name']}` | {t['type']} | {t.get('binding', '')} | {_meaning(t['name'])} |"
        for key in ("textures", "separate_images", "separate_samplers")
        for t in refl.get(key, [])
    ]
    lines += _rows("Textures and samplers", "| name | type | binding | meaning |", tex)
    bind = [
        f"| `{b['name']}` | {b['kind']} | {b['type']} | @group({b['group']}) "
        f"@binding({b['binding']}) | {_meaning(b['glsl'])} |"
        for b in refl.get("bindings", [])
    ]
    lines += _rows("Bindings", "| name | kind | type | where | meaning |", bind)
    uni = [
        f"| `{m['name']}` | {m['type']} | {blk['name']} @binding({blk['binding']}), offset "
        f"{m['offset']}, size {m['size']} | {_meaning(m['glsl'])} |"
        for blk in refl.get("uniform_blocks", [])
        for m in blk["members"]
    ]
    for ubo in refl.get("ubos", []):
        for m in refl["types"][ubo["type"]]["members"]:
            layout = f"offset {m['offset']}" + (", row-major" if m.get("row_major") else "")
            uni.append(
                f"| `{m['name']}` | {m['type']} | {ubo['name']}, {layout} | {_meaning(m['name'])} |"
            )
    uni += [
        f"| `{u['name']}` | {u['type']} | by name | {_meaning(u['name'])} |"
        for u in refl.get("loose_uniforms", [])
    ]
    lines += _rows("Uniforms", "| name | type | where | meaning |", uni)
    io = [
        f"| {key[:-1]} | `{v['name']}` | {v['type']} | {v['location']} | {_meaning(v['name'])} |"
        for key in ("inputs", "outputs")
        for v in refl.get(key, [])
    ]
    lines += _rows("Stage inputs and outputs", "| | name | type | location | meaning |", io)
    over = [
        f"| {o['id']} | `{o['name']}` | {o['type']} | {_fmt(o['default'])} |"
        for o in refl.get("overrides", [])
    ]
    lines += _rows("Overrides", "| id | name | type | default |", over)
    return lines


def _fmt(value) -> str:
    """A constant as the shortest text that reads back as the same float32 (ints as ints)."""
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return np.format_float_positional(np.float32(value), unique=True, trim="0")


STATUS_WORDS = {
    "fitted": "fitted",
    "bound": "fitted, at its range's bound",
    "frozen": "held: not identified by the reference",
    None: "held at the experiment's value (not fitted)",
}


def _spec_scalar(name: str, values: dict) -> tuple[str, object]:
    """A specialization constant's name (``waterColor_g``) -> (its GLSL scalar name
    ``waterColor[1]``, its value in ``values``, ``{GLSL name: value}``)."""
    if name in values:
        return name, values[name]
    base, comp = name.rsplit("_", 1)
    i = "rgba".index(comp)
    return f"{base}[{i}]", values[base][i]


def constants_lines(spec: dict, constants, fit: dict | None) -> list[str]:
    """The constants section: each specialization constant the shader reads (id -> name in
    ``spec``) with its value and whether it was fitted; ``fit``: {"status": {GLSL scalar name:
    status of ``study.fit.calibrate``}, "reads": GLSL names the shaders read (None: all)}."""
    if not spec:
        return []
    fit = fit or {}
    status, reads = fit.get("status") or {}, fit.get("reads")
    values = constants if isinstance(constants, dict) else constants.to_glsl_dict()
    rows, unread = [], []
    for sid, name in sorted(spec.items()):
        scalar, value = _spec_scalar(name, values)
        if reads is not None and scalar.split("[")[0] not in reads:
            unread.append(f"`{name}` ({sid})")
            continue
        word = STATUS_WORDS.get(status.get(scalar), status.get(scalar))
        mark = "**" if status.get(scalar) in ("fitted", "bound") else ""
        rows.append(f"| {sid} | `{name}` | {mark}{_fmt(value)}{mark} | {word} |")
    n_fit = sum(1 for s in status.values() if s in ("fitted", "bound"))
    lines = [
        "## Constants",
        "",
        "Already in the source, as the defaults of specialization constants: nothing to set. "
        + (f"The {n_fit} fitted are in bold." if status else ""),
        "",
        "| id | name | value | |",
        "|---|---|---|---|",
        *rows,
        "",
    ]
    if unread:
        lines += [
            "Declared but read by no line of this shader (leave them): " + ", ".join(unread) + ".",
            "",
        ]
    return lines


# what a target does with a uniform's initializer (so each fitted uniform is declared without one)
_INITIALIZERS = {
    "gles300": "GLSL ES refuses a uniform initializer",
    "hlsl": "HLSL ignores the initializer of a constant-buffer member (the application fills "
    "the buffer)",
    "msl": "Metal takes the uniforms from a buffer the application fills",
    "spirv": "the uniforms are set by the application (`glUniform*`)",
    "wgsl": "WGSL has no uniform initializer: the application fills the uniform buffer",
}


def _uniform_types(reflections: dict) -> dict:
    """Name -> GLSL type of every plain uniform of the reflections (block members and loose)."""
    out = {}
    for refl in reflections.values():
        for ubo in refl.get("ubos", []):
            out.update({m["name"]: m["type"] for m in refl["types"][ubo["type"]]["members"]})
        out.update({u["name"]: u["type"] for u in refl.get("loose_uniforms", [])})
        for blk in refl.get("uniform_blocks", []):
            out.update({m["glsl"]: m["type"] for m in blk["members"]})
    return out


def material_lines(target: str, reflections: dict, constants, fit: dict | None) -> list[str]:
    """The section of the fitted constants that are uniforms of the target's shaders (a user's
    shader's uniforms, ``uniform float FOG_DENSITY = 0.35;`` or without initializer): each
    with its value, which the material must set (``constants``, ``fit`` as
    :func:`constants_lines`)."""
    values = constants if isinstance(constants, dict) else constants.to_glsl_dict()
    types = _uniform_types(reflections)
    names = [n for n in values if n in types]
    if not names:
        return []
    status = (fit or {}).get("status") or {}
    rows = []
    for n in names:
        v = values[n]
        text = ", ".join(_fmt(x) for x in v) if isinstance(v, (tuple, list)) else _fmt(v)
        text = f"{types[n]}({text})" if isinstance(v, (tuple, list)) else text
        st = status.get(n, status.get(f"{n}[0]"))
        mark = "**" if st in ("fitted", "bound") else ""
        rows.append(f"| `{n}` | {types[n]} | {mark}{text}{mark} | {STATUS_WORDS.get(st, st)} |")
    return [
        "## Uniforms the material sets",
        "",
        f"Constants of the shader that are uniforms: {_INITIALIZERS[target]}, so each is "
        "declared here without one. Set each to its value below, as the material sets its "
        "other uniforms (by name).",
        "",
        "| name | type | value | |",
        "|---|---|---|---|",
        *rows,
        "",
    ]


def _shown(v) -> str:
    return ", ".join(_fmt(x) for x in v) if isinstance(v, (list, tuple)) else _fmt(v)


def _user_meaning(glsl: str, kind: str, fit: dict) -> str:
    """A user's name's meaning on the sheet: the engine value its declaration gives it
    (``fit["engine_values"]``), or the input it is bound to (``fit["inputs"]``: name -> the
    study's or an engine input, with that input's description)."""
    if kind == "uniform" and glsl in fit.get("engine_values", {}):
        return f"engine value: set it to {_shown(fit['engine_values'][glsl])}"
    target = fit.get("inputs", {}).get(glsl)
    if target is None:
        return ""
    what = _meaning(target) or VERTEX_MEANINGS.get(target, ((), ""))[1]
    return f"bound to `{target}`" + (f": {what}" if what else "")


def _bind_rows(reflections: dict, values: dict | None = None, by_name: bool = False,
               fit: dict | None = None) -> list:  # fmt: skip
    """What the application binds, over every stage: textures, uniforms (a member of a stage's
    constant buffer once per stage) and the vertex attributes. ``values``: a user's shader's
    constants (GLSL name -> value): a uniform among them is marked with the value to set.
    ``by_name``: the target binds samplers by name (GLSL ES), not at a binding number. ``fit``:
    a user's ``engine_values`` and bound ``inputs`` (:func:`_user_meaning`)."""
    rows, seen = [], set()

    def add(name, kind, gtype, where, glsl=None):
        if (name, where) not in seen:  # a block member once per stage, at its offset there
            seen.add((name, where))
            glsl = glsl or name  # the GLSL name (WGSL's may differ): meaning and value
            meaning = _meaning(glsl) or _user_meaning(glsl, kind, fit or {})
            if values and glsl in values and kind == "uniform":
                meaning = f"fitted constant: set it to {_shown(values[glsl])}"
            rows.append(f"| `{name}` | {kind} | {gtype} | {where} | {meaning} |")

    ordered = sorted(reflections.items(), key=lambda kv: ".vert." not in kv[0])
    for path, refl in ordered:
        for key in ("textures", "separate_images"):
            for t in refl.get(key, []):
                where = "by name" if by_name else f"binding {t.get('binding', '')}"
                add(t["name"], "texture", t["type"], where)
        for b in refl.get("bindings", []):  # WGSL's
            if b["kind"] != "uniform":
                where = f"@group({b['group']}) @binding({b['binding']})"
                add(b["name"], b["kind"], b["type"], where, b["glsl"])
    for path, refl in ordered:
        stage = "vertex" if ".vert." in path else "fragment"
        for ubo in refl.get("ubos", []):
            for m in refl["types"][ubo["type"]]["members"]:
                where = f"{stage} {ubo['name']}, offset {m['offset']}"
                add(
                    m["name"],
                    "uniform",
                    m["type"],
                    where + (", row-major" * bool(m.get("row_major"))),
                )
        for u in refl.get("loose_uniforms", []):
            add(u["name"], "uniform", u["type"], "by name")
        for blk in refl.get("uniform_blocks", []):  # WGSL's
            for m in blk["members"]:
                where = f"{stage} {blk['name']} @binding({blk['binding']}), offset {m['offset']}"
                add(m["name"], "uniform", m["type"], where, m["glsl"])
        if stage == "vertex":
            for v in refl.get("inputs", []):
                add(v["name"].rsplit(".", 1)[-1], "vertex attribute", v["type"],
                    f"location {v['location']}")  # fmt: skip
    return rows


def binding_sheet(
    target: str, reflections: dict, spec: dict, constants, expects=(), fit=None
) -> tuple[str, str]:
    """The binding sheets of ``target``: (``BINDINGS.md``, the short one: what the shader
    expects, what to bind, the constants, the target's conventions; ``BINDINGS_FULL.md``: every
    shader's reflection as tables). From the reflections of its shaders (relative path ->
    JSON), the specialization constants (id -> name), the exported ``constants`` (a
    ``shaders_port.Constants`` or ``{GLSL name: value}``), ``expects`` (the lines of
    ``study.export.textures.expects_lines``) and ``fit`` (:func:`constants_lines`)."""
    files = sorted(p.removesuffix(".reflect.json") for p in reflections)
    out = [
        f"# Binding sheet: {target}",
        "",
        "Shaders: " + ", ".join(f"`{f.split('/', 1)[-1]}`" for f in files) + ". This is the short "
        "sheet; every stage input and output, with block offsets, is in `BINDINGS_FULL.md`, and "
        "the raw reflection in `*.reflect.json`, beside it.",
        "",
        *expects,
        "## What to bind",
        "",
        "| name | kind | type | where | meaning |",
        "|---|---|---|---|---|",
        *_bind_rows(
            reflections,
            constants if isinstance(constants, dict) else None,
            by_name=target == "gles300",
            fit=fit,
        ),  # fmt: skip
        "",
    ]
    out += constants_lines(spec, constants, fit)
    out += material_lines(target, reflections, constants, fit)
    out += [f"## Conventions of {target}", "", *[f"* {n}" for n in _NOTES[target]], ""]
    full = [f"# Binding sheet, in full: {target}", "", "The short sheet is `BINDINGS.md`.", ""]
    for path, refl in sorted(reflections.items()):
        full += _shader_section(path, refl)
    return "\n".join(out).rstrip() + "\n", "\n".join(full).rstrip() + "\n"
