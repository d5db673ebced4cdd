"""Image instructions of the SPIR-V executor: texture lookups, fetches and queries.

A sampler binding is a ``pipeline.texture`` object (``Texture2D``, mipmapped or not, or
``CubeMap``). The lookups (GLSL -> SPIR-V):

* ``texture`` (``OpImageSampleImplicitLod``): on a mipmapped texture the level of detail is
  llvmpipe's, from the coordinates' differences over the pixel's quad (``spirv.quads``), plus
  a ``Bias`` operand (``texture(s, uv, bias)``); on a texture without mipmaps the level of
  detail changes nothing (its minification and magnification filters are the same) and none
  is computed;
* ``textureLod`` (``Lod``), ``textureGrad`` (``Grad``: the level of detail from the given
  gradients, per pixel, as llvmpipe), ``textureOffset`` / ``textureLodOffset`` / ...
  (``ConstOffset``: a texel offset within the selected level), ``textureProj`` (the
  ``Proj`` forms: the coordinate divided by its last component);
* ``texelFetch`` (``OpImageFetch``: a texel of a level, 0 outside it), ``textureSize``
  (``OpImageQuerySizeLod`` / ``OpImageQuerySize``), ``textureQueryLevels``,
  ``textureQueryLod``.

A mipmapped lookup with an implicit level of detail inside a loop whose trip count differs
between pixels is refused (GL leaves it undefined; ``textureLod``/``textureGrad`` are not).
Other image instructions (depth comparisons, gathers, storage images) raise
``UnsupportedInstruction`` naming the opcode and the line.
"""

from __future__ import annotations

import drjit as dr

from ..pipeline.texture import CubeMap, Texture2D, lod_from_gradients
from . import quads as _quads
from .ops import both, is_py, lift

_SAMPLES = (
    "OpImageSampleImplicitLod",
    "OpImageSampleExplicitLod",
    "OpImageSampleProjImplicitLod",
    "OpImageSampleProjExplicitLod",
)
IMAGE_OPS = _SAMPLES + (
    "OpImageFetch",
    "OpImage",
    "OpImageQuerySizeLod",
    "OpImageQuerySize",
    "OpImageQueryLevels",
    "OpImageQueryLod",
)


