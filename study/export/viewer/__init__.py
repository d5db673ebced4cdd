"""The calibrated water in a browser: ``viewer/`` of a calibration's output folder, a static page
that runs the exported GLSL ES 3.00 shaders (``shaders/gles300/``) in WebGL 2 on the
calibration's own inputs, beside the run's reference and port images.

The folder holds four files and needs nothing else: ``index.html`` (the page, from
``page.html``), ``viewer.js`` (the WebGL 2 code) and ``bound.js`` (a user's shader bound as the
GL check binds it), both copied as they are, and ``data.js``, one
``window.WATER_VIEWER_DATA = {...}`` assignment holding the shaders' text and every array as
base64 little-endian float32. Script files because Chromium, opened on a ``file://`` page,
neither fetches files nor uploads images to WebGL; a ``<script src>`` it loads.

``data.js`` (:func:`viewer_data`): the vertex and fragment shader text (the fitted file as
exported, and the ``#define SPIRV_CROSS_CONSTANT_ID_<id> <value>`` lines that give the start
constants), the inputs the GL check runs (the variant's prepared inputs with the exported LUT
and normal map; the maps derived from the normal map a shader reads, ``heightMap`` and
``slopeMoments`` with its mip levels, which the page uploads as they are), the matrices
column-major, the water quad, the camera, the animation rule and the run's reference / default
/ fitted images in GL row order (row 0 at the bottom). For a user's shader, ``bound``
(``user.bound_data``) instead of the study's textures: every uniform, texture and vertex
attribute the GL check binds for it on llvmpipe, with the geometry it draws (the water quad
after ``water.vert``, or the grid after the user's own vertex shader).
"""

from __future__ import annotations

import base64
import html
import json
import re
import string
from pathlib import Path

import numpy as np

from shaders_port import ShaderInputs
from shaders_port.inputs import normal_matrix, perspective_view_proj
from shaders_port.gl.renderer import MIPMAPPED
from shaders_port.pipeline.normal_maps import DERIVED_MAPS
from shaders_port.pipeline.texture import box_mip_chain
from shaders_port.variants import get_variant

from ..._io import read_exr, repo_path
from ..shaders import read_calibration
from ..targets import target_file
from ..textures import with_exported_textures
from ...scene.reference import water_mask
from .user import user_parts

TEMPLATES = Path(__file__).parent
# uniforms and samplers rendered for the study's camera: a shader that reads one is tied to it
SCREEN_SPACE = ("sceneColor", "sceneDepth", "reflection_sampler", "o2v_projection_reflection",
                "screenSize", "gl_FragCoord")  # fmt: skip
# sampler name -> (ShaderInputs field, filter, repeat), as shaders_port.gl.renderer binds them
_TEXTURES = {
    "refractionTexture": ("refraction_texture", "linear", False),
    "worldYComponent": ("world_y", "nearest", False),
    "normalMap": ("normal_map", "linear", True),
    "fresnelLookup": ("fresnel_lut", "nearest", False),
    "worldYComponentReflection": ("refl_world_y", "nearest", False),
    "reflectionBottom": ("refl_texture", "linear", False),
    "sceneColor": ("scene_color", "linear", False),
    "sceneDepth": ("scene_depth", "nearest", False),
    "reflection_sampler": ("reflection_color", "linear", False),
}
_SPEC = re.compile(
    r"#define SPIRV_CROSS_CONSTANT_ID_(\d+) [^\n]*\n#endif\n(?:static )?const (float|int) (\w+) ="
)


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a, "<f4").tobytes()).decode("ascii")


def _texture(a: np.ndarray, filt: str = "nearest", repeat: bool = False) -> dict:
    """A (H, W[, C]) float array (rows in GL order) as data.js holds it."""
    a = np.asarray(a, np.float32)
    return {
        "width": int(a.shape[1]),
        "height": int(a.shape[0]),
        "channels": 1 if a.ndim == 2 else int(a.shape[2]),
        "filter": filt,
        "repeat": repeat,
        "data": _b64(a),
    }


