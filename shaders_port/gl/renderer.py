"""Run the water shaders on a real OpenGL implementation (headless EGL, e.g. Mesa llvmpipe).

``GLRenderer`` draws the water quad of a ``ShaderInputs`` with the core-profile shaders
into a float32 RGBA framebuffer and reads it back in image order (row 0 = top).
A compatibility (GLSL 1.20) source is run through ``compat_to_core``, the documented
substitution table that maps the shipped compat files onto the shipped core files.

Texture set-up (one texture unit each, float32 storage, no mipmaps but slopeMoments'):
refractionTexture RGB32F linear clamp; worldYComponent R32F nearest clamp; normalMap RGB32F
linear repeat; reflectionTexture cube RGB32F linear clamp, seamless cube filtering off;
fresnelLookup (N x 1) RG32F nearest clamp; worldYComponentReflection R32F nearest clamp;
reflectionBottom RGB32F linear clamp; slopeMoments (``LEAN_NORMALS``, ``pipeline.normal_maps``)
RGBA32F trilinear repeat, its mip levels made by ``glGenerateMipmap``; heightMap
(``PARALLAX_OFFSET``) R32F linear repeat; the optional inputs:
the baseline's screen-space buffers and the local cube map boxReflectionTexture (cube RGB32F
linear clamp, as reflectionTexture).
"""

from __future__ import annotations

import time

import numpy as np

from ..glsl_text import compat_to_core, read_source, with_define, write_constants
from ..inputs import CONSTANT_SPECS, Constants, ShaderInputs, normal_matrix
from ..pipeline.normal_maps import DERIVED_MAPS
from .contexts import create_context

_GL_TEXTURE_CUBE_MAP_SEAMLESS = 0x884F
_FRAG_NAMES = ("water_refraction", "water_reflection", "water_baseline")
_UNIFORM_CONSTANTS = {
    py: spec[0] for py, spec in CONSTANT_SPECS.items() if spec[1].startswith("uniform")
}
_MASK_FRAG = "#version 330 core\nout vec4 fragColor;\nvoid main(void) { fragColor = vec4(1.0); }\n"
# sampler name -> (texture unit, filter 'linear'|'nearest', repeat)
SAMPLERS = {
    "refractionTexture": (0, "linear", False),
    "worldYComponent": (1, "nearest", False),
    "normalMap": (2, "linear", True),
    "reflectionTexture": (3, "linear", False),
    "fresnelLookup": (4, "nearest", False),
    "worldYComponentReflection": (5, "nearest", False),
    "reflectionBottom": (6, "linear", False),
    # the baseline shader's screen-space buffers (optional ShaderInputs fields)
    "sceneColor": (7, "linear", False),
    "sceneDepth": (8, "nearest", False),
    "reflection_sampler": (9, "linear", False),
    # the local cube map of BOX_REFLECTION (optional)
    "boxReflectionTexture": (10, "linear", False),
    # LEAN_NORMALS' slope moments of the normal map, mipmapped (trilinear)
    "slopeMoments": (11, "linear", True),
    # PARALLAX_OFFSET's heights of the normal map (R32F, tile lengths)
    "heightMap": (12, "linear", True),
}
MIPMAPPED = ("slopeMoments",)
# sampler -> the optional ShaderInputs field it is made from
OPTIONAL_SAMPLERS = {
    "sceneColor": "scene_color",
    "sceneDepth": "scene_depth",
    "reflection_sampler": "reflection_color",
    "boxReflectionTexture": "box_cubemap",
}
_CUBE_SAMPLERS = ("reflectionTexture", "boxReflectionTexture")
# vec3 uniform -> the optional ShaderInputs field it is set from
OPTIONAL_VEC3 = {"boxMin": "box_min", "boxMax": "box_max", "boxCapturePosition": "box_capture"}


def create_egl_context():
    """A standalone moderngl context (OpenGL >= 3.3 core) through EGL; clear error if
    unavailable."""
    return create_context("core")


def _mat_bytes(m: np.ndarray) -> bytes:
    """Row-major (4, 4) matrix acting on column vectors -> GL column-major bytes."""
    return np.ascontiguousarray(np.asarray(m, dtype=np.float32).T).tobytes()


