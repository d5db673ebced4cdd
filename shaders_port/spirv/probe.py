"""What a user's fragment shader computes on the way to its colour: the value one of its
variables holds when ``main`` returns, per pixel, and the surface normal its declaration names.

``// @study normal NAME [world|tangent]`` (``spirv.vertex.normal_pragma``) names the variable
that holds the water's surface normal. Its value is read from the executed SPIR-V: the module
keeps the source's names (glslang ``-g``), the variable is one of ``main``'s own (calls are
inlined into ``main``, whose locals keep their names) or one at file scope, and its value is
the one it holds at ``main``'s single return (``spirv-opt --merge-return``), per lane, with the
shader's branches taken as they are on each pixel.

:func:`surface_normals` gives the normal in the study's world frame (right-handed, ``+y`` up):

* ``world`` (the default): the shader's own world frame, ``up`` y as it is, ``up`` z rotated
  back by ``engine_inputs.UP_Z``;
* ``tangent``: the water plane's tangent frame, x along the texture's u (world +x), y along its
  v (world +z), z up (the frame of a tangent-space normal-map texel): world ``(x, z, y)``.
"""

from __future__ import annotations

import hashlib
import json

import drjit as dr
import numpy as np

from ..pipeline.raster import prepare
from ..pipeline.texture import backend_types
from . import translated as spirv_port
from .dialects import ShaderError, front_end
from .engine_inputs import UP_Z
from .execute import Executor
from .loops import check_passes
from .ops import lift

__all__ = ["capture", "surface_normals", "variable_id", "waves_digest"]


def variable_id(mod, name: str, label: str) -> int:
    """The id of the variable ``name`` of ``main`` (Function storage) or of the file (Private);
    ShaderError when there is none or more than one."""
    entry = mod.functions[mod.entry]
    local = [i.result for b in entry.blocks.values() for i in b.body
             if i.opname == "OpVariable" and mod.names.get(i.result) == name]  # fmt: skip
    private = [vid for vid, i in mod.defs.items()
               if i.opname == "OpVariable" and i.operands[0] == "Private"
               and mod.names.get(vid) == name]  # fmt: skip
    found = local + private
    if not found:
        raise ShaderError(
            f"{label}: the declaration names the variable {name!r} (`// @study normal {name}`), "
            "which is not a variable of main() nor one at file scope; name the variable that "
            "holds the surface normal when main() returns"
        )
    if len(found) > 1:
        raise ShaderError(
            f"{label}: {len(found)} variables are named {name!r} in main(); give the one that "
            "holds the surface normal a name of its own"
        )
    return found[0]


def _captured(m, P, b: dict, spec, C, name: str) -> np.ndarray:
    """(N, k) float32: the value of ``name`` on the lanes of the prepared frame ``P``."""
    mod = spirv_port.module_of(spec)
    vid = variable_id(mod, name, spec.label)
    b = dict(b)
    b.update(spirv_port.constant_values(spec, C))
    ex = Executor(mod, m, b)
    try:
        ex.run()
        check_passes(mod, dict(ex.passes), spec.label)  # a loop stopped at its bound: an error
        value = ex.vars.get(vid)
        if value is None:
            raise ShaderError(f"{spec.label}: the variable {name!r} is never written")
        comps = list(value) if isinstance(value, (list, tuple)) else [value]
        if any(isinstance(c, (list, tuple)) for c in comps):
            raise ShaderError(f"{spec.label}: {name!r} is no vector (a vec3 normal is expected)")
        comps = [lift(m, c, "float") for c in comps]
        if ex.quads is not None:  # helper lanes are no pixels
            comps = [ex.quads.shaded_part(m, c) for c in comps]
        dr.eval(comps)
        n = P.raster.index.size
        return np.stack(
            [np.broadcast_to(np.asarray(c.numpy(), np.float32), (n,)) for c in comps], -1
        )
    finally:
        ex.release()


