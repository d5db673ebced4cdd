"""The inputs engines' water shaders read, by the names engines give them, with their values on a
study frame.

A user's fragment shader reads the study's inputs (``spirv.translated.STUDY_INPUTS``) by their
names or through ``// @study bind NAME INPUT``. This module adds the inputs an engine's water
shader reads besides (:data:`ENGINE_INPUTS`) and the names engines give them
(:data:`ENGINE_ALIASES`: a declared name of the table binds itself). Its conventions (those of
``shaders_port.inputs``): world units, right-handed, ``+y`` up, the water plane ``y = 0``;
matrices act on column vectors and are uploaded column-major (``uniform mat4``); colours are
linear RGB.

* ``reflection_texture_matrix``: ``B @ reflection_view_proj``, ``B`` the bias matrix
  (``0.5 x + 0.5`` on x, y, z): ``textureProj(reflection_sampler, M * vec4(world, 1))`` reads
  the mirrored camera's image at the point's mirror image, as three.js's ``Reflector`` builds
  its ``textureMatrix`` (bias * projection * view of the mirrored camera);
* ``camera_near``, ``camera_far``: the planes of the camera's projection, recovered from the
  frame's ``view_proj`` (``projection = view_proj @ view^-1``; ``near = P[2,3] / (P[2,2] - 1)``,
  ``far = P[2,3] / (P[2,2] + 1)``), so ``sceneDepth`` (window depth ``d`` in [0, 1]) linearises
  to the eye distance ``2 n f / (f + n - (2 d - 1)(f - n))``;
* ``dudv_map``: the waves' DuDv map, derived from the study's normal map (:func:`dudv_map`);
* ``time``: ``ShaderInputs.time`` seconds (``k * animation.time_step`` on frame ``k`` of an
  animated experiment, ``study.scene.animation_data``; 0 for a still frame);
* ``sun_direction``: unit vector from the centre of the water quad towards ``lightpos``;
  ``sun_color``: ``lightcolor`` (the highlight's linear RGB scale);
* ``user_normal_map``: the image file the declaration names (``// @study normal_map FILE``):
  8-bit RGB read as stored (no sRGB decoding: a normal map holds data), bilinear, repeat, with
  its box-filtered mip chain (trilinear, as engines sample it);
* ``waves_normal_map``: the study's waves as engines store a normal map (:func:`waves_normal_map`:
  tangent space, x along the texture's u = world +x, y along v = world +z, z up), sampled as
  ``user_normal_map`` is. An engine's normal-map sampler (:data:`NORMAL_MAP_ALIASES`) reads it
  when the declaration names no image file: the shader's waves are then the reference's.

The option ``up = "z"`` (``// @study up z``) gives every world-space input in a Z-up frame:
a position or direction ``v`` as ``R v``, a matrix ``M`` taking world points as ``M R^T``
(its inverse ``R M^-1``), ``R`` the right-handed rotation by +90 degrees about x,
``(x, y, z) -> (x, -z, y)``; textures stay as they are.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..inputs import ShaderInputs, normal_matrix
from ..pipeline.texture import CLAMP, LINEAR, REPEAT, CubeMap, Texture2D

__all__ = [
    "ENGINE_INPUTS",
    "ENGINE_ALIASES",
    "SAME_AS",
    "UP_Z",
    "canonical",
    "dudv_map",
    "engine_values",
    "gl_class",
    "resolve_bindings",
    "gl_textures",
    "read_normal_map",
    "sky_cube",
    "split_view",
    "waves_normal_map",
    "to_up",
    "uniform_values",
]

# the first texture unit of the engine inputs' textures on OpenGL: after the study's samplers
# (``gl.renderer``'s units 0-10, the local cube map of the box reflection last)
ENGINE_UNIT = 13

# the right-handed rotation from the study's Y-up world to a Z-up one: (x, y, z) -> (x, -z, y)
UP_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
# window-space bias: clip (x, y, z) in [-1, 1] -> [0, 1]
_BIAS = np.array([[0.5, 0, 0, 0.5], [0, 0.5, 0, 0.5], [0, 0, 0.5, 0.5], [0, 0, 0, 1.0]])

# input name -> (GLSL type, what it is: orientation, units, colour space, filter and wrap)
ENGINE_INPUTS = {
    "reflection_texture_matrix": ("mat4", "bias * view-projection of the mirrored camera: "
                                  "world -> projective (s, t, depth, q) of reflection_sampler"),
    "refraction_sampler": ("sampler2D", "the same as sceneColor: the scene without the water, "
                           "this camera, screen space (s, t) = gl_FragCoord.xy / screenSize"),
    "depth_sampler": ("sampler2D", "the same as sceneDepth: window depth in [0, 1] (GL's "
                      "non-linear depth buffer), nearest, clamp"),
    "camera_near": ("float", "near plane of the camera's projection, world units"),
    "camera_far": ("float", "far plane of the camera's projection, world units"),
    "camera_near_far": ("vec2", "(camera_near, camera_far), world units"),
    "dudv_map": ("sampler2D", "DuDv of the waves: RG = 0.5 + 0.5 (-dh/dx, -dh/dz) of the "
                 "study's normal map (0.5: no distortion), B = 0; bilinear, repeat"),
    "time": ("float", "animation clock, seconds: k * animation.time_step on frame k, 0 still"),
    "sun_direction": ("vec3", "unit vector towards the light from the water quad's centre"),
    "sun_color": ("vec3", "linear RGB of the highlight (lightcolor)"),
    "camera_position": ("vec3", "the same as viewpos: camera position, world units"),
    "inverse_view_projection": ("mat4", "the same as uModelViewProjectionMatrixInverse: "
                                "clip -> world"),
    "sky_cube": ("samplerCube", "the sky as engines hold a cube map: the texel of direction d "
                 "holds the sky in direction d (reflectionTexture holds it in d * (1, -1, 1)); "
                 "linear RGB, bilinear, clamp, no filtering across faces"),
    "user_normal_map": ("sampler2D", "the image `// @study normal_map FILE` names: RGB as "
                        "stored / 255, bilinear, repeat, mipmapped (trilinear)"),
    "waves_normal_map": ("sampler2D", "the study's waves as a tangent-space normal map: RGB = "
                         "0.5 + 0.5 (n_x, n_z, n_y) of the world normal (x along u = world +x, "
                         "y along v = world +z, z up); bilinear, repeat, mipmapped (trilinear)"),
}  # fmt: skip

# an input that is another name of a study input
SAME_AS = {
    "refraction_sampler": "sceneColor",
    "depth_sampler": "sceneDepth",
    "camera_position": "viewpos",
    "inverse_view_projection": "uModelViewProjectionMatrixInverse",
}

# name an engine's fragment shader declares -> (input, engines that use the name)
ENGINE_ALIASES = {
    "textureMatrix": ("reflection_texture_matrix", "three.js (Water, Reflector)"),
    "mirrorSampler": ("reflection_sampler", "three.js (Water)"),
    "tReflectionMap": ("reflection_sampler", "three.js (Water2)"),
    "reflectionSampler": ("reflection_sampler", "Babylon.js (WaterMaterial)"),
    "m_water_reflection": ("reflection_sampler", "jMonkeyEngine (SimpleWater)"),
    "tRefractionMap": ("refraction_sampler", "three.js (Water2)"),
    "refractionSampler": ("refraction_sampler", "Babylon.js (WaterMaterial)"),
    "m_water_refraction": ("refraction_sampler", "jMonkeyEngine (SimpleWater)"),
    "m_water_depthmap": ("depth_sampler", "jMonkeyEngine (SimpleWater)"),
    "cameraNear": ("camera_near", "three.js"),
    "cameraFar": ("camera_far", "three.js"),
    "m_FrustumNearFar": ("camera_near_far", "jMonkeyEngine (SimpleWater)"),
    "m_water_dudvmap": ("dudv_map", "jMonkeyEngine (SimpleWater)"),
    "m_time": ("time", "jMonkeyEngine"),
    "cElapsedTimePS": ("time", "Urho3D"),
    "cElapsedTime": ("time", "Urho3D"),
    "sunDirection": ("sun_direction", "three.js (Water)"),
    "sunColor": ("sun_color", "three.js (Water)"),
    "eye": ("camera_position", "three.js (Water)"),
    "cameraPosition": ("camera_position", "three.js"),
    "g_CameraPosition": ("camera_position", "jMonkeyEngine"),
    "cCameraPosPS": ("camera_position", "Urho3D"),
    "g_ViewProjectionMatrixInverse": ("inverse_view_projection", "jMonkeyEngine"),
    "normalSampler": ("user_normal_map", "three.js (Water)"),
    "bumpSampler": ("user_normal_map", "Babylon.js (WaterMaterial)"),
    "m_water_normalmap": ("user_normal_map", "jMonkeyEngine (SimpleWater)"),
    "tNormalMap0": ("user_normal_map", "three.js (Water2)"),
}


# the engine names of a normal-map sampler: the image `normal_map FILE` names, else the waves
NORMAL_MAP_ALIASES = tuple(k for k, (v, _) in ENGINE_ALIASES.items() if v == "user_normal_map")


def canonical(name: str) -> str:
    """The study input an input name stands for (:data:`SAME_AS`), or ``name`` itself."""
    return SAME_AS.get(name, name)


def to_up(up: str, value: np.ndarray, kind: str) -> np.ndarray:
    """``value`` (float64) in the world frame ``up`` ('y': as it is; 'z': :data:`UP_Z`):
    ``kind`` 'vector' (3,) or (N, 3); 'matrix' (4, 4) taking world points; 'inverse' (4, 4)
    giving them; 'rotation' (3, 3) taking world directions."""
    v = np.asarray(value, np.float64)
    if up == "y":
        return v
    if up != "z":
        raise ValueError(f"up = {up!r}: write `// @study up y` or `// @study up z`")
    R4 = np.eye(4)
    R4[:3, :3] = UP_Z
    if kind == "vector":
        return v @ UP_Z.T
    if kind == "matrix":
        return v @ R4.T
    if kind == "inverse":
        return R4 @ v
    if kind == "rotation":
        return v @ UP_Z.T
    raise ValueError(f"unknown kind {kind!r}")


def split_view(inputs: ShaderInputs) -> tuple[np.ndarray, np.ndarray]:
    """``(view, projection)`` float64 (4, 4) of a frame, acting on column vectors:
    ``view = [R | -R eye]`` with ``R`` the camera's rotation (``shaders_port.inputs.
    normal_matrix``) and ``eye`` = ``viewpos``, ``projection = view_proj @ view^-1``.
    ValueError when ``view_proj`` is no perspective times a rigid view."""
    vp = np.asarray(inputs.view_proj, np.float64)
    R = normal_matrix(vp).astype(np.float64)
    view = np.eye(4)
    view[:3, :3] = R
    view[:3, 3] = -R @ np.asarray(inputs.viewpos, np.float64)
    return view, vp @ np.linalg.inv(view)


def _near_far(inputs: ShaderInputs) -> tuple[float, float]:
    P = split_view(inputs)[1]
    return float(P[2, 3] / (P[2, 2] - 1.0)), float(P[2, 3] / (P[2, 2] + 1.0))


def uniform_values(inputs: ShaderInputs, up: str = "y") -> dict:
    """The uniforms of :data:`ENGINE_INPUTS` a frame has, float64 NumPy (matrices (4, 4)
    row-major acting on column vectors), in the world frame ``up``; a frame without the
    mirrored camera has no ``reflection_texture_matrix``, one whose ``view_proj`` is no
    perspective times a rigid view no ``camera_near``/``camera_far``."""
    x0, z0, x1, z1 = inputs.water_rect
    centre = np.array([(x0 + x1) / 2, 0.0, (z0 + z1) / 2])
    sun = np.asarray(inputs.lightpos, np.float64) - centre
    out = {
        "time": np.float64(getattr(inputs, "time", 0.0) or 0.0),
        "sun_direction": to_up(up, sun / np.linalg.norm(sun), "vector"),
        "sun_color": np.asarray(inputs.lightcolor, np.float64),
    }
    if inputs.reflection_view_proj is not None:
        m = _BIAS @ np.asarray(inputs.reflection_view_proj, np.float64)
        out["reflection_texture_matrix"] = to_up(up, m, "matrix")
    try:
        out["camera_near"], out["camera_far"] = (np.float64(v) for v in _near_far(inputs))
        out["camera_near_far"] = np.array([out["camera_near"], out["camera_far"]])
    except ValueError:
        pass  # no perspective * rigid split: a shader reading them fails naming the input
    return out


def dudv_map(normal_map: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 DuDv map of the study's normal map ``normal_map`` ((H, W, 3), world
    normals encoded ``0.5 n + 0.5``, ``+y`` up): RG = ``0.5 + 0.5 (n_x, n_z) / n_y`` clipped to
    [0, 1], B = 0. For a height field ``h(x, z)`` the normal is proportional to
    ``(-dh/dx, 1, -dh/dz)``, so RG encodes ``-grad h`` (the surface slope, the offset engines
    add to the texture coordinate, scaled by their distortion strength), 0.5 where the water
    is flat, a slope of 1 at 0 or 1."""
    n = 2.0 * np.asarray(normal_map, np.float64) - 1.0
    ny = np.maximum(n[..., 1], 1e-6)
    rg = np.clip(0.5 + 0.5 * n[..., [0, 2]] / ny[..., None], 0.0, 1.0)
    return np.concatenate([rg, np.zeros_like(rg[..., :1])], -1).astype(np.float32)