class GLRenderer:
    """Draw one water shader for one ``ShaderInputs`` on OpenGL, for many constant sets.

    Args:
        name: 'water_refraction' or 'water_reflection'.
        inputs: textures, matrices, uniforms and output resolution.
        dialect: dialect of ``source`` (and of the shipped file when ``source`` is None):
            'core' runs as is; 'compat' (GLSL 1.20) runs through ``compat_to_core``.
        source: fragment shader text to run instead of the shipped file (e.g. an export).
        defines: preprocessor names to define (a shader variant, ``shaders_port.variants``),
            each inserted after ``#version`` unless the source already has that ``#define``
            line (an exported variant file carries its own).
    """

    MAX_PROGRAMS = 8  # compiled programs kept (one per distinct constants text), oldest dropped
    CONTEXT = "core"  # the kind of context (``gl.contexts.KINDS``)
    MASK_FRAG = _MASK_FRAG  # the fragment shader of the coverage mask (links with ``_vert``)

    def __init__(
        self,
        name: str,
        inputs: ShaderInputs,
        *,
        dialect: str = "core",
        source: str | None = None,
        defines: tuple[str, ...] = (),
    ):
        if name not in _FRAG_NAMES:
            raise ValueError(f"unknown water shader {name!r}; known: {_FRAG_NAMES}")
        if dialect not in ("core", "compat"):
            raise ValueError(f"dialect must be 'core' or 'compat', got {dialect!r}")
        if not isinstance(inputs, ShaderInputs):
            raise TypeError(f"inputs must be a ShaderInputs, got {type(inputs).__name__}")
        import moderngl

        self._mgl = moderngl
        self.name, self.inputs, self.dialect = name, inputs, dialect
        self.defines = tuple(defines)
        for d in self.defines:
            with_define("#version 120\n", d)  # raises on a name that is not a preprocessor name
        self._source = source if source is not None else read_source(name, "frag", dialect)
        self._vert = read_source("water", "vert", "core")
        self._programs: dict[str, object] = {}
        self.ctx = create_context(self.CONTEXT)
        try:
            if self.CONTEXT != "es":  # OpenGL ES filters every cube map seamlessly
                self.ctx.disable_direct(_GL_TEXTURE_CUBE_MAP_SEAMLESS)
            self._setup_context()
            self._setup_geometry()
            self._setup_textures()
            w, h = inputs.width, inputs.height
            self._color = self.ctx.renderbuffer((w, h), 4, dtype="f4")
            self.fbo = self.ctx.framebuffer(color_attachments=[self._color])
            self._mask = self._render_mask()
        except Exception:
            self.release()
            raise

    # -- set-up -------------------------------------------------------------------------------
    def _setup_context(self) -> None:
        """State of the context the shaders read besides uniforms (none on a core context)."""

    def _fixed_function_arrays(self, vao, arrays: dict) -> None:
        """Feed ``vao`` 's compatibility built-in attributes from ``arrays`` (built-in name ->
        (buffer, components, stride, offset)); none on a core context."""

    def _setup_geometry(self) -> None:
        x0, z0, x1, z1 = self.inputs.water_rect
        tile = self.inputs.normal_tile
        corners = [(x0, z0), (x1, z0), (x0, z1), (x1, z1)]
        data = np.array([[x, 0.0, z, x / tile, z / tile] for x, z in corners], dtype=np.float32)
        self._vbo = self.ctx.buffer(data.tobytes())

    def _texture2d(self, arr: np.ndarray):
        """(H, W[, C]) float32 array -> 2-D float texture, row 0 at t = 0.5 / H."""
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        comps = 1 if arr.ndim == 2 else arr.shape[2]
        h, w = arr.shape[:2]
        return self.ctx.texture((w, h), comps, arr.tobytes(), dtype="f4", alignment=4)

    def _texture_cube(self, arr: np.ndarray):
        """(6, F, F, 3) float32 faces in GL order -> an RGB32F cube-map texture."""
        cube = np.ascontiguousarray(arr, dtype=np.float32)
        size = (cube.shape[1], cube.shape[1])
        return self.ctx.texture_cube(size, 3, cube.tobytes(), dtype="f4", alignment=4)

    def _setup_textures(self) -> None:
        i = self.inputs
        lut = i.fresnel_lut[None, :, :]  # (1, N, 2): N x 1 texture, s = cos(theta)
        self._textures = {
            "refractionTexture": self._texture2d(i.refraction_texture),
            "worldYComponent": self._texture2d(i.world_y),
            "normalMap": self._texture2d(i.normal_map),
            "reflectionTexture": self._texture_cube(i.cubemap),
            "fresnelLookup": self._texture2d(lut),
            "worldYComponentReflection": self._texture2d(i.refl_world_y),
            "reflectionBottom": self._texture2d(i.refl_texture),
        }
        for sname, field in OPTIONAL_SAMPLERS.items():
            arr = getattr(i, field)
            if arr is not None:
                cube = sname in _CUBE_SAMPLERS
                self._textures[sname] = (self._texture_cube if cube else self._texture2d)(arr)
        self._samplers = {s: self._sampler(s) for s in SAMPLERS if s in self._textures}

    def _sampler(self, sname: str):
        """The moderngl sampler of ``SAMPLERS[sname]`` (trilinear where ``MIPMAPPED``)."""
        mgl = self._mgl
        _, filt, repeat = SAMPLERS[sname]
        f = mgl.LINEAR if filt == "linear" else mgl.NEAREST
        fmin = mgl.LINEAR_MIPMAP_LINEAR if sname in MIPMAPPED else f
        return self.ctx.sampler(repeat_x=repeat, repeat_y=repeat, repeat_z=repeat, filter=(fmin, f))

    def _derived_map(self, sname: str) -> None:
        """Upload the map ``DERIVED_MAPS[sname]`` of the normal map (``pipeline.normal_maps``;
        its mip chain built by GL where ``MIPMAPPED``) and make its sampler: done when a
        program first reads it."""
        tex = self._texture2d(DERIVED_MAPS[sname](self.inputs.normal_map))
        if sname in MIPMAPPED:
            tex.build_mipmaps()
        self._textures[sname] = tex
        self._samplers[sname] = self._sampler(sname)

    def texture_units(self) -> dict:
        """Input name -> (texture unit, moderngl texture, moderngl sampler) of every texture
        this renderer binds (``SAMPLERS``: those of its inputs that are not None, and the
        ``DERIVED_MAPS`` a program it ran reads)."""
        return {s: (unit, self._textures[s], self._samplers[s])
                for s, (unit, _, _) in SAMPLERS.items() if s in self._textures}  # fmt: skip

    def geometry(self) -> dict:
        """What :meth:`draw` draws: ``mode`` ('triangle_strip'), ``attributes`` name ->
        (V, k) float32 per-vertex values (``aVertex`` the quad's corners, world units;
        ``aMultiTexCoord0`` (x, z) / normal_tile), ``indices`` None, ``depth_test`` False."""
        data = np.frombuffer(self._vbo.read(), np.float32).reshape(-1, 5)
        attributes = {"aVertex": data[:, :3].copy(), "aMultiTexCoord0": data[:, 3:].copy()}
        return {"mode": "triangle_strip", "attributes": attributes, "indices": None,
                "depth_test": False}  # fmt: skip

    def program_of(self, constants: Constants | None = None):
        """The linked moderngl program :meth:`draw` runs for ``constants``, its static
        uniforms set."""
        return self._program(self._frag_source(constants))[0]

    def _bind_textures(self) -> None:
        for unit, tex, smp in self.texture_units().values():
            tex.use(location=unit)
            smp.use(location=unit)

    def _program(self, frag_source: str):
        prog = self._programs.get(frag_source)
        if prog is None:
            try:
                prog = self.ctx.program(vertex_shader=self._vert, fragment_shader=frag_source)
            except self._mgl.Error as exc:
                raise RuntimeError(f"OpenGL rejected the {self.name} shader:\n{exc}") from exc
            vao = self._vertex_array(prog)
            self._set_static_uniforms(prog)
            prog = (prog, vao)
            self._programs[frag_source] = prog
            while len(self._programs) > self.MAX_PROGRAMS:  # oldest first (dicts keep order)
                old_prog, old_vao = self._programs.pop(next(iter(self._programs)))
                old_vao.release()
                old_prog.release()
        return prog

    def _vertex_array(self, prog):
        """The vertex array drawing the water quad (``_vbo``) with ``prog``."""
        if "aMultiTexCoord0" in prog:
            return self.ctx.vertex_array(prog, [(self._vbo, "3f 2f", "aVertex", "aMultiTexCoord0")])
        # a variant that reads no normal map (the linker dropped the texcoords)
        return self.ctx.vertex_array(prog, [(self._vbo, "3f 8x", "aVertex")])

    def _set_static_uniforms(self, prog) -> None:
        i = self.inputs
        vals = {
            "WaterTransformationMatrix": _mat_bytes(np.eye(4)),
            "uModelViewProjectionMatrix": _mat_bytes(i.view_proj),
            "uTextureMatrix0": _mat_bytes(i.tex_matrix0),
            "uTextureMatrix1": _mat_bytes(i.tex_matrix1),
            "viewpos": i.viewpos.astype(np.float32).tobytes(),
            "lightpos": i.lightpos.astype(np.float32).tobytes(),
            "lightcolor": i.lightcolor.astype(np.float32).tobytes(),
        }
        if self._reads(prog, "uModelViewProjectionMatrixInverse"):
            vals["uModelViewProjectionMatrixInverse"] = _mat_bytes(
                np.linalg.inv(i.view_proj.astype(np.float64)).astype(np.float32)
            )
        if self._reads(prog, "uNormalMatrix"):
            vals["uNormalMatrix"] = np.ascontiguousarray(normal_matrix(i.view_proj).T).tobytes()
        if self._reads(prog, "screenSize"):
            vals["screenSize"] = np.array([i.width, i.height], np.float32).tobytes()
        if self._reads(prog, "o2v_projection_reflection"):
            if i.reflection_view_proj is None:
                raise ValueError(
                    f"{self.name} reads o2v_projection_reflection but "
                    "ShaderInputs.reflection_view_proj is None; build the inputs with "
                    "study.scene.baseline_inputs.with_baseline_inputs"
                )
            vals["o2v_projection_reflection"] = _mat_bytes(i.reflection_view_proj)
        for uname, field in OPTIONAL_VEC3.items():
            if self._reads(prog, uname):
                if getattr(i, field) is None:
                    raise ValueError(
                        f"{self.name} reads {uname} but ShaderInputs.{field} is None; build "
                        "the inputs with study.scene.box_inputs.with_box_inputs"
                    )
                vals[uname] = np.asarray(getattr(i, field), np.float32).tobytes()
        for k in range(4):
            vals[f"wave{k + 1}"] = i.waves[k].astype(np.float32).tobytes()
        self._write_uniforms(prog, vals)
        for sname, (unit, _, _) in SAMPLERS.items():
            uname = self._sampler_uniform(prog, sname)
            if uname is not None:
                if sname not in self._textures and sname in DERIVED_MAPS:
                    self._derived_map(sname)
                if sname not in self._textures:
                    builder = (
                        "box_inputs.with_box_inputs"
                        if sname in _CUBE_SAMPLERS
                        else "baseline_inputs.with_baseline_inputs"
                    )
                    raise ValueError(
                        f"{self.name} reads the sampler {sname} but ShaderInputs."
                        f"{OPTIONAL_SAMPLERS[sname]} is None; build the inputs with "
                        f"study.scene.{builder}"
                    )
                prog[uname].value = unit

    # -- how a program names its inputs (overridden for shaders translated by SPIRV-Cross) ----
    def _reads(self, prog, uname: str) -> bool:
        """Whether ``prog`` reads the uniform ``uname`` (of the shipped core shaders' names)."""
        return uname in prog

    def _write_uniforms(self, prog, vals: dict) -> None:
        """Write ``vals`` (uniform name -> GL bytes) into the uniforms ``prog`` reads."""
        for uname, data in vals.items():
            if uname in prog:
                prog[uname].write(data)

    def _sampler_uniform(self, prog, sname: str) -> str | None:
        """The uniform of ``prog`` that samples texture ``sname`` (None: it reads none)."""
        return sname if sname in prog else None

    def _frag_source(self, constants: Constants | None) -> str:
        src = self._source if constants is None else write_constants(self._source, constants)
        for d in self.defines:
            if f"\n#define {d}\n" not in src:
                src = with_define(src, d)
        return compat_to_core(src, "frag") if self.dialect == "compat" else src

    def _render_mask(self) -> np.ndarray:
        prog = self.ctx.program(vertex_shader=self._vert, fragment_shader=self.MASK_FRAG)
        self._set_static_uniforms(prog)
        vao = self._vertex_array(prog)
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        vao.render(self._mgl.TRIANGLE_STRIP)
        mask = self._read()[..., 0] > 0.5
        vao.release()
        prog.release()
        return mask

    def _read(self) -> np.ndarray:
        w, h = self.inputs.width, self.inputs.height
        raw = self.fbo.read(components=4, dtype="f4", alignment=4)
        return np.frombuffer(raw, dtype=np.float32).reshape(h, w, 4)[::-1].copy()

    # -- drawing ------------------------------------------------------------------------------
    def draw(self, constants: Constants | None = None) -> None:
        """Draw one frame into the framebuffer (no read-back, no synchronisation)."""
        prog, vao = self._program(self._frag_source(constants))
        if constants is not None:
            for py, uname in _UNIFORM_CONSTANTS.items():
                if uname in prog:
                    v = getattr(constants, py)
                    prog[uname].value = (
                        tuple(float(x) for x in v) if isinstance(v, (tuple, list)) else float(v)
                    )
        self._bind_textures()
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        vao.render(self._mgl.TRIANGLE_STRIP)

    def render(self, constants: Constants | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Render one frame.

        ``constants``: written into the shader's constants block (and set as uniforms);
        None runs the source's own block as is, its uniforms left at their initializers.
        Returns (rgba, mask): rgba (height, width, 4) float32 linear RGB + alpha as the
        shader wrote it, 0 outside the quad; mask (height, width) bool, quad coverage.
        Row 0 is the top of the image.
        """
        self.draw(constants)
        return self._read(), self._mask.copy()

    def time_frames(
        self, constants: Constants | None = None, n: int = 20, warmup: int = 3
    ) -> list[float]:
        """Seconds per frame (draw + glFinish, no read-back) for ``n`` frames after ``warmup``."""
        for _ in range(warmup):
            self.draw(constants)
            self.ctx.finish()
        out = []
        for _ in range(n):
            t0 = time.perf_counter()
            self.draw(constants)
            self.ctx.finish()
            out.append(time.perf_counter() - t0)
        return out

    def release(self) -> None:
        """Free all GL objects and the context (idempotent)."""
        ctx = getattr(self, "ctx", None)
        if ctx is not None:
            ctx.release()
            self.ctx = None
        self._programs = {}

    def __enter__(self) -> "GLRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def run_glsl(
    name: str,
    inputs: ShaderInputs,
    constants: Constants | None = None,
    *,
    defines: tuple[str, ...] = (),
    source: str | None = None,
    dialect: str = "core",
) -> tuple[np.ndarray, np.ndarray]:
    """One-shot ``GLRenderer(name, inputs, ...).render(constants)``; see GLRenderer.render."""
    with GLRenderer(name, inputs, dialect=dialect, defines=defines, source=source) as r:
        return r.render(constants)


def time_glsl(
    inputs: ShaderInputs,
    constants: Constants | None = None,
    n: int = 20,
    *,
    name: str = "water_refraction",
    defines: tuple[str, ...] = (),
) -> list[float]:
    """Seconds per frame of the core shader on this GL implementation, glFinish-synchronised,
    ``n`` frames after 3 warm-up frames (shader compilation excluded)."""
    with GLRenderer(name, inputs, defines=defines) as r:
        return r.time_frames(constants, n=n)


def alternate_frames(drawn: list, n: int, warmup: int = 1) -> list[list[float]]:
    """Seconds per frame of several renderers drawn in turn, frame by frame, so that a load
    that comes and goes falls on all of them alike: ``drawn`` a list of (renderer, constants);
    ``warmup`` rounds, then ``n`` timed rounds of one frame each (draw + glFinish on the
    renderer's own context, made current for it). Returns one list of ``n`` times per
    renderer, in ``drawn``'s order."""
    out: list[list[float]] = [[] for _ in drawn]
    for k in range(warmup + n):
        for times, (r, constants) in zip(out, drawn):
            with r.ctx:
                t = r.time_frames(constants, n=1, warmup=0)[0]
            if k >= warmup:
                times.append(t)
    return out
