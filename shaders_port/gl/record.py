"""What a GL renderer binds for its shader, read back from OpenGL: every active uniform of the
linked program with the value the renderer wrote (``glGetUniform``), every texture a sampler
uniform reads with its sampler state and texels (``glGetTexImage``, every mip level), and the
geometry it draws. Another GL front end (the WebGL 2 viewer, ``study.export.viewer``) given
this record binds exactly what the GL check bound, nothing recomputed.

The renderer is a ``gl.renderer.GLRenderer`` or one of its subclasses (the engine inputs of
``spirv.engine_inputs.gl_class``, the grid of a user's vertex shader, ``gl.grid``): its
``texture_units()``, ``geometry()`` and ``program_of()``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["GL_TYPES", "recorded_bindings"]

# GL uniform type enum -> (GLSL type name, NumPy dtype of its components)
GL_TYPES = {
    0x1406: ("float", np.float32),
    0x8B50: ("vec2", np.float32),
    0x8B51: ("vec3", np.float32),
    0x8B52: ("vec4", np.float32),
    0x8B5A: ("mat2", np.float32),
    0x8B5B: ("mat3", np.float32),
    0x8B5C: ("mat4", np.float32),
    0x1404: ("int", np.int32),
    0x8B53: ("ivec2", np.int32),
    0x8B54: ("ivec3", np.int32),
    0x8B55: ("ivec4", np.int32),
    0x1405: ("uint", np.uint32),
    0x8DC6: ("uvec2", np.uint32),
    0x8DC7: ("uvec3", np.uint32),
    0x8DC8: ("uvec4", np.uint32),
    0x8B56: ("bool", np.int32),
    0x8B57: ("bvec2", np.int32),
    0x8B58: ("bvec3", np.int32),
    0x8B59: ("bvec4", np.int32),
    0x8B5E: ("sampler2D", np.int32),
    0x8B60: ("samplerCube", np.int32),
}
# GL filter enum -> its name in lower case (WebGL's constant, upper-cased)
FILTERS = {
    0x2600: "nearest",
    0x2601: "linear",
    0x2700: "nearest_mipmap_nearest",
    0x2701: "linear_mipmap_nearest",
    0x2702: "nearest_mipmap_linear",
    0x2703: "linear_mipmap_linear",
}


def _uniforms(prog, mgl) -> list[dict]:
    """Every active uniform of ``prog``: ``name`` (an array's without ``[0]``), ``type``
    (GLSL), ``count`` (array length), ``value`` (flat NumPy array: matrices column-major as
    GL holds them; a sampler's texture unit)."""
    out = []
    for name in prog:
        u = prog[name]
        if not isinstance(u, mgl.Uniform):
            continue
        if u.gl_type not in GL_TYPES:
            raise ValueError(
                f"the program's uniform {name} is of GL type 0x{u.gl_type:04x}, which the "
                f"record does not know (it knows {', '.join(t for t, _ in GL_TYPES.values())})"
            )
        kind, dtype = GL_TYPES[u.gl_type]
        value = np.frombuffer(u.read(), dtype).copy()
        out.append({"name": name, "type": kind, "count": int(u.array_length), "value": value})
    return out


def _texture(tex, smp, mgl) -> dict:
    """A texture's texels and sampler state: ``target`` '2d' (``levels``: (h, w, C) float32
    arrays, GL upload order, level 0 first) or 'cube' (``faces``: six (F, F, C) arrays in GL
    face order); ``min_filter`` / ``mag_filter`` (:data:`FILTERS`); ``wrap`` 'repeat' or
    'clamp_to_edge'."""
    fmin, fmag = (FILTERS[f] for f in smp.filter)
    rec = {
        "min_filter": fmin,
        "mag_filter": fmag,
        "wrap": "repeat" if smp.repeat_x else "clamp_to_edge",
        "channels": int(tex.components),
    }
    w, h = tex.size
    c = tex.components
    if isinstance(tex, mgl.TextureCube):
        rec["target"] = "cube"
        rec["faces"] = [
            np.frombuffer(tex.read(face=k, alignment=4), np.float32).reshape(h, w, c).copy()
            for k in range(6)
        ]
        return rec
    n = int(np.floor(np.log2(max(w, h)))) + 1 if "mipmap" in fmin else 1
    rec["target"] = "2d"
    rec["levels"] = []
    for k in range(n):
        lw, lh = max(1, w >> k), max(1, h >> k)
        a = np.frombuffer(tex.read(level=k, alignment=4), np.float32).reshape(lh, lw, c)
        rec["levels"].append(a.copy())
    return rec


def recorded_bindings(renderer, constants=None) -> dict:
    """What ``renderer`` binds to draw its shader with ``constants`` (None: the source's own):
    ``uniforms`` (:func:`_uniforms`, samplers included), ``textures`` (one per texture unit a
    sampler reads: ``unit``, ``input`` (the renderer's name of it), ``uniforms`` (the sampler
    uniforms reading it) and :func:`_texture`), ``geometry`` (``renderer.geometry()``).
    RuntimeError when a sampler reads a unit the renderer binds no texture to."""
    mgl = renderer._mgl
    prog = renderer.program_of(constants)
    uniforms = _uniforms(prog, mgl)
    by_unit = {u: (name, tex, smp) for name, (u, tex, smp) in renderer.texture_units().items()}
    textures: dict[int, dict] = {}
    for u in uniforms:
        if not u["type"].startswith("sampler"):
            continue
        unit = int(u["value"][0])
        if unit not in by_unit:
            raise RuntimeError(
                f"the shader's sampler {u['name']} reads texture unit {unit}, to which the GL "
                "renderer binds no texture"
            )
        if unit not in textures:
            name, tex, smp = by_unit[unit]
            rec = {"unit": unit, "input": name, "uniforms": [], **_texture(tex, smp, mgl)}
            textures[unit] = rec
        textures[unit]["uniforms"].append(u["name"])
    geometry = renderer.geometry()
    return {"uniforms": uniforms, "textures": list(textures.values()), "geometry": geometry}