def _col_major(m: np.ndarray) -> list[float]:
    return [float(x) for x in np.asarray(m, np.float32).T.ravel()]


def spec_defines(frag: str, start: dict) -> str:
    """``#define SPIRV_CROSS_CONSTANT_ID_<id> <value>`` lines giving the exported GLSL ES
    fragment shader ``frag`` the constants ``start`` (GLSL name -> number or list; a colour
    ``waterColor`` sets ``waterColor_r`` ... ``waterColor_a``), one per specialization constant
    of ``frag`` that ``start`` names. Floats are written with a decimal point or an exponent
    (GLSL ES converts no int to float)."""
    lines = []
    for spec_id, kind, name in _SPEC.findall(frag):
        base, _, comp = name.rpartition("_")
        if name in start:
            value = start[name]
        elif base in start and isinstance(start[base], (list, tuple)) and comp in "rgba":
            value = start[base]["rgba".index(comp)]
        else:
            continue
        lit = str(int(value)) if kind == "int" else repr(float(value))
        lines.append(f"#define SPIRV_CROSS_CONSTANT_ID_{spec_id} {lit}\n")
    return "".join(lines)


def with_spec_defines(frag: str, start: dict) -> str:
    """``frag`` with the :func:`spec_defines` of ``start`` after its ``#version`` line."""
    head, sep, rest = frag.partition("\n")
    return head + sep + spec_defines(frag, start) + rest


def tied_names(frag: str, bindings: dict | None = None) -> list[str]:
    """The screen-space inputs (``SCREEN_SPACE``) the fragment shader text ``frag`` reads, by
    their own names or through ``bindings`` (the shader's name -> the study's input)."""
    bound = {s for n, s in (bindings or {}).items() if re.search(rf"\b{re.escape(n)}\b", frag)}
    return [n for n in SCREEN_SPACE if re.search(rf"\b{n}\b", frag) or n in bound]


def viewer_data(inputs: ShaderInputs, vert: str, frag: str, frag_default: str, images: dict,
                camera: dict, animation: dict, bindings: dict | None = None) -> dict:  # fmt: skip
    """The object ``data.js`` assigns. ``inputs``: as the exported shader runs them (float32);
    ``vert`` / ``frag`` / ``frag_default``: GLSL ES 3.00 text, the last with the start
    constants;
    ``images``: name -> (H, W, 3) linear RGB in image order (row 0 at the top), ``scored``
    (H, W) 1 where the reference sees the water at the study's camera; ``camera``:
    position, target, fov_y (degrees), near, far, orbit (bool), pitch_deg; ``animation``:
    velocities (4, 2) texture units per second; ``bindings``: a user's shader's sampler and
    uniform names -> the study's inputs."""
    i = inputs
    x0, z0, x1, z1 = i.water_rect
    quad = [[x, 0.0, z, x / i.normal_tile, z / i.normal_tile]
            for x, z in ((x0, z0), (x1, z0), (x0, z1), (x1, z1))]  # fmt: skip
    textures = {}
    for sampler, (field, filt, repeat) in _TEXTURES.items():
        a = getattr(i, field)
        if a is None:
            continue
        if field == "fresnel_lut":
            a = a[None, :, :]  # N x 1
        textures[sampler] = _texture(a, filt, repeat)
    for sampler, texels in DERIVED_MAPS.items():  # the maps derived from the normal map it reads
        if not re.search(rf"\b{sampler}\b", frag):
            continue
        if sampler in MIPMAPPED:  # the levels given, uploaded as they are
            chain = box_mip_chain(texels(i.normal_map))
            textures[sampler] = {**_texture(chain[0], "trilinear", True),
                                 "levels": [_b64(lv) for lv in chain[1:]]}  # fmt: skip
        else:
            textures[sampler] = _texture(texels(i.normal_map), "linear", True)
    textures["reflectionTexture"] = {"size": int(i.cubemap.shape[1]), "data": _b64(i.cubemap)}
    if i.box_cubemap is not None:  # the local cube map of reflection = box
        textures["boxReflectionTexture"] = {
            "size": int(i.box_cubemap.shape[1]),
            "data": _b64(i.box_cubemap),
        }
    box = {k: None if getattr(i, k) is None else [float(v) for v in getattr(i, k)]
           for k in ("box_min", "box_max", "box_capture")}  # fmt: skip
    return {
        "width": int(i.width),
        "height": int(i.height),
        "shaders": {"vert": vert, "frag": frag, "frag_default": frag_default},
        "inputs": {
            "quad": [float(v) for row in quad for v in row],
            "normal_tile": float(i.normal_tile),
            "view_proj": _col_major(i.view_proj),
            "normal_matrix": [float(x) for x in normal_matrix(i.view_proj).T.ravel()],
            "tex_matrix0": _col_major(i.tex_matrix0),
            "tex_matrix1": _col_major(i.tex_matrix1),
            "reflection_view_proj": None
            if i.reflection_view_proj is None
            else _col_major(i.reflection_view_proj),
            "viewpos": [float(v) for v in i.viewpos],
            "lightpos": [float(v) for v in i.lightpos],
            "lightcolor": [float(v) for v in i.lightcolor],
            "waves": np.asarray(i.waves, np.float32).tolist(),
            **box,
        },
        "textures": textures,
        "images": {k: _texture(np.asarray(v, np.float32)[::-1]) for k, v in images.items()},
        "camera": camera,
        "animation": animation,
        "bindings": dict(bindings or {}),
    }


