"""What OpenGL's rasteriser hands the water fragment shaders, per pixel.

The vertex shader ``water`` outputs varyings that are affine functions of the world
position of the vertex on the water plane ``y = 0``::

    varyingVecWorldPosition = p
    varyingVecEye           = viewpos - p
    varyingVecLight         = lightpos - p
    gl_TexCoord[k]          = ((p.x, p.z) / normal_tile + wave_k, 0, 1)

Perspective-correct interpolation of an attribute that is affine in the world position
over a planar primitive gives exactly that affine function evaluated at the surface point
seen through the pixel centre. So each pixel's varyings are computed here from the
intersection of the camera ray through the pixel centre with ``y = 0`` (in float64, then
rounded to float32). A pixel is covered when that point lies in ``water_rect``, in front of
the camera and inside the near/far clip range.

Pixel ``(row r, column c)`` of the image (row 0 at the top) has its centre at window
coordinates ``(c + 0.5, H - r - 0.5)`` (GL window origin at the bottom left).
"""

from __future__ import annotations

import dataclasses
import itertools
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..inputs import ShaderInputs
from .interpolate import plane_points
from .texture import CLAMP, LINEAR, NEAREST, REPEAT, CubeMap, Texture2D


@dataclass
class Raster:
    """Per-pixel varyings of the water quad (NumPy).

    Attributes:
        mask: (H, W) bool, True where the quad covers the pixel centre.
        index: (N,) int64 flat pixel indices ``r * W + c`` of the covered pixels, in order.
        world: (N, 3) float32 ``varyingVecWorldPosition`` (world units, y = 0).
        vec_eye: (N, 3) float32 ``varyingVecEye``.
        vec_light: (N, 3) float32 ``varyingVecLight``.
        texcoord: (4, N, 2) float32 ``gl_TexCoord[k].xy``.
        width, height: image size in pixels.
    """

    mask: np.ndarray
    index: np.ndarray
    world: np.ndarray
    vec_eye: np.ndarray
    vec_light: np.ndarray
    texcoord: np.ndarray
    width: int
    height: int


def rasterize_water(inputs: ShaderInputs) -> Raster:
    """Coverage and interpolated varyings of the water quad for ``inputs.width x inputs.height``."""
    W, H = inputs.width, inputs.height
    vp = inputs.view_proj.astype(np.float64)
    c, r = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    p, t = plane_points(vp, W, H, c, r)
    x0, z0, x1, z1 = inputs.water_rect
    clip = np.concatenate([p, np.ones_like(p[..., :1])], -1) @ vp.T
    w = clip[..., 3]
    mask = (
        np.isfinite(t)
        & (t >= 0.0)
        & (t <= 1.0)
        & (w > 0)
        & (np.abs(clip[..., 2]) <= w)
        & (p[..., 0] >= x0)
        & (p[..., 0] <= x1)
        & (p[..., 2] >= z0)
        & (p[..., 2] <= z1)
    )
    index = np.flatnonzero(mask.ravel())
    world = p.reshape(-1, 3)[index]
    base = world[:, [0, 2]] / inputs.normal_tile
    texcoord = np.stack([base + inputs.waves[k].astype(np.float64) for k in range(4)])
    return Raster(
        mask=mask,
        index=index,
        world=world.astype(np.float32),
        vec_eye=(inputs.viewpos.astype(np.float64) - world).astype(np.float32),
        vec_light=(inputs.lightpos.astype(np.float64) - world).astype(np.float32),
        texcoord=texcoord.astype(np.float32),
        width=W,
        height=H,
    )


