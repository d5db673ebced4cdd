"""Run a fragment shader that SPIRV-Cross wrote back as GLSL (the HLSL round trip) on OpenGL.

SPIRV-Cross renames what it translates: the HLSL's loose uniforms arrive in one std140 uniform
block (``$Global``), each texture and its sampler become one combined sampler
(``SPIRV_Cross_Combined<texture><sampler>``), and matrices may be stored row-major.
:class:`TranslatedRenderer` is a :class:`~shaders_port.gl.renderer.GLRenderer` that sets the same
inputs through those names, all read from the reflection of the SPIR-V
(:func:`shaders_port.spirv.tools.hlsl_round_trip`): the members' offsets, strides and layouts of the
block, and the texture/sampler pairs with their registers. Nothing is guessed from the text.
"""

from __future__ import annotations

import numpy as np

from .renderer import GLRenderer

_MATRIX_SIZE = {"mat2": 2, "mat3": 3, "mat4": 4}


class TranslatedRenderer(GLRenderer):
    """A GLRenderer for SPIRV-Cross GLSL of one of the water fragment shaders.

    Args:
        name: the shader file ('water_refraction', 'water_reflection', 'water_baseline').
        inputs: the ``ShaderInputs`` (as the variant's application uploads them).
        source: the GLSL 330 text from :func:`shaders_port.spirv.tools.hlsl_round_trip`.
        reflection: the reflection JSON returned with it.
    """

    def __init__(self, name: str, inputs, source: str, reflection: dict):
        self._members = self._block_members(reflection)
        self._combined = self._combined_samplers(reflection)
        self._ubo, self._data = None, None  # the uniform block's buffer and its bytes
        super().__init__(name, inputs, source=source)

    @staticmethod
    def _block_members(reflection: dict) -> dict:
        """Member name -> (offset, type, matrix stride, row-major) of the module's one uniform
        block (empty without one); RuntimeError if there are several."""
        ubos = reflection.get("ubos", [])
        if len(ubos) > 1:
            names = [u["name"] for u in ubos]
            raise RuntimeError(f"expected at most one uniform block, the shader has {names}")
        if not ubos:
            return {}
        block = reflection["types"][ubos[0]["type"]]
        return {
            m["name"]: (
                m["offset"],
                m["type"],
                m.get("matrix_stride", 16),
                bool(m.get("row_major", False)),
            )
            for m in block["members"]
        } | {"": (ubos[0]["block_size"], "", 0, False)}

    @staticmethod
    def _combined_samplers(reflection: dict) -> dict:
        """Texture name -> the combined sampler SPIRV-Cross makes of it and the sampler with the
        same register (binding)."""
        samplers = {s["binding"]: s["name"] for s in reflection.get("separate_samplers", [])}
        out = {}
        for img in reflection.get("separate_images", []):
            smp = samplers.get(img["binding"])
            if smp is None:
                raise RuntimeError(
                    f"texture {img['name']} (register t{img['binding']}) has no sampler in the "
                    f"same register; samplers: {sorted(samplers.values())}"
                )
            out[img["name"]] = f"SPIRV_Cross_Combined{img['name']}{smp}"
        for img in reflection.get("textures", []):  # already combined in the source
            out[img["name"]] = img["name"]
        return out

    def _block(self, prog):
        """The uniform block of ``prog`` (None for a program without one, e.g. the mask's)."""
        blocks = [prog[k] for k in prog if isinstance(prog[k], self._mgl.UniformBlock)]
        if len(blocks) > 1:
            raise RuntimeError(f"{self.name}: the program has {len(blocks)} uniform blocks")
        return blocks[0] if blocks else None

    def _reads(self, prog, uname: str) -> bool:
        return uname in prog or uname in self._members

    def _write_uniforms(self, prog, vals: dict) -> None:
        super()._write_uniforms(prog, vals)  # the vertex shader's, by their own names
        block = self._block(prog)
        if block is None:
            return
        size = max(self._members[""][0], block.size)  # GL pads the block to 16 bytes
        if self._data is None or len(self._data) != size:
            self._data = bytearray(size)
        data = self._data  # kept: a later call (the vertex shader's uniforms) writes its own
        for uname, raw in vals.items():
            if uname not in self._members:
                continue
            offset, typ, stride, row_major = self._members[uname]
            n = _MATRIX_SIZE.get(typ)
            if n is None:
                data[offset : offset + len(raw)] = raw
                continue
            cols = np.frombuffer(raw, np.float32).reshape(n, n)  # GL bytes: one column a row
            vecs = cols.T if row_major else cols
            for k in range(n):
                data[offset + k * stride : offset + k * stride + 4 * n] = vecs[k].tobytes()
        if self._ubo is not None:
            self._ubo.release()
        self._ubo = self.ctx.buffer(bytes(data))
        block.binding = 0
        self._ubo.bind_to_uniform_block(0)

    def _bind_textures(self) -> None:
        super()._bind_textures()
        if self._ubo is not None:
            self._ubo.bind_to_uniform_block(0)

    def _sampler_uniform(self, prog, sname: str) -> str | None:
        uname = self._combined.get(sname)
        if uname is None or not any(u in prog for u in self._combined.values()):
            return super()._sampler_uniform(prog, sname)  # not a translated program (the mask)
        if uname not in prog:
            raise RuntimeError(
                f"{self.name}: the translated shader reads {sname} but has no uniform {uname}; "
                f"its uniforms: {sorted(prog)}"
            )
        return uname