def write_viewer(folder: Path, data: dict, page: dict) -> Path:
    """``index.html``, ``viewer.js``, ``bound.js`` and ``data.js`` in ``folder`` (created);
    ``page``: the template's fields (``page.html``: title, errors, notes), HTML-escaped here
    except ``options``. Returns the path of ``index.html``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    (folder / "data.js").write_text(f"window.WATER_VIEWER_DATA = {text};\n", encoding="utf-8")
    for script in ("viewer.js", "bound.js"):
        (folder / script).write_text((TEMPLATES / script).read_text("utf-8"), "utf-8")
    fields = {k: v if k == "options" else html.escape(str(v), quote=False) for k, v in page.items()}
    page_text = string.Template((TEMPLATES / "page.html").read_text("utf-8")).substitute(fields)
    (folder / "index.html").write_text(page_text, encoding="utf-8")
    return folder / "index.html"


def _camera(exp, inputs: ShaderInputs, orbit: bool) -> dict:
    """The experiment's camera as the page orbits it; ``orbit`` only when the page's
    ``perspective_view_proj`` (near 0.05, far 100) rebuilds the inputs' matrix."""
    c = exp.section("camera")
    near, far = 0.05, 100.0
    vp = perspective_view_proj(c["position"], c["target"], fov_y_deg=c["fov_y"],
                               aspect=inputs.width / inputs.height, near=near, far=far)  # fmt: skip
    same = np.allclose(vp, inputs.view_proj, rtol=1e-5, atol=1e-6)
    off = np.asarray(c["position"], float) - np.asarray(c["target"], float)
    return {
        "position": [float(v) for v in c["position"]],
        "target": [float(v) for v in c["target"]],
        "fov_y": float(c["fov_y"]),
        "near": near,
        "far": far,
        "orbit": bool(orbit and same),
        "pitch_deg": round(float(np.degrees(np.arcsin(off[1] / np.linalg.norm(off)))), 1),
    }


def read_names(frag: str, names) -> list[str]:
    """Those of ``names`` the shader text ``frag`` reads (each as a whole word), in order."""
    return [n for n in names if re.search(rf"\b{re.escape(n)}\b", frag)]


