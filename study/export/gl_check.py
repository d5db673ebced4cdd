"""The exported core shader, and the exported HLSL by way of SPIR-V, run on the OpenGL that
headless EGL gives (Mesa llvmpipe on the CPU; a GPU's own driver where EGL picks it) against the
Dr.Jit port."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from shaders_port.gl.compare import compare_port_gl, is_gpu
from shaders_port.gl.renderer import GLRenderer
from shaders_port.gl.round_trip import TranslatedRenderer
from shaders_port.spirv.gl_run import context_support
from shaders_port.spirv.tools import hlsl_round_trip
from shaders_port.variants import get_variant


def gl_check(shader: str, inputs, constants, shaders_dir: Path) -> dict:
    """Run the exported core file of variant ``shader``, ``core/<shader>.frag``, exactly as
    written (its own constants block and ``#define`` lines, nothing added) on llvmpipe and
    compare it with the port of the variant with ``constants`` on the water pixels. Returns the
    figures of ``compare_port_gl`` and ``passed``."""
    variant = get_variant(shader)
    source = (shaders_dir / "core" / f"{variant.name}.frag").read_text()
    with GLRenderer(variant.shader, variant.prepare_inputs(inputs), source=source) as r:
        gl = gl_renderer_of(r)
        res = compare_port_gl(inputs, constants, shader, renderer=_OwnBlock(r),
                              gpu_addressing=is_gpu(gl))  # fmt: skip
        res["gl_renderer"] = gl
    return verdict(res, "the exported shader")


def gl_renderer_of(r) -> str | None:
    """The ``GL_RENDERER`` string of a renderer's context (e.g. "llvmpipe (LLVM 15.0.6, 256
    bits)" or "NVIDIA H200/PCIe/SSE2"), None where it has none."""
    try:
        return str(r.ctx.info["GL_RENDERER"])
    except (AttributeError, KeyError, TypeError):
        return None


NAMED_IN_REPORT = 10  # outliers named (with their reasons) in the check's figures


def verdict(res: dict, what: str) -> dict:
    """The figures of ``compare_port_gl`` kept in reports and ``passed`` by the GL check's
    thresholds (mean |diff| <= 1e-3, 99.9th percentile <= 1e-2, no unexplained outlier, all
    finite); ``explained`` (reason -> outliers), the largest outliers with their reasons
    (``outlier_pixels``), ``gl_renderer`` (which OpenGL ran it) and ``reason`` (None when it
    passed, else which threshold failed, in words); a warning on stderr if it fails."""
    out = {
        k: res[k]
        for k in (
            "mean_abs",
            "p999",
            "max_abs",
            "n_water",
            "n_outliers",
            "n_nonfinite",
            "unexplained",
        )
    }
    out["explained"] = dict(res.get("explained", {}))
    out["outlier_pixels"] = list(res.get("outlier_pixels", []))[:NAMED_IN_REPORT]
    out["gl_renderer"] = res.get("gl_renderer")
    why = _failures(res)
    out["passed"] = not why
    out["reason"] = "; ".join(why) if why else None
    if not out["passed"]:
        print(
            f"calibrate: WARNING: {what} on {out['gl_renderer'] or 'OpenGL'} does not match the "
            f"port: {out['reason']}: {out}",
            file=sys.stderr,
        )
    return out


def passes(res: dict) -> bool:
    """Whether ``res`` (``compare_port_gl``'s figures) passes the GL check's thresholds (none
    of :func:`_failures`): the verdict every run of an exported shader against the port takes,
    on llvmpipe, in the browser, on lavapipe."""
    return not _failures(res)


