"""The exported shaders in the engines' languages: GLSL ES 3.00, HLSL 5.0, Metal, SPIR-V and WGSL.

Each core GLSL file of an export (``core/<name>.<vert|frag>``, constants already written) is
translated with the real tools (``shaders_port.spirv.tools``: glslang to SPIR-V, SPIRV-Cross to each
target), the fitted constants carried as named specialization constants holding their values,
and checked as far as this machine can:

========  =======================================  =============================================
target    file                                     check at export
========  =======================================  =============================================
spirv     ``spirv/<name>.<stage>.spv``             ``spirv-val``
hlsl      ``hlsl/<name>.<stage>.hlsl``             glslang's HLSL front end (``-D -e main -V``)
                                                   to SPIR-V, ``spirv-val``
gles300   ``gles300/<name>.<stage>``               glslang's ES profile (``#version 300 es``)
msl       ``msl/<name>.<stage>.metal``             none: no Metal compiler here (generated and
                                                   reflected only)
wgsl      ``wgsl/<name>.<stage>.wgsl``             naga (npm ``naga-wasm``): the Vulkan SPIR-V
                                                   it is made from read and validated, the WGSL
                                                   parsed back and validated
========  =======================================  =============================================

WGSL (WebGPU) is made by ``shaders_port.spirv.wgsl`` from the SPIR-V by way of Vulkan GLSL and
naga, run by Node.js: the target is made when ``node`` and ``node_modules/naga-wasm``
(``bash scripts/setup.sh``) are there. Its reflection is its own (``wgsl.reflection``: every
``@group(0) @binding(n)``, the uniform blocks' members with their byte offsets, the
``override`` constants); the tests run it with wgpu on Mesa's lavapipe
(``study.export.wgsl_run``).

Beside them, per target, ``<name>.<stage>.reflect.json`` (``spirv-cross --reflect`` of the
module the target is made from: for HLSL the one glslang makes of the HLSL, so its registers
and its ``$Global`` offsets; for WGSL its own, above; elsewhere with the plain uniforms added
as ``loose_uniforms``, which the reflection of OpenGL SPIR-V leaves out), ``BINDINGS.md``, the
short binding sheet, and ``BINDINGS_FULL.md``, every shader's reflection as tables
(``study.export.bindings``).
``targets.json`` at the top of the export lists the files and the checks. The calibration's GL
check runs the HLSL on llvmpipe too (``study.export.gl_check.hlsl_check``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from shaders_port.spirv import tools as S
from shaders_port.spirv import wgsl as W
from shaders_port.spirv.tools import missing_tools

from .bindings import binding_sheet
from .textures import expects_lines, read_texture_record

TARGETS = ("gles300", "hlsl", "msl", "spirv", "wgsl")
CHECKS = {
    "spirv": "spirv-val",
    "hlsl": "glslangValidator -D -e main -V (HLSL front end) to SPIR-V, spirv-val",
    "gles300": "glslangValidator, ES profile (#version 300 es)",
    "msl": "none: no Metal compiler here (generated and reflected only)",
    "wgsl": "naga 30.0.1 (npm naga-wasm 30.1.0): the Vulkan SPIR-V read and validated, the WGSL "
    "written, parsed back and validated (the tests run it with wgpu on Mesa's lavapipe)",
}
_TOOLS = ("glslangValidator", "spirv-val", "spirv-cross")


def target_file(target: str, stem: str, stage: str) -> str:
    """Path of a translated shader inside the export, e.g. ``hlsl/water_refraction.frag.hlsl``."""
    ext = {"gles300": "", "hlsl": ".hlsl", "msl": ".metal", "spirv": ".spv", "wgsl": ".wgsl"}
    ext = ext[target]
    return f"{target}/{stem}.{stage}{ext}"


def resolve_targets(targets) -> tuple[str, ...]:
    """The targets to write: ``None`` -> every target whose tools are installed (none without
    glslang, SPIRV-Tools and SPIRV-Cross; no ``wgsl`` without Node.js and naga-wasm); otherwise
    the names given, checked. ValueError for an unknown name, RuntimeError naming the missing
    tools if targets are asked for and cannot be made."""
    if targets is None:
        if missing_tools(_TOOLS):
            return ()
        return tuple(t for t in TARGETS if t != "wgsl" or not W.missing_tools())
    targets = tuple(dict.fromkeys(targets))
    unknown = [t for t in targets if t not in TARGETS]
    if unknown:
        raise ValueError(f"unknown target(s) {unknown}; known: {', '.join(TARGETS)}")
    missing = missing_tools(_TOOLS) if targets else []
    missing += W.missing_tools() if "wgsl" in targets else []
    if missing:
        raise RuntimeError(
            f"the targets {list(targets)} need {', '.join(missing)}; run `bash scripts/setup.sh`, "
            "or export without them (--targets none)"
        )
    return targets


def _loose_uniforms(spv: bytes, stage: str, label: str) -> list[dict]:
    """The shader's plain (non-texture) uniforms, name and type: the reflection of OpenGL SPIR-V
    does not list them, so they are read from the ``$Global`` block glslang makes of the HLSL."""
    hlsl = S.cross(spv, S.TARGET_ARGS["hlsl"], label)
    refl = S.reflect(S.hlsl_to_spirv(hlsl, stage, label), label)
    return [
        {"name": m["name"], "type": m["type"]}
        for ubo in refl.get("ubos", [])
        for m in refl["types"][ubo["type"]]["members"]
    ]


def _one_file(fname: str, text: str, targets, vertex=None) -> tuple[dict, dict, dict, dict, list]:
    """Translate and check one core file: (relative path -> bytes, relative path of each
    reflection -> its JSON, target -> seconds, specialization constant id -> name, the WGSL
    still to make: [(Vulkan SPIR-V, stage, relative path)], see :func:`_finish_wgsl`). The
    reflection of a target other than HLSL and WGSL gets ``loose_uniforms``
    (:func:`_loose_uniforms`). ``vertex``: the text of the vertex shader the varyings'
    locations follow (None: the study's ``water.vert``)."""
    stem, stage = fname.rsplit(".", 1)
    files, reflections, seconds, wgsl = {}, {}, {}, []
    t0 = time.perf_counter()
    label = f"core/{fname}"
    linked = S.link_locations(S.specialize_constants(text), stage, vertex)
    spv = S.glsl_to_spirv(linked, stage, label)
    base = S.reflect(spv, label)
    spec = {c["id"]: c["name"] for c in base.get("specialization_constants", [])}
    loose = _loose_uniforms(spv, stage, label) if set(targets) - {"hlsl", "wgsl"} else []
    base_s = time.perf_counter() - t0
    for target in targets:
        t = time.perf_counter()
        label = target_file(target, stem, stage)
        if target == "spirv":
            data, refl = spv, {**base, "loose_uniforms": loose}
        elif target == "wgsl":  # naga runs once for every file (Node.js starts slowly)
            wgsl.append((W.vulkan_module(spv, stage, label), stage, label))
            seconds[target] = base_s + time.perf_counter() - t
            continue
        else:
            out = S.cross(spv, S.TARGET_ARGS[target], label)
            data = out.encode("utf-8")
            if target == "hlsl":
                refl = S.reflect(S.hlsl_to_spirv(out, stage, label), label)
            else:
                if target == "gles300":
                    S.es_compile_check(out, stage, label)
                refl = {**base, "loose_uniforms": loose}
        files[label] = data
        reflections[f"{target}/{stem}.{stage}.reflect.json"] = refl
        seconds[target] = base_s + time.perf_counter() - t
    return files, reflections, seconds, spec, wgsl


def _finish_wgsl(jobs: list, files: dict, reflections: dict) -> float:
    """The WGSL of ``jobs`` (:func:`_one_file`'s) and its reflections into ``files`` and
    ``reflections``, naga run once for all; returns the seconds it took."""
    t = time.perf_counter()
    for (_, _, label), (text, refl) in zip(jobs, W.of_vulkan(jobs)):
        files[label] = text.encode("utf-8")
        reflections[label.removesuffix(".wgsl") + ".reflect.json"] = refl
    return time.perf_counter() - t


def translate_targets(
    core_texts: dict, targets, constants, expects=(), fit=None
) -> tuple[dict, dict]:
    """Every core file of ``core_texts`` (file name -> GLSL) in every target: returns
    (relative path -> bytes to write, the ``targets.json`` manifest); ``expects`` and ``fit``
    go to the binding sheets (``study.export.bindings.binding_sheet``). Raises RuntimeError
    with the tool's log when a translation or a check fails (nothing is written then)."""
    files, manifest = {}, {"targets": {}, "seconds": {}}
    reflections, spec, wgsl = {}, {}, []
    vertex = next((t for f, t in core_texts.items() if f.endswith(".vert")), None)
    for fname, text in core_texts.items():
        f, r, s, c, w = _one_file(fname, text, targets, vertex)
        files.update(f)
        reflections.update(r)
        spec.update(c)
        wgsl += w
        for t, sec in s.items():
            manifest["seconds"][t] = manifest["seconds"].get(t, 0.0) + sec
    if wgsl:
        manifest["seconds"]["wgsl"] += _finish_wgsl(wgsl, files, reflections)
    for target in targets:
        mine = {k: v for k, v in reflections.items() if k.startswith(f"{target}/")}
        for path, refl in mine.items():
            files[path] = (json.dumps(refl, indent=1) + "\n").encode("utf-8")
        sheet, full = binding_sheet(target, mine, spec, constants, expects, fit)
        files[f"{target}/BINDINGS.md"] = sheet.encode("utf-8")
        files[f"{target}/BINDINGS_FULL.md"] = full.encode("utf-8")
        manifest["targets"][target] = {
            "files": sorted(p for p in files if p.startswith(f"{target}/")),
            "check": CHECKS[target],
        }
    files["targets.json"] = (json.dumps(manifest, indent=1) + "\n").encode("utf-8")
    return files, manifest


def sheets_of_export(folder, calibration: dict) -> dict:
    """The binding sheets of an export folder (``shaders/``) written again from its files: each
    target's ``*.reflect.json``, the specialization constants of the SPIR-V, GLSL ES or WGSL
    reflection, ``textures/textures.json`` and ``calibration``, the ``constants.json`` object
    the export was made from (its values, what was fitted, what the shader reads). Returns
    {relative path: Markdown}, the ``BINDINGS.md`` and ``BINDINGS_FULL.md`` of every target
    found: what the export wrote, for a page that shows them without running the tools."""
    folder = Path(folder)
    refl = {
        p.relative_to(folder).as_posix(): json.loads(p.read_text())
        for p in sorted(folder.glob("*/*.reflect.json"))
    }
    spec = {
        c["id"]: c["name"]
        for path, r in refl.items()
        if path.split("/")[0] in ("spirv", "gles300", "wgsl")
        for c in r.get("specialization_constants", r.get("overrides", []))
    }
    values = {**(calibration.get("constants_not_read") or {}).get("values", {})}
    values.update(calibration["constants"])
    fit = {
        "status": {n: p.get("status") for n, p in calibration.get("parameters", {}).items()},
        # what the shaders read: a calibration's ``constants`` hold those alone (a user's file
        # declares its own, none a specialization constant)
        "reads": set(calibration["constants"]),
        # a user's shader: the engine values its declaration sets, the inputs it binds (those
        # an engine's name binds by itself are not recorded: the export's sheet names them)
        "engine_values": (calibration.get("declaration") or {}).get("values", {}),
        "inputs": (calibration.get("declaration") or {}).get("bindings", {}),
    }
    record = read_texture_record(folder)
    expects = expects_lines(record) if record else []
    out = {}
    for target in TARGETS:
        mine = {k: v for k, v in refl.items() if k.startswith(f"{target}/")}
        if mine:
            short, full = binding_sheet(target, mine, spec, values, expects, fit)
            out[f"{target}/BINDINGS.md"], out[f"{target}/BINDINGS_FULL.md"] = short, full
    return out