def waves_normal_map(normal_map: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 tangent-space normal map of the study's normal map ``normal_map``
    ((H, W, 3), world normals encoded ``0.5 n + 0.5``, ``+y`` up): RGB = ``0.5 + 0.5 (n_x, n_z,
    n_y)``, the frame of a normal-map texel on the water plane (x along the texture's u = world
    +x, y along v = world +z, z up; a flat texel is (0.5, 0.5, 1))."""
    return np.ascontiguousarray(np.asarray(normal_map, np.float32)[..., [0, 2, 1]])


def sky_cube(cubemap: np.ndarray) -> np.ndarray:
    """(6, F, F, C) the study's sky cube map ``cubemap`` (GL face order +X, -X, +Y, -Y, +Z, -Z,
    the texel of direction ``d`` holding the sky in direction ``d * (1, -1, 1)``) as engines
    hold one (the texel of ``d`` holding the sky in ``d``): the texel of ``d * (1, -1, 1)`` is
    on the same face for the x and z faces and on the opposite one for the y faces, at the same
    s and the opposite t, so the faces +Y and -Y swap and every face's rows reverse (exact: the
    texel centres are symmetric)."""
    return np.ascontiguousarray(np.asarray(cubemap)[[0, 1, 3, 2, 4, 5], ::-1])


def read_normal_map(path) -> np.ndarray:
    """(H, W, 3) float32 RGB in [0, 1] of an 8- or 16-bit image file, rows in GL upload order:
    the file's top row at ``t = 1`` (as three.js and Babylon.js upload an image, ``flipY`` /
    ``invertY``); ValueError naming the file when it cannot be read."""
    from PIL import Image  # noqa: PLC0415 - an optional input: only a declaration naming a file

    p = Path(path)
    try:
        with Image.open(p) as im:
            mode16 = im.mode in ("I;16", "I;16B", "I")
            a = np.asarray(im if mode16 else im.convert("RGB"))
    except (OSError, ValueError) as exc:
        raise ValueError(f"normal_map: cannot read the image {str(p)!r}: {exc}") from None
    a = a.astype(np.float32) / (65535.0 if mode16 else 255.0)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, -1)
    return np.ascontiguousarray(a[::-1])


def gl_textures(inputs: ShaderInputs, normal_map: str | None) -> dict:
    """Input -> (array (H, W, C) float32 in GL upload order, filter, wrap, mipmapped) of the
    sampler inputs of :data:`ENGINE_INPUTS` that are not another study input's name."""
    out = {
        "dudv_map": (dudv_map(inputs.normal_map), LINEAR, REPEAT, False),
        "waves_normal_map": (waves_normal_map(inputs.normal_map), LINEAR, REPEAT, True),
    }
    if normal_map:
        out["user_normal_map"] = (read_normal_map(normal_map), LINEAR, REPEAT, True)
    return out


