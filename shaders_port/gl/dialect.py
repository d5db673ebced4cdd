"""The water quad drawn on an OpenGL context of an older dialect: a user's fragment shader run
as written, on the context and after the study's vertex shader in its own GLSL version.

:func:`dialect_renderer_class` makes a subclass of a ``GLRenderer`` (``gl.renderer``) that
draws on a context of ``gl.contexts.KINDS`` other than the core profile:

* ``'compatibility'`` (GLSL 1.10-4.50): the study's vertex shader in GLSL 1.20 (GLSL 1.50
  compatibility for a fragment shader of 1.40 or later: GLSL does not link 1.30 and earlier
  with 1.40 and later), reading the compatibility built-ins as the seed's ``water.vert`` does.
  They are fed as a compatibility profile feeds them: ``gl_Vertex`` and ``gl_MultiTexCoord0``
  from the fixed-function vertex and texture-coordinate arrays (``glVertexPointer``,
  ``glTexCoordPointer`` on the quad's buffer), ``gl_ModelViewMatrix`` and
  ``gl_ProjectionMatrix`` (so ``gl_ModelViewProjectionMatrix``, ``gl_NormalMatrix`` and their
  inverses) from the fixed-function matrices (``glLoadMatrixf``) given as ``matrices``. It
  writes ``gl_TexCoord[0..3]`` and the study's varyings (``varyingVecEye``, ..., and
  ``vTexCoord0..3``, the same values), so a fragment shader may read either;
* ``'es'`` (GLSL ES 1.00-3.20): the study's vertex shader in the fragment shader's own GLSL ES
  version (GLSL ES links only shaders of one version), with the core shader's attributes and
  uniforms (``aVertex``, ``aMultiTexCoord0``, ``uModelViewProjectionMatrix``) and ``highp``
  everywhere.

The coverage mask is drawn with a fragment shader of the same version. Everything else (the
textures, samplers, uniforms set by name, the framebuffer) is the base class's.
"""

from __future__ import annotations

import ctypes

import numpy as np

from .contexts import gl_function

__all__ = ["dialect_renderer_class", "study_vertex", "mask_fragment"]

_WAVES = "".join(f"uniform vec2 wave{k};\n" for k in range(1, 5))
_VARYINGS = ("vec3 varyingVecEye", "vec3 varyingVecLight", "vec3 varyingVecWorldPosition",
             *(f"vec4 vTexCoord{k}" for k in range(4)))  # fmt: skip
_BODY = """void main(void)
{{
    varyingVecWorldPosition = vec3(WaterTransformationMatrix * {vertex});
    varyingVecEye = viewpos - varyingVecWorldPosition.xyz;
    varyingVecLight = lightpos - varyingVecWorldPosition.xyz;
{texcoords}    gl_Position = {mvp} * {vertex};
}}
"""
# GL enums (Khronos gl.h)
_GL_FLOAT, _GL_ARRAY_BUFFER, _GL_TEXTURE0 = 0x1406, 0x8892, 0x84C0
_GL_VERTEX_ARRAY, _GL_NORMAL_ARRAY, _GL_TEXTURE_COORD_ARRAY = 0x8074, 0x8075, 0x8078
_ARRAYS = {
    "gl_Vertex": ("glVertexPointer", _GL_VERTEX_ARRAY),
    "gl_MultiTexCoord0": ("glTexCoordPointer", _GL_TEXTURE_COORD_ARRAY),
}
_GL_MODELVIEW, _GL_PROJECTION = 0x1700, 0x1701
_STRIDE, _UV_OFFSET = 20, 12  # the quad's buffer: x, y, z, s, t float32 per vertex


def _version_line(version: int, es: bool) -> str:
    if es:
        return "#version 100" if version == 100 else f"#version {version} es"
    return "#version 120" if version < 140 else "#version 150 compatibility"


def study_vertex(version: int, es: bool) -> str:
    """The study's ``water.vert`` in the GLSL a fragment shader of ``version`` (``es``: GLSL ES)
    links with (module doc)."""
    head = _version_line(version, es) + "\n"
    legacy = version == 100 if es else version < 140
    inp, out = ("attribute", "varying") if legacy else ("in", "out")
    uniforms = _WAVES + "uniform vec3 viewpos;\nuniform vec3 lightpos;\n"
    uniforms += "uniform mat4 WaterTransformationMatrix;\n"
    if es:
        head += "precision highp float;\n"
        attrs = f"{inp} vec4 aVertex;\n{inp} vec4 aMultiTexCoord0;\n"
        uniforms += "uniform mat4 uModelViewProjectionMatrix;\n"
        uv, vertex, mvp = "aMultiTexCoord0", "aVertex", "uModelViewProjectionMatrix"
        tex = "".join(f"    vTexCoord{k} = vec4({uv}.xy + wave{k + 1}, 0.0, 1.0);\n"
                      for k in range(4))  # fmt: skip
    else:
        attrs, uv, vertex, mvp = (
            "",
            "gl_MultiTexCoord0",
            "gl_Vertex",
            "gl_ModelViewProjectionMatrix",
        )
        tex = "".join(
            f"    gl_TexCoord[{k}] = vec4({uv}.xy + wave{k + 1}, 0.0, 1.0);\n"
            f"    vTexCoord{k} = gl_TexCoord[{k}];\n"
            for k in range(4)
        )
    outs = "".join(f"{out} {v};\n" for v in _VARYINGS)
    return head + attrs + uniforms + outs + _BODY.format(vertex=vertex, texcoords=tex, mvp=mvp)


