"""The calibrated water as a three.js material: ``threejs/`` of a calibration's output folder.

The folder is self-contained (opened from ``file://`` or served by any static server):

* ``water.js``: the ES module (a project template, copied as it is). It exports
  ``loadCalibration`` (the calibration read from the files the binding sheet names: the GLSL
  ES 3.00 export and ``shaders/textures/textures.json``, whose scene record holds the light,
  the waves' offsets and velocities and the top-down camera's extent and size, the values the
  sheet gives), ``loadWaterTextures`` (the shipped normal map and Fresnel LUT, read with three's
  ``EXRLoader``), ``WaterInputs`` (the top-down colour and world-height render targets and the
  sky cube map, built from the user's own three.js scene) and ``createWater`` (the water quad
  with the calibrated ``RawShaderMaterial``, the waves' clock and the per-camera uniforms).
* ``calibration.js``: one ``export default {...}``: the paths of those files, and what is not
  the calibration's but the scene's: the water rectangle, the sky cube map's size, the study's
  camera and resolution (the example's view); a user's shader's names for the inputs and its
  values; the ``#define`` lines of the start constants (for the tests); the three.js version
  the module was tested with.
* ``example.html`` and ``example.js``: the pool in three.js. Its floor and walls are a height
  field laid from the study's world-height texture, unlit, carrying the study's lit top-down
  colour; its sky is the study's cube map as three holds one (``scene.background``). The
  module builds every input of the water from that scene, as it would from a game's; the page
  also draws the water on the study's own images (``renderFloat({inputs: 'study'})``, for the
  tests). It reads the study's images from ``../viewer/data.js``.
* ``three.module.js``, ``three.core.js``, ``addons/``: three.js as the npm package ships it
  (``package.json`` pins the version; ``scripts/setup.sh`` installs it into ``node_modules/``).

A user's shader after the study's vertex shader is wired by its own names: a sampler or
uniform bound to an input the module builds is set as that input, a uniform constant or a
``value`` of its declaration to its value (:func:`user_wiring`). A shader that reads an input
the module does not build (the screen-space buffers, the box's cube map, the under-water
reflection renders, LEAN's slope moments, an engine input such as ``sky_cube``), or that brings
its own vertex shader, gets no folder: a :class:`ThreeUnsupported` names why. The parallax's
``heightMap`` is loaded from the shipped ``height_map.exr`` as the normal map is.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path


from ..._io import repo_path
from ..shaders import read_calibration
from ..targets import target_file
from ..textures import read_texture_record
from ..viewer import spec_defines, start_constants

TEMPLATES = Path(__file__).parent
FOLDER = "threejs"
# three.js files the folder holds: path in the folder -> path in the npm package
THREE_FILES = {
    "three.module.js": "build/three.module.js",
    "three.core.js": "build/three.core.js",
    "addons/loaders/EXRLoader.js": "examples/jsm/loaders/EXRLoader.js",
    "addons/libs/fflate.module.js": "examples/jsm/libs/fflate.module.js",
    "LICENSE": "LICENSE",
}
# the uniforms and samplers water.js sets: those of the study's refraction shaders
BUILT = frozenset(
    ("normalMap", "worldYComponent", "refractionTexture", "reflectionTexture", "fresnelLookup",
     "WaterTransformationMatrix", "viewpos", "lightpos", "lightcolor", "wave1", "wave2",
     "wave3", "wave4", "uModelViewProjectionMatrix", "uModelViewProjectionMatrixInverse",
     "uNormalMatrix", "uTextureMatrix0")
)  # fmt: skip
#: the maps derived from the normal map water.js binds when the calibration ships them:
#: textures.json's record -> sampler (LEAN's mipmapped slopeMoments is not among them)
DERIVED_SAMPLERS = {"height_map": "heightMap"}
_UNIFORM = re.compile(r"^\s*uniform\s+(?:(?:highp|mediump|lowp)\s+)?\w+\s+(\w+)\s*;", re.M)


class ThreeUnsupported(ValueError):
    """A calibration the three.js module does not wire (its message names the input)."""


def three_package() -> Path:
    """The npm package ``three`` the project pins (``node_modules/three``); FileNotFoundError
    with the fix when it is not installed."""
    pkg = repo_path("node_modules/three")
    if not (pkg / "package.json").is_file():
        raise FileNotFoundError(
            f"three.js is not installed ({pkg} is missing): run `bash scripts/setup.sh` (it "
            "runs `npm ci` for the version package-lock.json pins)"
        )
    return pkg


def three_version() -> str:
    """The installed three.js version (``node_modules/three/package.json``)."""
    return json.loads((three_package() / "package.json").read_text("utf-8"))["version"]


def uniform_names(*sources: str) -> list[str]:
    """The uniform and sampler names the GLSL texts ``sources`` declare, in order, once each."""
    seen: list[str] = []
    for text in sources:
        seen += [n for n in _UNIFORM.findall(text) if n not in seen]
    return seen


def lacking_inputs(vert: str, frag: str) -> list[str]:
    """The uniforms and samplers of the GLSL texts ``vert`` and ``frag`` that water.js does
    not set (not in ``BUILT``), in order."""
    return [n for n in uniform_names(vert, frag) if n not in BUILT]


def _own_vertex_refused(saved) -> None:
    """ThreeUnsupported for a user's shader with a vertex shader of its own."""
    user = saved.user
    if user is not None and user.vertex is not None:
        raise ThreeUnsupported(
            f"{saved.data['shader']} runs after its own vertex shader {user.vertex.label}, "
            "whose matrices and attributes the module does not build; wire the pair from its "
            "binding sheet (shaders/*/BINDINGS.md)"
        )