def _columns(M) -> list:
    a = np.asarray(M, np.float32)
    return [[float(a[i, j]) for i in range(a.shape[0])] for j in range(a.shape[1])]


def engine_values(m, inputs: ShaderInputs, options: dict) -> dict:
    """The executor's values of :data:`ENGINE_INPUTS` (not those of :data:`SAME_AS`) for one
    frame: matrices as column lists, vectors as lists, floats, textures as ``Texture2D``;
    ``options``: ``up`` ('y' or 'z'), ``normal_map`` (an image path or None)."""
    out = {}
    for name, v in uniform_values(inputs, options.get("up", "y")).items():
        if v.ndim == 2:
            out[name] = _columns(v)
        elif v.ndim == 1:
            out[name] = [float(np.float32(x)) for x in v]
        else:
            out[name] = float(np.float32(v))
    for name, (a, filt, wrap, mips) in gl_textures(inputs, options.get("normal_map")).items():
        tex = Texture2D.from_numpy(m, a, filt, wrap if wrap in (REPEAT, CLAMP) else CLAMP)
        out[name] = tex.with_mipmaps(m, LINEAR, a) if mips else tex
    out["sky_cube"] = CubeMap.from_numpy(m, sky_cube(inputs.cubemap))
    return out


def resolve_bindings(source: str, bindings: dict, constants, image: bool = False) -> dict:
    """The bindings a user's shader runs with: its own (``bindings``, name -> input) and each
    engine name of :data:`ENGINE_ALIASES` and input of :data:`SAME_AS` its code (comments left
    out) uses that it neither binds nor declares a constant (in ``constants``); every target
    given as the study input it stands for (:func:`canonical`). An engine's normal-map sampler
    reads ``user_normal_map`` when the declaration names an image (``image``), else
    ``waves_normal_map``."""
    code = re.sub(r"//[^\n]*|/\*.*?\*/", "", source, flags=re.S)
    out = {}
    for name, (inp, _) in ENGINE_ALIASES.items():
        if name not in constants and re.search(rf"\b{name}\b", code):
            out[name] = "waves_normal_map" if inp == "user_normal_map" and not image else inp
    for name in SAME_AS:
        if name not in constants and re.search(rf"\b{name}\b", code):
            out[name] = name
    out.update(bindings)
    return {k: canonical(v) for k, v in out.items()}