def _failures(res: dict) -> list[str]:
    """Which of the GL check's thresholds ``res`` (``compare_port_gl``'s figures) fails, in
    words; empty when it passes."""
    why = []
    if not (np.isfinite(res["mean_abs"]) and res["mean_abs"] <= GL_MEAN):
        why.append(f"mean |diff| {res['mean_abs']:.3g} > {GL_MEAN:g}")
    if not res["p999"] <= GL_P999:
        why.append(f"99.9th percentile {res['p999']:.3g} > {GL_P999:g}")
    if res["unexplained"]:
        left = [p for p in res.get("outlier_pixels", []) if not p["why"]]
        where = ", ".join(f"(y {p['y']}, x {p['x']}) {p['diff']:.3g}" for p in left[:3])
        over = res.get("explained", {}).get("gpu_over_cap")
        cap = f"; the GPU reasons would take {over} pixels, over 0.1 % of the water" if over else ""
        why.append(
            f"{res['unexplained']} pixel(s) over 1e-2 unexplained"
            + (f": {where}" if where else "")
            + cap
        )
    if res["n_nonfinite"]:
        why.append(f"{res['n_nonfinite']} non-finite pixel(s)")
    return why


def hlsl_check(shader: str, inputs, constants, shaders_dir: Path) -> dict:
    """The exported HLSL of variant ``shader`` (``hlsl/<shader>.frag.hlsl``) compiled back by
    glslang's HLSL front end, translated to GLSL 330 by SPIRV-Cross and run on llvmpipe, against
    the port with ``constants``: the figures and verdict of :func:`gl_check`."""
    variant = get_variant(shader)
    hlsl = (shaders_dir / "hlsl" / f"{variant.name}.frag.hlsl").read_text()
    glsl, refl = hlsl_round_trip(hlsl, "frag", f"hlsl/{variant.name}.frag.hlsl")
    prepared = variant.prepare_inputs(inputs)
    with TranslatedRenderer(variant.shader, prepared, glsl, refl) as r:
        gl = gl_renderer_of(r)
        res = compare_port_gl(inputs, constants, shader, renderer=_OwnBlock(r),
                              gpu_addressing=is_gpu(gl))  # fmt: skip
        res["gl_renderer"] = gl
    return verdict(res, "the exported HLSL (through glslang -D and SPIRV-Cross)")


class _OwnBlock:
    """A GLRenderer view whose render() ignores the constants (uses the exported block)."""

    def __init__(self, r):
        self.r = r

    def render(self, constants):
        return self.r.render(None)


GLES_NOT_RUN = (
    "not run on llvmpipe (the GL check runs the core file and the HLSL); compiled by glslang's "
    "ES profile"
)
GLES_NOTE = (
    f"{GLES_NOT_RUN}; the same files run in WebGL 2 in viewer/ (matched against the port in "
    "headless Chromium by the test suite)"
)


def target_checks(shader: str, inputs, constants, shaders_dir: Path) -> dict:
    """What checked each engine target of an export of variant ``shader``
    (:func:`manifest_checks`), with the HLSL round trip on llvmpipe against the port with
    ``constants`` (:func:`hlsl_check`)."""
    out = manifest_checks(shaders_dir)
    if "hlsl" in out:
        out["hlsl"]["llvmpipe"] = hlsl_check(shader, inputs, constants, shaders_dir)
    return out


def manifest_checks(shaders_dir: Path) -> dict:
    """What checked each engine target of an export (``targets.json``): the export's own check,
    and, for GLSL ES, why it did not run on llvmpipe. Empty when the export wrote no targets."""
    import json

    manifest = shaders_dir / "targets.json"
    if not manifest.is_file():
        return {}
    out = {}
    for target, entry in json.loads(manifest.read_text())["targets"].items():
        out[target] = {"files": entry["files"], "check": entry["check"]}
    if "gles300" in out:
        out["gles300"]["llvmpipe"] = GLES_NOTE
    return out


GL_MEAN, GL_P999 = 1e-3, 1e-2  # the thresholds of :func:`verdict` (mean, 99.9th percentile)


