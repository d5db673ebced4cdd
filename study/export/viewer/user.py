"""A user's shader in the viewer: what the GL check binds for it, as ``data.js`` holds it.

The GL check draws a user's shader on llvmpipe (``UserShader.gl_renderer``): its fragment
shader after the study's ``water.vert`` on the water quad, or after the user's own vertex
shader on the water grid (``fit.vertex``), every uniform and sampler bound by its name, the
declaration's bindings and the engine inputs (``shaders_port.spirv.engine_inputs``) included,
in the world frame the shader declares (``// @study up z``). :func:`bound_data` runs that
renderer and reads back what it bound (``shaders_port.gl.record``), once with the fitted
values and once with the start values, and writes it down for ``viewer.js``, which binds the
list as it is: the page cannot bind anything the check did not.

``bound`` in ``data.js``: ``uniforms`` {"fitted" | "default": [{name, type (GLSL), value
(flat list: matrices column-major; a sampler's texture unit)}]}; ``textures`` [{unit, input,
uniforms, target '2d' | 'cube', width, height, channels, levels (2d: base64 float32 per mip
level, GL upload order) | faces (cube: six, GL face order), min_filter, mag_filter, wrap}];
``geometry`` {mode 'triangle_strip' | 'triangles', attributes {name: {size, data}}, indices
(base64 uint32, or null), depth_test, screen (the quad's plane under the screen's corners,
or null)}; ``clock`` {uniform name: 'wave1' ... 'wave4' | 'time'}, the uniforms the page's
clock moves; ``inactive``: the uniforms the GLSL ES files declare that the GL check's program
does not read (its linker removed them: read only for a vertex output no fragment input
takes), left at 0 by the page, which refuses any other uniform the list lacks.
"""

from __future__ import annotations

import base64
import re
import tempfile
from pathlib import Path

import numpy as np

from shaders_port.gl.record import recorded_bindings
from shaders_port.spirv.engine_inputs import to_up

from ..shaders import export_user_shader, staged_name
from ..targets import target_file

__all__ = ["CLOCK", "bound_data", "clock_uniforms", "screen_plane", "user_parts"]

# a uniform's name in SPIRV-Cross's GLSL ES (``uniform highp float NAME;``, ``... NAME[4];``)
_UNIFORM = re.compile(r"^uniform\b[^;]*?(\w+)\s*(?:\[\d+\])?\s*;", re.M)
#: the study inputs the page's clock moves: the normal-map layers' offsets and the time
CLOCK = ("wave1", "wave2", "wave3", "wave4", "time")


def _b64(a: np.ndarray, dtype: str = "<f4") -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype).tobytes()).decode("ascii")


def _value(u: dict) -> list:
    v = u["value"]
    return [float(x) for x in v] if v.dtype == np.float32 else [int(x) for x in v]


def _texture(t: dict) -> dict:
    first = (t["levels"] if t["target"] == "2d" else t["faces"])[0]
    out = {k: t[k] for k in ("unit", "input", "uniforms", "target", "min_filter", "mag_filter",
                             "wrap", "channels")}  # fmt: skip
    out.update(width=int(first.shape[1]), height=int(first.shape[0]))
    key = "levels" if t["target"] == "2d" else "faces"
    out[key] = [_b64(a) for a in t[key]]
    return out


def screen_plane(inputs, up: str = "y") -> np.ndarray | None:
    """(4, 5) float32 ``[x, y, z, s, t]`` of the water plane's points under the screen's four
    corners (NDC (-1, -1), (1, -1), (-1, 1), (1, 1): a triangle strip) as the GL check's quad
    carries them (positions in the world frame ``up``, texcoord ``(x, z) / normal_tile``);
    None when a corner's ray does not meet the plane ``y = 0`` in front of the camera."""
    inv = np.linalg.inv(np.asarray(inputs.view_proj, np.float64))
    rows = []
    for x, y in ((-1, -1), (1, -1), (-1, 1), (1, 1)):
        a, b = (inv @ np.array([x, y, z, 1.0]) for z in (-1.0, 1.0))
        a, b = a[:3] / a[3], b[:3] / b[3]
        if not (a[1] > 0 > b[1]):
            return None
        p = a + a[1] / (a[1] - b[1]) * (b - a)
        rows.append([*to_up(up, [p[0], 0.0, p[2]], "vector"), *(p[[0, 2]] / inputs.normal_tile)])
    return np.asarray(rows, np.float32)