def _world_uniforms(inputs: ShaderInputs, up: str) -> dict:
    """The study's world-space uniforms in the frame ``up``, float64 (as :func:`uniform_values`)."""
    vp = np.asarray(inputs.view_proj, np.float64)
    vals = {
        "viewpos": to_up(up, inputs.viewpos, "vector"),
        "lightpos": to_up(up, inputs.lightpos, "vector"),
        "uModelViewProjectionMatrix": to_up(up, vp, "matrix"),
        "uTextureMatrix0": to_up(up, inputs.tex_matrix0, "matrix"),
        "uTextureMatrix1": to_up(up, inputs.tex_matrix1, "matrix"),
        "uModelViewProjectionMatrixInverse": to_up(up, np.linalg.inv(vp), "inverse"),
    }
    if inputs.reflection_view_proj is not None:
        vals["o2v_projection_reflection"] = to_up(up, inputs.reflection_view_proj, "matrix")
    try:
        vals["uNormalMatrix"] = to_up(up, normal_matrix(vp), "rotation")
    except ValueError:
        pass
    return vals


def _gl_bytes(v: np.ndarray) -> bytes:
    """A value of :func:`uniform_values` as GL uniform bytes (matrices column-major)."""
    a = np.asarray(v, np.float32)
    return np.ascontiguousarray(a.T if a.ndim == 2 else a).tobytes()