def gl_check_user(shader, inputs, values: dict, ours: dict) -> dict:
    """A user's shader (``shaders_port.spirv.user_shader.UserShader``) written back with ``values``
    and run on OpenGL (llvmpipe) against the executor's render ``ours`` (``ShaderOutput.numpy()``):
    mean and 99.9th percentile of the per-pixel max-over-channel |difference| on the pixels both
    cover, passed within ``GL_MEAN`` / ``GL_P999``; ``text``: which text ran (the file as
    written, or its core-profile translation, ``shaders_port.spirv.gl_run``), ``context``: on
    which context (e.g. "OpenGL 4.5 compatibility profile, llvmpipe ..."), ``why_translation``:
    why the file did not run as written; on an OpenGL ES context (the file at highp),
    ``own_precision``: the file at its own precision qualifiers (:func:`_own_precision`) and a
    failed check's ``note`` (:data:`ES_CUBE`). A file the driver rejects as written (what its
    dialect has that this driver lacks: an extension, ...) runs as its translation,
    ``why_translation`` quoting the driver. ``ran`` False (with ``why``) without a headless
    OpenGL; a shader OpenGL does not run (a GLSL ES 3.10 file where no ES context is made, a
    compile error of the driver in a text with no translation, or in both) is a failed check,
    ``passed`` False with ``why`` naming the file, and a warning on stderr."""
    rejected = ""
    try:
        rgba, mask, run, context = _render(shader, inputs, values)
    except ValueError as exc:  # dialects.ShaderError: a dialect no context here runs
        return _user_failed(str(exc))
    except RuntimeError as exc:
        msg = str(exc)
        if "rejected" not in msg:  # no headless OpenGL
            return {"ran": False, "why": msg.splitlines()[0], "passed": None}
        log = "; ".join([ln.strip() for ln in msg.splitlines()[1:] if "error" in ln.lower()][:3])
        if not shader.dialect.translated:  # nothing else to run
            return _user_failed(f"OpenGL (llvmpipe) rejected {shader.label}: {log}")
        # what this driver lacks of the file's dialect (an extension, ...): its translation runs
        about = context_support("es" if shader.dialect.es else "compatibility")[1]
        rejected = f"{about} rejected your file as written: {log}"
        print(f"calibrate: {shader.label}: {rejected}; its translation runs", file=sys.stderr)
        try:
            rgba, mask, run, context = _render(shader, inputs, values, as_written=False)
        except RuntimeError as exc2:
            log2 = [ln.strip() for ln in str(exc2).splitlines()[1:] if "error" in ln.lower()]
            return _user_failed(f"{rejected}; and its translation: {'; '.join(log2[:3])}")
    out = _user_verdict(rgba, mask, ours)
    out.update(text=run.what, context=context)
    if run.why:
        out["why_translation"] = rejected or run.why
    if run.kind == "es":
        out["own_precision"] = _own_precision(shader, inputs, values, ours)
    if not out["passed"]:
        if run.kind == "es":
            out["note"] = ES_CUBE
        print(
            f"calibrate: WARNING: {shader.label} ({run.what}) on {context} does not match the "
            f"executor: mean |diff| {out['mean_abs']:.3g}, 99.9th percentile {out['p999']:.3g}",
            file=sys.stderr,
        )
    return out


def _render(shader, inputs, values: dict, **how):
    """(rgba, mask, the ``GLRun``, the context in words) of ``shader.gl_renderer``."""
    with shader.gl_renderer(inputs, values, **how) as r:
        rgba, mask = r.render(None)
        return rgba, mask, r.gl_run, r.context


ES_CUBE = (
    "OpenGL ES filters cube maps across their faces (seamless); the executor, as desktop "
    "OpenGL with GL_TEXTURE_CUBE_MAP_SEAMLESS off, each face on its own"
)