def user_wiring(saved, vert: str, frag: str) -> tuple[dict, dict]:
    """How water.js sets a user's shader (``saved``: its ``SavedCalibration``; ``vert``,
    ``frag``: the GLSL ES export it runs): (the shader's uniform and sampler names bound to an
    input the module builds -> that input's name, the uniforms the material sets -> their
    values: fitted uniform constants and the declaration's ``value`` lines). ThreeUnsupported
    for a shader with a vertex shader of its own (its names and attributes are the engine's)."""
    user = saved.user
    _own_vertex_refused(saved)
    bound = user.run_bindings()
    engine = user.engine_values()
    names, values = {}, {}
    for n in uniform_names(vert, frag):
        if n in BUILT:
            continue
        if bound.get(n) in BUILT:
            names[n] = bound[n]
        elif n in saved.constants or n in engine:
            v = saved.constants[n] if n in saved.constants else engine[n]
            values[n] = [float(x) for x in v] if isinstance(v, (list, tuple)) else float(v)
    return names, values


def _check_version(text: str) -> None:
    """ThreeUnsupported unless the GLSL ES text starts with ``#version 300 es`` (the module
    drops that line: three's ``glslVersion`` writes it, before its own ``#define`` lines)."""
    head = text.partition("\n")[0]
    if not head.startswith("#version 300 es"):
        raise ThreeUnsupported(f"the GLSL ES export starts {head!r}, not '#version 300 es'")


def _defines(frag: str, start: dict) -> dict:
    """``spec_defines`` lines as three's ``material.defines`` (name -> value text)."""
    out = {}
    for line in spec_defines(frag, start).splitlines():
        _, name, value = line.split(" ", 2)
        out[name] = value
    return out


def calibration_data(out: Path, exp, inputs) -> dict:
    """The object ``calibration.js`` exports for the calibration in ``out`` of the study's
    shader, with its shader ``inputs`` (``ShaderInputs`` at the experiment's resolution): the
    files ``loadCalibration`` reads (URLs relative to ``threejs/``) and the scene's layout
    (world units, +y up, the water plane at y = 0)."""
    saved = read_calibration(out / "constants.json")
    summary = saved.data
    shaders = out / "shaders"
    _own_vertex_refused(saved)  # before reading the study's vertex shader, which it has not
    stem = summary["shader"].rsplit(".", 1)[0] if saved.user is not None else summary["shader"]
    vert = (shaders / target_file("gles300", "water", "vert")).read_text("utf-8")
    frag = (shaders / target_file("gles300", stem, "frag")).read_text("utf-8")
    names, values = user_wiring(saved, vert, frag) if saved.user is not None else ({}, {})
    # the derived maps the calibration ships (textures.json's records) water.js binds too
    shipped = {
        DERIVED_SAMPLERS[k] for k in read_texture_record(shaders) or {} if k in DERIVED_SAMPLERS
    }
    bound = set(names) | set(values) | shipped
    lacking = [n for n in lacking_inputs(vert, frag) if n not in bound]
    if lacking:
        raise ThreeUnsupported(
            f"{summary['shader']} reads {', '.join(lacking)}, which the three.js module does "
            "not build (it builds the top-down renders, the sky cube map, the shipped textures "
            "and the camera's and light's uniforms)"
        )
    _check_version(vert)
    _check_version(frag)
    if (read_texture_record(shaders) or {}).get("scene") is None:
        raise FileNotFoundError(f"{shaders / 'textures' / 'textures.json'} has no scene record")
    wx0, wz0, wx1, wz1 = (float(v) for v in inputs.water_rect)
    cam = exp.section("camera")
    return {
        "threeVersion": three_version(),
        "shader": summary["shader"],
        "experiment": summary.get("experiment") or summary["scenes"][0],  # joint: the first
        # what loadCalibration reads: the files the binding sheet names
        "files": {
            "vert": f"../shaders/{target_file('gles300', 'water', 'vert')}",
            "frag": f"../shaders/{target_file('gles300', stem, 'frag')}",
            "textures": "../shaders/textures/textures.json",
        },
        # a user's file has no specialization constants: its module carries the fitted ones
        "startDefines": None if saved.user else _defines(frag, start_constants(summary)),
        "uniformNames": names,
        "values": values,
        "constants": summary["constants"],
        "water": {"rect": [wx0, wz0, wx1, wz1], "y": 0.0},
        "sky": {"size": int(inputs.cubemap.shape[1])},
        "camera": {
            "position": [float(v) for v in cam["position"]],
            "target": [float(v) for v in cam["target"]],
            "fovY": float(cam["fov_y"]),
            "near": 0.05,
            "far": 100.0,
        },
        "resolution": [int(inputs.width), int(inputs.height)],
    }


def write_threejs(out: Path, exp, inputs) -> Path:
    """``out/threejs/`` of the calibration in ``out`` (see the module's docstring), written
    into a temporary folder and moved into place whole. Returns the path of ``example.html``.
    ThreeUnsupported for a shader the module does not wire, FileNotFoundError without three.js
    or the GLSL ES export."""
    out = Path(out)
    data = calibration_data(out, exp, inputs)
    pkg = three_package()
    tmp = out / (FOLDER + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    for name, src in THREE_FILES.items():
        (tmp / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(pkg / src, tmp / name)
    for name in ("water.js", "example.html", "example.js"):
        shutil.copyfile(TEMPLATES / name, tmp / name)
    text = json.dumps(data, indent=1, allow_nan=False)
    (tmp / "calibration.js").write_text(
        "// Where water.js's loadCalibration finds the calibration, and the example's scene\n"
        "// (written by study/export/threejs).\n"
        f"export default {text};\n",
        "utf-8",
    )
    final = out / FOLDER
    shutil.rmtree(final, ignore_errors=True)
    tmp.rename(final)
    return final / "example.html"