def capture(shader, inputs, name: str, values: dict | None = None, backend: str | None = None):
    """``(value (H, W, k) float32, mask (H, W) bool)``: the value the variable ``name`` of the
    ``UserShader`` ``shader`` holds when ``main`` returns, on each pixel of ``inputs`` its water
    covers (through its vertex shader where it has one), with the constants ``values`` (default
    the start values); NaN where the water does not cover the pixel."""
    m = backend_types(backend)
    spec = shader.spec()
    C = shader.resolved_values(m, values)
    if shader.vertex is not None:
        P, b = shader.vertex.frame(m, inputs, spec, C)
    else:
        P = prepare(inputs, m)
        b = spirv_port.frame_bindings(m, P, inputs, spec)
    lanes = _captured(m, P, b, spec, C, name)
    r = P.raster
    out = np.full((r.height * r.width, lanes.shape[1]), np.nan, np.float32)
    out[r.index] = lanes
    return out.reshape(r.height, r.width, -1), r.mask.copy()


def surface_normals(shader, inputs, values: dict | None = None, backend: str | None = None):
    """``(normals (H, W, 3) float64, mask (H, W) bool)``: the unit surface normal the declaration
    names (``shader.normal``), in the study's world frame (see the module doc), on each covered
    pixel of ``inputs``. ShaderError when the shader declares none, or when a covered pixel's
    normal is not finite, has no length or points down."""
    if shader.normal is None:
        raise ShaderError(
            f"{shader.label}: waves.source = 'shader' needs the variable that holds the surface "
            "normal: declare it with `// @study normal NAME [world|tangent]`"
        )
    name, frame = shader.normal
    v, mask = capture(shader, inputs, name, values, backend)
    if v.shape[-1] < 3:
        raise ShaderError(f"{shader.label}: {name!r} has {v.shape[-1]} component(s); a vec3 "
                          "normal is expected")  # fmt: skip
    n = v[..., :3].astype(np.float64)
    if frame == "tangent":
        n = n[..., [0, 2, 1]]
    elif shader.engine.get("up", "y") == "z":
        n = n @ UP_Z  # the Z-up world's vector back in the study's frame (UP_Z^T n)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    bad = mask & ~(np.isfinite(length[..., 0]) & (length[..., 0] > 1e-12))
    if not bad.any():
        n = n / np.where(mask[..., None], length, 1.0)
        bad = mask & (n[..., 1] <= 0.0)
    if bad.any():
        ys, xs = np.nonzero(bad)
        raise ShaderError(
            f"{shader.label}: the normal {name!r} ({frame} frame) is not finite, has no length or "
            f"points down on {int(bad.sum())} of {int(mask.sum())} points of the water plane "
            f"(first at pixel ({xs[0]}, {ys[0]}) of the {v.shape[1]}x{v.shape[0]} probe); check "
            "the frame the declaration gives (world or tangent) and `// @study up`"
        )
    return n, mask


def waves_digest(shader) -> str:
    """SHA-256 of everything that decides the normals :func:`surface_normals` reads from the
    ``UserShader`` ``shader`` at its start values: its source preprocessed (``#include`` s
    expanded, its defines applied), its vertex shader's, the declaration (start values, engine
    values, bindings, options, the normal's name and frame) and the bytes of the normal-map
    image it names. A reference built from the shader's waves is cached under it."""
    text = front_end(shader.source, shader.label, shader.defines, shader.include_paths,
                     preprocess=True)  # fmt: skip
    data = {
        "fragment": text,
        "vertex": None if shader.vertex is None else shader.vertex.shader.source,
        "vertex_cells": None if shader.vertex is None else list(shader.vertex.cells),
        "start": {k: list(np.atleast_1d(v).astype(float)) for k, v in shader.defaults().items()},
        "values": {k: list(v) for k, v in shader.engine_values().items()},
        "bindings": sorted(shader.run_bindings().items()),
        "engine": shader.engine_record(),
        "normal": list(shader.normal or ()),
    }
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()