def _geometry(g: dict, inputs, up: str) -> dict:
    out = {
        "mode": g["mode"],
        "attributes": {
            n: {"size": int(a.shape[1]), "data": _b64(a)} for n, a in g["attributes"].items()
        },  # fmt: skip
        "indices": None if g["indices"] is None else _b64(g["indices"], "<u4"),
        "depth_test": bool(g["depth_test"]),
        "screen": None,
    }
    if g["indices"] is None:  # the study's quad: drawn as the screen's corners where it can
        plane = screen_plane(inputs, up)
        if plane is not None:
            out["screen"] = {
                "aVertex": {"size": 3, "data": _b64(plane[:, :3])},
                "aMultiTexCoord0": {"size": 2, "data": _b64(plane[:, 3:])},
            }
    return out


def clock_uniforms(shader, names) -> dict:
    """Uniform name -> the :data:`CLOCK` input it is bound to, of ``names`` (the program's
    uniforms), through the user's declaration and engine names (both stages) or by its own
    name."""
    bindings = dict(shader.vertex.shader.inputs) if shader.vertex is not None else {}
    bindings.update(shader.run_bindings())
    return {n: bindings.get(n, n) for n in names if bindings.get(n, n) in CLOCK}


def bound_data(shader, inputs, fitted: dict, start: dict) -> dict:
    """``bound`` of ``data.js`` (see the module doc) for the user's shader ``shader``
    (``UserShader``) on ``inputs`` (``ShaderInputs`` as the GL check runs them) with the
    values ``fitted`` and ``start`` ({GLSL name: float | tuple}). RuntimeError without a
    headless OpenGL (llvmpipe), whose bindings it reads."""
    # the core-profile translation the GLSL ES export is made from (not the file as written
    # on a compatibility or ES context, whose built-ins WebGL 2 has not)
    with shader.gl_renderer(inputs, fitted, as_written=False) as r:
        rec = recorded_bindings(r)
    with shader.gl_renderer(inputs, start, as_written=False) as r:
        rec0 = recorded_bindings(r)
    up = shader.engine["up"]
    return {
        "uniforms": {
            k: [{"name": u["name"], "type": u["type"], "value": _value(u)} for u in rc["uniforms"]]
            for k, rc in (("fitted", rec), ("default", rec0))
        },
        "textures": [_texture(t) for t in rec["textures"]],
        "geometry": _geometry(rec["geometry"], inputs, up),
        "clock": clock_uniforms(shader, [u["name"] for u in rec["uniforms"]]),
    }


def _stem(label: str, stage: str) -> str:
    """The exported file's name without its ending (``study.export.shaders.staged_name``)."""
    return staged_name(label, stage).rsplit(".", 1)[0]


def user_parts(shader, shaders: Path, inputs, fitted: dict, start: dict) -> dict:
    """What the viewer runs of the user's shader ``shader`` exported in ``shaders`` (a
    ``shaders/`` folder with its GLSL ES 3.00 files): ``vert`` (its own vertex shader's export
    for a pair, else ``water.vert``'s), ``frag`` (the fitted file), ``frag_default`` (the file
    exported again at ``start``: SPIRV-Cross writes a user's constants as literals),
    ``bound`` (:func:`bound_data`) and ``names`` (the textures, for the page)."""
    vstem = _stem(shader.vertex.label, "vert") if shader.vertex is not None else "water"
    fstem = _stem(shader.label, "frag")
    vert = (Path(shaders) / target_file("gles300", vstem, "vert")).read_text("utf-8")
    frag = (Path(shaders) / target_file("gles300", fstem, "frag")).read_text("utf-8")
    with tempfile.TemporaryDirectory(prefix="viewer_start_") as tmp:
        export_user_shader(shader, start, Path(tmp), targets=("gles300",))
        frag_default = (Path(tmp) / target_file("gles300", fstem, "frag")).read_text("utf-8")
    bound = bound_data(shader, inputs, fitted, start)
    declared = set(_UNIFORM.findall(vert + frag_default + frag))
    bound["inactive"] = sorted(declared - {u["name"] for u in bound["uniforms"]["fitted"]})
    names = ", ".join(f"{'/'.join(t['uniforms'])} ({t['input']})" for t in bound["textures"])
    return {"vert": vert, "frag": frag, "frag_default": frag_default, "bound": bound,
            "names": names}  # fmt: skip