def mask_fragment(version: int, es: bool) -> str:
    """A fragment shader writing 1 that links with :func:`study_vertex` of ``version``."""
    head = _version_line(version, es) + "\n" + ("precision highp float;\n" if es else "")
    if es and version >= 300:
        return head + "out vec4 fragColor;\nvoid main(void) { fragColor = vec4(1.0); }\n"
    return head + "void main(void) { gl_FragColor = vec4(1.0); }\n"


def _matrix(m) -> ctypes.Array:
    """A (4, 4) matrix acting on column vectors as ``glLoadMatrixf`` reads it (column-major)."""
    return (ctypes.c_float * 16)(*np.asarray(m, np.float32).T.ravel())


def _load_matrices(matrices: dict) -> None:
    """The fixed-function projection and modelview matrices of the current context."""
    load = gl_function("glLoadMatrixf", None, ctypes.POINTER(ctypes.c_float))
    mode = gl_function("glMatrixMode", None, ctypes.c_uint32)
    mode(_GL_PROJECTION)
    load(_matrix(matrices["projection"]))
    mode(_GL_MODELVIEW)
    load(_matrix(matrices["modelview"]))


def _client_arrays(vao_glo: int, arrays: dict) -> None:
    """Point the fixed-function arrays of the vertex array object ``vao_glo`` at ``arrays``
    (built-in name -> (moderngl buffer, components, stride, offset), float32)."""
    u32, i32, vp = ctypes.c_uint32, ctypes.c_int32, ctypes.c_void_p
    bind_va = gl_function("glBindVertexArray", None, u32)
    bind_buffer = gl_function("glBindBuffer", None, u32, u32)
    enable = gl_function("glEnableClientState", None, u32)
    bind_va(vao_glo)
    for name, (buf, k, stride, offset) in arrays.items():
        bind_buffer(_GL_ARRAY_BUFFER, buf.glo)
        if name == "gl_Normal":
            if k != 3:
                raise ValueError(f"gl_Normal takes 3 components, got {k}")
            gl_function("glNormalPointer", None, u32, i32, vp)(_GL_FLOAT, stride, offset)
            enable(_GL_NORMAL_ARRAY)
            continue
        if name == "gl_MultiTexCoord0":
            gl_function("glClientActiveTexture", None, u32)(_GL_TEXTURE0)
        fn, kind = _ARRAYS[name]
        gl_function(fn, None, i32, u32, i32, vp)(k, _GL_FLOAT, stride, offset)
        enable(kind)
    bind_va(0)


def dialect_renderer_class(
    base, kind: str, version: int, matrices: dict | None = None, vertex: str | None = None
):
    """A subclass of ``base`` (``GLRenderer`` or a subclass drawing the study's quad) on a
    context of ``kind`` ('compatibility' or 'es') for a fragment shader of GLSL ``version``
    (module doc); ``matrices``: {'modelview', 'projection'} (4, 4) float64 acting on column
    vectors, loaded as the fixed-function matrices of a compatibility context (their product is
    the frame's world -> clip matrix: the water's model matrix is the identity); ``vertex``: a
    vertex shader of the quad with the core shader's names in place of the study's (an export's
    ``gles300/water.vert``). A subclass drawing a grid (``gl.grid``) replaces the vertex shader;
    the matrices and the built-in attributes it names are fed alike."""
    if kind not in ("compatibility", "es"):
        raise ValueError(f"a dialect renderer draws on a compatibility or ES context, not {kind!r}")
    es = kind == "es"

    class DialectRenderer(base):
        CONTEXT = kind
        MASK_FRAG = mask_fragment(version, es)

        def _setup_context(self) -> None:
            super()._setup_context()
            if not es:
                _load_matrices(matrices)

        def _setup_geometry(self) -> None:
            super()._setup_geometry()
            self._vert = vertex or study_vertex(version, es)

        def _texture2d(self, arr):
            a = np.asarray(arr, np.float32)
            if es and a.ndim == 3 and a.shape[2] == 3:  # RGB32F: no mipmaps in OpenGL ES
                a = np.concatenate([a, np.ones_like(a[..., :1])], axis=2)
            return super()._texture2d(a)

        def _fixed_function_arrays(self, vao, arrays: dict) -> None:
            if arrays and not es:
                _client_arrays(vao.glo, arrays)

        def _vertex_array(self, prog):
            if es:
                return super()._vertex_array(prog)
            vao = self.ctx.vertex_array(prog, [])
            vao.vertices = 4
            self._fixed_function_arrays(vao, {
                "gl_Vertex": (self._vbo, 3, _STRIDE, 0),
                "gl_MultiTexCoord0": (self._vbo, 2, _STRIDE, _UV_OFFSET),
            })  # fmt: skip
            return vao

    return DialectRenderer