def gl_class(base, options: dict):
    """A subclass of the GL renderer class ``base`` (``gl.renderer.GLRenderer`` or a subclass)
    that also gives the shader the inputs of :data:`ENGINE_INPUTS` (uniforms, and the textures
    of :func:`gl_textures` on texture units :data:`ENGINE_UNIT` and up, after the study's
    samplers) and, with ``options['up']`` 'z', draws the water quad and gives every world-space
    uniform in the Z-up frame (``water.vert`` then passes Z-up varyings)."""
    up = options.get("up", "y")
    normal_map = options.get("normal_map")

    class _EngineInputs(base):
        def _setup_geometry(self) -> None:
            super()._setup_geometry()
            if up == "y" or not hasattr(self, "_vbo"):
                return  # a user's vertex shader's grid (``gl.grid``) has its attributes in ``up``
            data = np.frombuffer(self._vbo.read(), np.float32).reshape(-1, 5).copy()
            data[:, :3] = to_up(up, data[:, :3], "vector")
            self._vbo.release()
            self._vbo = self.ctx.buffer(data.astype(np.float32).tobytes())

        def _setup_textures(self) -> None:
            super()._setup_textures()
            mgl = self._mgl
            self._engine_textures = {}
            for k, (name, (a, filt, wrap, mips)) in enumerate(
                gl_textures(self.inputs, normal_map).items()
            ):
                tex = self._texture2d(a)
                f = mgl.LINEAR if filt == LINEAR else mgl.NEAREST
                fmin = f
                if mips:
                    tex.build_mipmaps()
                    fmin = mgl.LINEAR_MIPMAP_LINEAR
                rep = wrap == REPEAT
                smp = self.ctx.sampler(repeat_x=rep, repeat_y=rep, filter=(fmin, f))
                self._engine_textures[name] = (ENGINE_UNIT + k, tex, smp)
            cube = sky_cube(self.inputs.cubemap).astype(np.float32)
            tex = self.ctx.texture_cube(
                (cube.shape[1], cube.shape[1]), cube.shape[3], cube.tobytes(), dtype="f4"
            )
            f = mgl.LINEAR
            smp = self.ctx.sampler(repeat_x=False, repeat_y=False, repeat_z=False, filter=(f, f))
            self._engine_textures["sky_cube"] = (ENGINE_UNIT + len(self._engine_textures), tex, smp)

        def texture_units(self) -> dict:
            return {**super().texture_units(), **self._engine_textures}

        def _set_static_uniforms(self, prog) -> None:
            super()._set_static_uniforms(prog)
            # the study's uniforms in the frame ``up``, also those ``base`` writes only when the
            # program reads them by the study's name (a shader may read them by an engine's)
            vals = _world_uniforms(self.inputs, up)
            vals["screenSize"] = np.array([self.inputs.width, self.inputs.height], np.float64)
            vals.update(uniform_values(self.inputs, up))
            for name, study in SAME_AS.items():
                if study in vals:
                    vals[name] = vals[study]
            self._write_uniforms(prog, {k: _gl_bytes(v) for k, v in vals.items()})
            for name, (unit, _, _) in self._engine_textures.items():
                uname = self._sampler_uniform(prog, name)
                if uname is not None:
                    prog[uname].value = unit

    return _EngineInputs