def _own_precision(shader, inputs, values: dict, ours: dict) -> dict:
    """The GLSL ES file at its own precision qualifiers (``lowp``, ``mediump``, and the samplers'
    default ``lowp``; ``gl_run.plan(..., highp=False)``) on the ES context against ``ours``:
    ``mean_abs``, ``p999``, ``within`` the GL check's thresholds, and ``note`` when not (llvmpipe
    computes reduced precision at 16-bit float, the executor at 32-bit)."""
    with shader.gl_renderer(inputs, values, highp=False) as r:
        rgba, mask = r.render(None)
    res = _user_verdict(rgba, mask, ours)
    out = {"mean_abs": res["mean_abs"], "p999": res["p999"], "within": res["passed"]}
    if not res["passed"]:
        out["note"] = (
            f"at its own precision qualifiers llvmpipe differs from the executor by "
            f"{res['mean_abs']:.3g} on average, {res['p999']:.3g} at the 99.9th percentile: it "
            "computes lowp and mediump values at 16-bit float (GLSL ES samples at lowp unless "
            "told: `precision highp sampler2D;`, `precision highp samplerCube;`), the executor "
            "every value at 32-bit; a GPU that honours them differs alike"
        )
        print(f"calibrate: WARNING: {shader.label}: {out['note']}", file=sys.stderr)
    return out


def _user_failed(why: str) -> dict:
    """A GL check of a user's shader that could not run its shader: failed, with the reason
    (also on stderr)."""
    print(f"calibrate: WARNING: the GL check failed: {why}", file=sys.stderr)
    return {"ran": False, "why": why, "passed": False}


def hlsl_check_user(shader, inputs, values: dict, ours: dict, shaders_dir: Path) -> dict:
    """A user's shader's exported HLSL (``hlsl/<stem>.frag.hlsl`` of ``shaders_dir``) compiled
    back by glslang's HLSL front end, translated to GLSL 330 by SPIRV-Cross and run on llvmpipe
    against the executor's render ``ours``, as :func:`gl_check_user` judges it."""
    stem = shader.label.rsplit(".", 1)[0]
    hlsl = (shaders_dir / "hlsl" / f"{stem}.frag.hlsl").read_text()
    # a round trip that fails is the HLSL's failure (an error, as for the study's shaders); only
    # a missing headless OpenGL is "not run"
    glsl, refl = hlsl_round_trip(hlsl, "frag", f"hlsl/{stem}.frag.hlsl")
    try:
        with shader.gl_renderer(inputs, values, source=glsl, reflection=refl) as r:
            rgba, mask = r.render(None)
    except RuntimeError as exc:
        return {"ran": False, "why": str(exc).splitlines()[0], "passed": None}
    return _user_verdict(rgba, mask, ours)


def gles_check_user(shader, inputs, values: dict, ours: dict, shaders_dir: Path) -> dict:
    """A user's shader's exported GLSL ES 3.00 (``gles300/<stem>.frag`` of ``shaders_dir``,
    after the export's ``gles300`` vertex shader) on an OpenGL ES context of llvmpipe against
    the executor's render ``ours``, each uniform constant set to its value in ``values`` as the
    material sets it (the binding sheet's "Uniforms the material sets"): the figures and
    verdict of :func:`gl_check_user`, ``context``, and a failed check's ``note``; ``ran``
    False (with ``why``) where no ES context is made."""
    folder = Path(shaders_dir) / "gles300"
    stem = shader.label.rsplit(".", 1)[0]
    vstem = "water" if shader.vertex is None else shader.vertex.label.rsplit(".", 1)[0]
    frag = (folder / f"{stem}.frag").read_text(encoding="utf-8")
    vert = (folder / f"{vstem}.vert").read_text(encoding="utf-8")
    try:
        with shader.gl_renderer(inputs, values, source=frag, es=vert) as r:
            rgba, mask = r.render(None)
            context = r.context
    except RuntimeError as exc:
        return {"ran": False, "why": str(exc).splitlines()[0], "passed": None}
    out = {**_user_verdict(rgba, mask, ours), "context": context}
    if not out["passed"]:
        out["note"] = ES_CUBE
    return out


def _user_verdict(rgba: np.ndarray, mask: np.ndarray, ours: dict) -> dict:
    both = mask & (ours["mask"] > 0.5)
    d = np.abs(rgba[..., :3] - ours["color"]).max(-1)[both]
    mean, p999 = float(d.mean()), float(np.percentile(d, 99.9))
    return {
        "ran": True,
        "pixels": int(both.sum()),
        "mean_abs": mean,
        "p999": p999,
        "passed": bool(mean <= GL_MEAN and p999 <= GL_P999),
    }