@dataclass
class Prepared:
    """Dr.Jit copies of one frame's inputs (textures, varyings of the covered pixels).

    Lanes are the covered pixels in ``raster.index`` order. ``varyingVec*`` are Array3f;
    ``texcoord[k]`` is ``(s, t)`` Float pairs; samplers are ``pipeline.texture`` objects named
    like the GLSL uniforms; ``tex_matrix0/1`` are nested tuples of the float32 entries and
    ``lightcolor`` a tuple (hashable: :meth:`shading_state` is a ``dr.freeze`` argument).
    """

    raster: Raster
    inputs: ShaderInputs
    varyingVecWorldPosition: object
    varyingVecEye: object
    varyingVecLight: object
    texcoord: list
    refractionTexture: object
    worldYComponent: object
    normalMap: object
    reflectionTexture: object
    fresnelLookup: object
    worldYComponentReflection: object
    reflectionBottom: object
    tex_matrix0: tuple
    tex_matrix1: tuple
    lightcolor: tuple
    # a number of its own per call of prepare() that uploaded (see pipeline.frame.call_frozen)
    upload: int = 0
    # what LEAN_NORMALS reads, set by pipeline.normal_maps.with_lean: the mipmapped slopeMoments
    # texture and each layer's level of detail there (a Float per lane); None otherwise
    slopeMoments: object = None
    slopeLod: tuple | None = None
    # what PARALLAX_OFFSET reads (pipeline.normal_maps.with_maps): the heightMap texture
    heightMap: object = None

    def shading_state(self) -> "Prepared":
        """A copy without the NumPy-holding ``raster`` / ``inputs`` (what the shader reads)."""
        return dataclasses.replace(self, raster=None, inputs=None)


# the last few frames uploaded (a joint fit alternates between its scenes), least recent first
_CACHE: OrderedDict = OrderedDict()
_CACHE_SIZE = 8
_UPLOADS = itertools.count(1)


def _mat_tuple(M: np.ndarray) -> tuple:
    return tuple(tuple(float(v) for v in row) for row in np.asarray(M, np.float32))


def prepare(inputs: ShaderInputs, m) -> Prepared:
    """Rasterise and upload ``inputs`` for the Dr.Jit type module ``m`` (cached per inputs object,
    the last eight kept; the cache entry is not used when any array of ``inputs`` is replaced)."""
    if not isinstance(inputs, ShaderInputs):
        raise TypeError(f"expected ShaderInputs, got {type(inputs).__name__}")
    key = (id(inputs), m.__name__)
    arrays = tuple(id(v) for v in vars(inputs).values())
    hit = _CACHE.get(key)
    if hit is not None and hit[0] == arrays and hit[1].inputs is inputs:
        _CACHE.move_to_end(key)
        return hit[1]
    r = rasterize_water(inputs)
    if r.index.size == 0:
        raise ValueError(
            "the water quad covers no pixel: check water_rect, view_proj and "
            "the camera position in ShaderInputs"
        )
    lut = inputs.fresnel_lut[None, :, :]
    P = Prepared(
        raster=r,
        inputs=inputs,
        varyingVecWorldPosition=m.Array3f(r.world.T),
        varyingVecEye=m.Array3f(r.vec_eye.T),
        varyingVecLight=m.Array3f(r.vec_light.T),
        texcoord=[(m.Float(r.texcoord[k, :, 0]), m.Float(r.texcoord[k, :, 1])) for k in range(4)],
        refractionTexture=Texture2D.from_numpy(m, inputs.refraction_texture, LINEAR, CLAMP),
        worldYComponent=Texture2D.from_numpy(m, inputs.world_y, NEAREST, CLAMP),
        normalMap=Texture2D.from_numpy(m, inputs.normal_map, LINEAR, REPEAT),
        reflectionTexture=CubeMap.from_numpy(m, inputs.cubemap),
        fresnelLookup=Texture2D.from_numpy(m, lut, NEAREST, CLAMP),
        worldYComponentReflection=Texture2D.from_numpy(m, inputs.refl_world_y, NEAREST, CLAMP),
        reflectionBottom=Texture2D.from_numpy(m, inputs.refl_texture, LINEAR, CLAMP),
        tex_matrix0=_mat_tuple(inputs.tex_matrix0),
        tex_matrix1=_mat_tuple(inputs.tex_matrix1),
        lightcolor=tuple(float(v) for v in inputs.lightcolor),
        upload=next(_UPLOADS),
    )
    _CACHE[key] = (arrays, P)
    _CACHE.move_to_end(key)
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return P