# the study's inputs that do not move with the view: (names, what they are, in the page's words)
_WORLD_INPUTS = (
    (("refractionTexture", "worldYComponent"),
     "the ground seen from above, a top-down texture in world coordinates"),
    (("worldYComponentReflection", "reflectionBottom"),
     "the geometry above the water seen from below, a top-down texture in world coordinates"),
    (("reflectionTexture",), "the sky cube map, in world space"),
    (("boxReflectionTexture", "boxMin", "boxMax", "boxCapturePosition"),
     "the local cube map and its box, in world space"),
    (("normalMap",), "the normal map, laid on the water in world units"),
    (("fresnelLookup",), "the Fresnel table, a function of the angle alone"),
    (("lightpos", "lightcolor"), "the light, in world space"),
)  # fmt: skip


def views_note(frag: str) -> str:
    """The inputs of the study's shader text ``frag`` that do not move with the view, in words:
    only those it reads ("" for none)."""
    parts = []
    for names, what in _WORLD_INPUTS:
        read = read_names(frag, names)
        if read:
            head, _, tail = what.partition(", ")
            parts.append(f"{head} ({', '.join(read)}), {tail}")
    return f"It reads {'; '.join(parts)}." if parts else ""


def _camera_note(camera: dict, tied: list[str], fixed_note, frag: str = "") -> str:
    """The page's words on the camera; ``fixed_note(tied)``: why a fixed camera is fixed (the
    parts' ``fixed_note``); ``frag``: the shader text, whose view-independent inputs are named."""
    if camera["orbit"]:
        views = views_note(frag)
        return (
            "orbits the pool (drag on the image, or the sliders): everything this shader reads "
            "is independent of the view. " + (views + " " if views else "") + "The run's "
            "images are at the study's camera only."
        )
    return fixed_note(tied)


def _study_fixed_note(tied: list[str], frag: str = "") -> str:
    if tied:
        views = views_note(frag)
        return (
            f"fixed at the study's camera: this shader reads {', '.join(tied)}, rendered for "
            "that camera." + (" " + views if views else "")
        )
    return "fixed at the study's camera: the experiment's camera is not a plain look-at."


def _user_fixed_note(shader):
    pair = (
        f"; its own vertex shader {shader.vertex.label} draws the water grid with the "
        "study camera's matrices, baked into the data as the GL check binds them"
        if shader.vertex is not None
        else ""
    )
    return lambda tied: (
        "fixed at the study's camera: a user's shader, every uniform and texture bound as "
        f"the GL check (llvmpipe) binds them for that camera{pair}; the viewer does not "
        "know which of them its technique ties to the view."
    )


def start_constants(summary: dict) -> dict:
    """The start constants of the calibration ``summary`` (``constants.json``): its fitted
    ``constants`` (GLSL names) with each scalar of ``parameters`` (``'waterColor[1]'``, ...) at
    its ``default``, the value the fit started from."""
    start = {k: list(v) if isinstance(v, list) else v for k, v in summary["constants"].items()}
    for name, p in summary.get("parameters", {}).items():
        base, _, index = name.partition("[")
        if "default" not in p or base not in start:
            continue
        if index:
            start[base][int(index.rstrip("]"))] = p["default"]
        else:
            start[base] = p["default"]
    return start


def _images(out: Path, summary: dict) -> dict:
    """The run's images in ``out``: ``reference``, ``default`` and ``fitted`` (an animated
    calibration: ``fitted_frame0.exr`` and frame 0's reference where the cache still holds it),
    (H, W, 3) float32; those missing left out."""
    files = {k: out / f"{k}.exr" for k in ("reference", "default", "fitted")}
    if not files["fitted"].is_file():
        files["fitted"] = out / "fitted_frame0.exr"
    refs = summary.get("animation", {}).get("references") or []
    if not files["reference"].is_file() and refs:
        files["reference"] = repo_path(refs[0]["path"])
    return {k: read_exr(f)[0] for k, f in files.items() if f.is_file()}