class ImageOps:
    """The image instructions of ``spirv.execute.Executor`` (a mixin: it uses the executor's
    ``get``, ``count``, ``base``, ``quads``, ``lane_loops`` and ``unsupported``)."""

    def image_op(self, ins, bm):
        op, o = ins.opname, ins.operands
        if op == "OpImage":
            return self.get(o[0])
        if op in _SAMPLES:
            return self.sample(ins, bm)
        tex = self._texture(ins)
        if op == "OpImageFetch":
            return self.fetch(ins, tex, bm)
        if op in ("OpImageQuerySizeLod", "OpImageQuerySize"):
            k = self.get(o[1]) if op == "OpImageQuerySizeLod" else 0
            if not isinstance(k, int):
                raise self.unsupported(ins, "a level that differs between pixels")
            if isinstance(tex, CubeMap):
                return [max(1, tex.size >> k)] * 2
            return [max(1, tex.width >> k), max(1, tex.height >> k)]
        if op == "OpImageQueryLevels":
            return 1 + len(getattr(tex, "levels", ()))
        # OpImageQueryLod: (the level accessed, the level of detail)
        lod = self._implicit_lod(ins, tex, self._coords(ins, self.get(o[1]), False))
        q = float(len(getattr(tex, "levels", ())))
        if is_py(lod):
            return [min(max(lod, 0.0), q), lod]
        return [dr.clip(lod, 0.0, q), lod]

    def _texture(self, ins):
        tex = self.get(ins.operands[0])
        if not isinstance(tex, (Texture2D, CubeMap)):
            raise self.unsupported(ins, "a sampler that is not bound to a study texture")
        return tex

    def _coords(self, ins, coord, proj: bool, cube: bool = True) -> list:
        """The lookup's coordinates; ``textureProj``'s divided by their last component (of a
        2D texture's ``vec4``, the third is ignored, as GLSL says)."""
        c = [lift(self.m, x, "float") for x in coord]
        if proj:
            if not cube and len(c) == 4:
                c = [c[0], c[1], c[3]]
            c = [x / c[-1] for x in c[:-1]]
        return c

    def _implicit_lod(self, ins, tex, c):
        """llvmpipe's level of detail of a mipmapped 2D texture at coordinates ``c``."""
        if not getattr(tex, "levels", ()):
            return 0.0
        if self.quads is None:
            raise self.unsupported(ins, "an implicit level of detail without the frame's quads")
        if self.lane_loops:
            raise self.unsupported(
                ins,
                "an implicit level of detail inside a loop whose trip count differs between "
                "pixels (undefined in GL); use textureLod or textureGrad there",
            )
        (dsdx, dsdy), (dtdx, dtdy) = (_quads.quad_gradients(self.m, self.quads, x) for x in c[:2])
        return lod_from_gradients(self.m, tex, dsdx, dtdx, dsdy, dtdy)

    def sample(self, ins, bm):
        o = ins.operands
        tex = self._texture(ins)
        proj = "Proj" in ins.opname
        c = self._coords(ins, self.get(o[1]), proj, isinstance(tex, CubeMap))
        operands = dict(o[2]) if len(o) > 2 else {}
        unknown = set(operands) - {"Bias", "Lod", "Grad", "ConstOffset"}
        if unknown:
            raise self.unsupported(ins, f"the image operand(s) {', '.join(sorted(unknown))}")
        offset = self.get(operands["ConstOffset"][0]) if "ConstOffset" in operands else (0, 0)
        eff = both(self.base, bm)
        active = True if eff.value is True else eff.value
        self.count("fetches", bm)
        if isinstance(tex, CubeMap):
            if len(c) != 3:
                raise self.unsupported(ins, f"a {len(c)}-component cube-map coordinate")
            texel = tex.sample(self.m, c[0], c[1], c[2], active)
        elif len(c) != 2:
            raise self.unsupported(ins, f"a {len(c)}-component 2D coordinate")
        elif not tex.levels:
            if tuple(offset) != (0, 0):
                texel = tex.filtered(self.m, 0, c[0], c[1], active, tuple(offset))
            else:
                texel = tex.sample(self.m, c[0], c[1], active)
        else:
            if "Lod" in operands:
                lod = self.get(operands["Lod"][0])
            elif "Grad" in operands:
                dx, dy = (self.get(g) for g in operands["Grad"])
                lod = lod_from_gradients(self.m, tex, dx[0], dx[1], dy[0], dy[1])
            else:
                lod = self._implicit_lod(ins, tex, c)
            if "Bias" in operands:
                lod = lod + self.get(operands["Bias"][0])
            texel = tex.sample_lod(self.m, c[0], c[1], lod, active, tuple(offset))
        texel = list(texel)
        return texel + [0.0, 0.0, 1.0][len(texel) - 1 :] if len(texel) < 4 else texel[:4]

    def fetch(self, ins, tex, bm):
        o = ins.operands
        if not isinstance(tex, Texture2D):
            raise self.unsupported(ins, "texelFetch of a cube map")
        operands = dict(o[2]) if len(o) > 2 else {}
        k = self.get(operands["Lod"][0]) if "Lod" in operands else 0
        off = self.get(operands["ConstOffset"][0]) if "ConstOffset" in operands else (0, 0)
        if not isinstance(k, int) or not 0 <= k <= len(tex.levels):
            raise self.unsupported(ins, "a texelFetch level that is not a constant of the chain")
        i, j = (lift(self.m, x, "int") + d for x, d in zip(self.get(o[1]), off))
        eff = both(self.base, bm)
        self.count("fetches", bm)
        texel = tex.texel(self.m, i, j, k, True if eff.value is True else eff.value)
        return texel + [0.0, 0.0, 1.0][len(texel) - 1 :] if len(texel) < 4 else texel[:4]
