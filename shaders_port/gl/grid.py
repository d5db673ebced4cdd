"""A water shader pair drawn on OpenGL over a tessellated water grid: the user's own vertex
shader in place of the study's ``water.vert``.

:func:`grid_renderer_class` makes a subclass of a ``GLRenderer`` (``gl.renderer``) that draws
``GL_TRIANGLES`` of the grid (an index buffer, ``triangles`` in their order) with the given
vertex shader, its attributes from float32 buffers by name (a ``vec4`` read from three
components gets ``w = 1``, as GL fills it), its uniforms written from GL bytes by name, into
a framebuffer with a depth buffer, the depth test ``GL_LESS`` on (cleared to 1), no face
culling. The study's uniforms and samplers are set by their names as for the study's quad.
"""

from __future__ import annotations

import numpy as np

__all__ = ["grid_renderer_class"]

_GL_DEPTH_TEST = 0x0B71


def grid_renderer_class(
    base, vertex_source: str, attributes: dict, triangles, uniforms: dict, builtins=None
):
    """A subclass of ``base`` (``GLRenderer`` or a subclass) drawing the grid: ``attributes``
    name -> (V, k) float32 per-vertex values, ``triangles`` (T, 3) vertex indices, ``uniforms``
    name -> GL bytes (matrices column-major); ``builtins``: attribute name -> the compatibility
    built-in it is when ``vertex_source`` reads that instead (``gl_Vertex``, ... on a
    compatibility context, ``gl.dialect``). Constructed as ``base`` is; ``render(None)``."""
    builtins = dict(builtins or {})
    tris = np.ascontiguousarray(triangles, np.int32)

    class GridRenderer(base):
        def _setup_geometry(self) -> None:
            self._vert = vertex_source
            self._buffers = {
                n: (self.ctx.buffer(np.ascontiguousarray(a, np.float32).tobytes()), a.shape[1])
                for n, a in attributes.items()
            }
            self._ibo = self.ctx.buffer(tris.tobytes())
            size = (self.inputs.width, self.inputs.height)
            self._depth = self.ctx.depth_renderbuffer(size)

        def _vao(self, prog):
            content = [(buf, f"{k}f", n) for n, (buf, k) in self._buffers.items() if n in prog]
            vao = self.ctx.vertex_array(prog, content, index_buffer=self._ibo,
                                        index_element_size=4)  # fmt: skip
            # the attributes the program reads as compatibility built-ins (gl_Vertex, ...)
            named = {builtins[n]: (b, k, 0, 0) for n, (b, k) in self._buffers.items()
                     if n not in prog and n in builtins}  # fmt: skip
            self._fixed_function_arrays(vao, named)
            return vao

        def _program(self, frag_source: str):
            hit = self._programs.get(frag_source)
            if hit is None:
                try:
                    prog = self.ctx.program(vertex_shader=self._vert, fragment_shader=frag_source)
                except self._mgl.Error as exc:
                    raise RuntimeError(f"OpenGL rejected the shader pair:\n{exc}") from exc
                self._set_static_uniforms(prog)
                hit = self._programs[frag_source] = (prog, self._vao(prog))
            return hit

        def _set_static_uniforms(self, prog) -> None:
            super()._set_static_uniforms(prog)
            self._write_uniforms(prog, uniforms)

        def geometry(self) -> dict:
            """What ``draw`` draws: ``mode`` 'triangles', ``attributes`` as given, ``indices``
            (T, 3) int32, ``depth_test`` True (``GL_LESS``, cleared to 1)."""
            return {"mode": "triangles", "attributes": dict(attributes), "indices": tris,
                    "depth_test": True}  # fmt: skip

        def _draw_grid(self, vao) -> None:
            self.fbo.use()
            self.ctx.enable_direct(_GL_DEPTH_TEST)
            self.ctx.depth_func = "<"
            self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            vao.render(self._mgl.TRIANGLES)

        def _render_mask(self) -> np.ndarray:
            self.fbo = self.ctx.framebuffer(color_attachments=[self._color],
                                            depth_attachment=self._depth)  # fmt: skip
            prog = self.ctx.program(vertex_shader=self._vert, fragment_shader=self.MASK_FRAG)
            self._set_static_uniforms(prog)
            vao = self._vao(prog)
            self._draw_grid(vao)
            mask = self._read()[..., 0] > 0.5
            vao.release()
            prog.release()
            return mask

        def draw(self, constants=None) -> None:
            if constants is not None:
                raise ValueError("a grid renderer draws a user's shader pair: render(None)")
            prog, vao = self._program(self._frag_source(None))
            self._bind_textures()
            self._draw_grid(vao)

    return GridRenderer