def _scene_error(summary: dict) -> tuple[str, dict]:
    """(the scene the viewer shows, its ``{"rmse"|"flip": {"default", "fitted"}}``): a joint
    calibration's first scene (its ``error`` is scene -> start / fitted -> metrics)."""
    if "scenes" not in summary:
        return summary["experiment"], summary["error"]
    name = summary["scenes"][0]
    e = summary["error"][name]
    return name, {m: {k: e[k][m] for k in ("default", "fitted")} for m in ("rmse", "flip")}


class ViewerUnsupported(ValueError):
    """A calibration the viewer does not draw (its message says why and what to use)."""


def not_drawn(shader) -> str | None:
    """Why the viewer cannot draw a user's shader (``UserShader``; None when it can): it binds
    what the GL check binds on llvmpipe (``user.bound_data``), so a dialect no desktop OpenGL
    runs (GLSL ES 3.10 and later) has nothing to bind."""
    d = shader.dialect
    if not d.runs_on_desktop_gl:
        return (
            f"{shader.label} is {d.name}, which the GL check does not run on llvmpipe (the "
            "viewer binds what the GL check binds)"
        )
    return None


def _check_export(out: Path, summary: dict, stem: str) -> Path:
    """The GLSL ES 3.00 fragment file the viewer runs, ``shaders/gles300/<stem>.frag``;
    ViewerUnsupported when the export left that target out, FileNotFoundError when it is
    missing."""
    shaders = out / "shaders"
    frag_path = shaders / target_file("gles300", stem, "frag")
    left_out = summary.get("engine_targets", {}).get("gles300", {}).get("left_out")
    if left_out:
        raise ViewerUnsupported(
            f"the viewer runs the GLSL ES 3.00 export, which {summary['shader']} has none of "
            f"(left out: {left_out}); the other engine targets in {shaders} are written"
        )
    if not frag_path.is_file():
        raise FileNotFoundError(
            f"{frag_path} is missing: the viewer runs the GLSL ES 3.00 export, which needs "
            "glslang-tools and spirv-cross (scripts/setup.sh installs them); export again with "
            f"`study export {out / 'constants.json'} --out {out}`"
        )
    return frag_path


def _study_parts(out: Path, saved, inputs: ShaderInputs) -> dict:
    """What the viewer runs of a shader of the study's space calibrated in ``out``: the
    exported GLSL ES files (the fitted ``frag``, ``frag_default`` at ``start``), the inputs as
    the variant prepares them, the study's textures bound by name."""
    summary = saved.data
    frag_path = _check_export(out, summary, summary["shader"])
    frag = frag_path.read_text("utf-8")
    start = start_constants(summary)
    inputs = with_exported_textures(inputs, out / "shaders")
    return {
        "vert": (out / "shaders" / target_file("gles300", "water", "vert")).read_text("utf-8"),
        "frag": frag,
        "frag_default": with_spec_defines(frag, start),
        "inputs": get_variant(summary["shader"]).prepare_inputs(inputs),
        "bindings": {},
        "orbit": True,
        "data": {},
        "names": lambda data: ", ".join(read_names(frag, sorted(data["textures"]))),
        "fixed_note": lambda tied: _study_fixed_note(tied, frag),
    }


def _user_parts(out: Path, saved, inputs: ShaderInputs) -> dict:
    """What the viewer runs of the user's shader calibrated in ``out`` (``user.user_parts``)
    at its fitted and ``start`` values, bound as the GL check binds it (of the study's own
    textures, those the three.js page's pool is built from are kept); ViewerUnsupported for a
    dialect the GL check does not run, or without a headless OpenGL."""
    shader, summary = saved.user, saved.data
    why = not_drawn(shader)
    if why is not None:
        raise ViewerUnsupported(
            f"{why}; the GL check and the engine targets in {out / 'shaders'} are written"
        )
    _check_export(out, summary, summary["shader"].rsplit(".", 1)[0])
    start = {k: tuple(v) if isinstance(v, list) else v for k, v in start_constants(summary).items()}
    inputs = with_exported_textures(inputs, out / "shaders")
    try:
        u = user_parts(shader, out / "shaders", inputs, saved.constants, start)
    except RuntimeError as exc:  # no headless OpenGL: nothing to read the bindings from
        first = str(exc).splitlines()[0]
        raise ViewerUnsupported(f"{first} (the viewer binds what the GL check binds)") from None
    return {
        "vert": u["vert"],
        "frag": u["frag"],
        "frag_default": u["frag_default"],
        "inputs": inputs,
        "bindings": summary.get("declaration", {}).get("bindings", {}),
        "orbit": False,
        "data": {"bound": u["bound"]},
        # the shader's own textures are bound; the study's are kept for the three.js page's
        # pool (its ground colour and height seen from above, and the sky)
        "textures": ("refractionTexture", "worldYComponent", "reflectionTexture"),
        "names": lambda data: u["names"],
        "fixed_note": _user_fixed_note(shader),
    }


def calibration_viewer(out: Path, exp, inputs: ShaderInputs) -> Path:
    """``out/viewer/`` of the calibration in ``out`` (its ``constants.json``, ``shaders/``
    export and ``reference.exr`` / ``default.exr`` / ``fitted.exr``) of experiment ``exp``
    (frame 0 of an animated one) with its shader inputs ``inputs`` (at the experiment's
    resolution, before the variant's preparation). Returns the path of ``index.html``."""
    out = Path(out)
    saved = read_calibration(out / "constants.json")
    summary = saved.data
    kind = _user_parts if saved.user is not None else _study_parts
    parts = kind(out, saved, inputs)
    inputs, vert, frag = parts["inputs"], parts["vert"], parts["frag"]
    images = _images(out, summary)
    # where the reference sees the water (not a wall in front of it): the pixels the run scored
    images["scored"] = water_mask(exp, inputs.width, inputs.height).astype(np.float32)
    tied = tied_names(frag, parts["bindings"])
    camera = _camera(exp, inputs, orbit=parts["orbit"] and not tied)
    vel = np.asarray(exp.animation.velocities, np.float64)
    data = viewer_data(inputs, vert, frag, parts["frag_default"], images, camera,
                       {"velocities": vel.tolist()}, parts["bindings"])  # fmt: skip
    data.update(parts["data"])
    if "textures" in parts:
        data["textures"] = {k: v for k, v in data["textures"].items() if k in parts["textures"]}
    name, err = _scene_error(summary)
    flip = err["flip"]
    options = [
        ("live_fitted", "live: fitted shader (WebGL 2)"),
        ("live_default", "live: original constants (WebGL 2)"),
        ("reference", "reference (path traced)"),
        ("default", f"port, original constants (FLIP {flip['default']:.4f})"),
        ("fitted", f"port, fitted constants (FLIP {flip['fitted']:.4f})"),
    ]
    options = [(v, t) for v, t in options if v.startswith("live_") or v in images]
    page = {
        "title": f"{name}: {summary['shader']}, calibrated",
        "options": "".join(f'<option value="{v}">{html.escape(t)}</option>' for v, t in options),
        "flip_default": f"{err['flip']['default']:.4f}",
        "flip_fitted": f"{err['flip']['fitted']:.4f}",
        "rmse_default": f"{err['rmse']['default']:.4f}",
        "rmse_fitted": f"{err['rmse']['fitted']:.4f}",
        "time_max": "20",
        "pitch_deg": camera["pitch_deg"],
        "orbit_drag": "" if camera["orbit"] else " (off: see the camera below)",
        "inputs": parts["names"](data),
        "velocities": "; ".join(f"wave{k + 1} ({v[0]:g}, {v[1]:g})" for k, v in enumerate(vel)),
        "camera_note": _camera_note(camera, tied, parts["fixed_note"], frag),
        "provenance": f"Experiment {name}, {inputs.width}x{inputs.height} "
        f"pixels; written by study.export.viewer from {out.name}/.",
    }
    return write_viewer(out / "viewer", data, page)
