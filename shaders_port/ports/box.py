"""The box-projected (local) cube map of Lagarde and Zanuttini, read by ``water_refraction``
compiled with ``BOX_REFLECTION`` (block [7]).

A cube map of the scene without the water captured at one point is exact for reflected rays
leaving from that point only; from a water point elsewhere it shows the walls at the wrong
place (a sky cube map shows no walls at all). The local cube map corrects the direction: the
reflected ray from the water point is intersected with a proxy of the scene, the box of the
pool's walls, and the cube map is looked up towards the hit point from where it was captured.
Here the box's top (``box_max.y``, the walls' top) is open: a ray that leaves through it sees
the distant sky, which is looked up along the ray itself.

The state a shader needs is :class:`BoxProbe` (made by :func:`box_state`): the cube map
(``CubeMap``, linear RGB, the study's ``y`` flip), the box's corners and the capture point
(world units, float32-valued Python tuples).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import numpy as np

from ..inputs import BOX_INPUTS, ShaderInputs
from ..pipeline.texture import CubeMap

# the floor of |R| per axis in the box's slab distances (no division by zero)
MIN_COMPONENT = 1e-6


@dataclass
class BoxProbe:
    """The local cube map and its box (freeze-traversable)."""

    boxReflectionTexture: object
    boxMin: tuple
    boxMax: tuple
    boxCapturePosition: tuple


def _vec3(v) -> tuple:
    return tuple(float(x) for x in np.asarray(v, np.float32))


def box_state(m, inputs: ShaderInputs, shader: str) -> BoxProbe:
    """Upload the local cube map and its box; a ValueError names what ``inputs`` lacks."""
    inputs.require(BOX_INPUTS, shader, "study.scene.box_inputs.with_box_inputs")
    return BoxProbe(
        boxReflectionTexture=CubeMap.from_numpy(m, inputs.box_cubemap),
        boxMin=_vec3(inputs.box_min),
        boxMax=_vec3(inputs.box_max),
        boxCapturePosition=_vec3(inputs.box_capture),
    )


def box_lookup(m, B: BoxProbe, origin, R):
    """The local cube map's lookup direction (Array3f, not normalised) of the ray ``origin +
    t R`` (``R``: Array3f, ``R.y > 0``): ``boxHit - boxCapturePosition`` where the ray leaves
    the box through a wall (``boxHit.y < boxMax.y``), else ``R`` (through the open top)."""
    lo, hi = m.Array3f(*B.boxMin), m.Array3f(*B.boxMax)
    boxPlane = dr.select(R >= 0.0, hi, lo)  # mix(boxMin, boxMax, step(0.0, R))
    boxT = dr.abs(boxPlane - origin) / dr.maximum(dr.abs(R), MIN_COMPONENT)
    boxHit = origin + dr.minimum(boxT.x, boxT.z) * R
    return dr.select(boxHit.y < B.boxMax[1], boxHit - m.Array3f(*B.boxCapturePosition), R)


def box_reflection(m, P, B: BoxProbe, C, R):
    """Block [7] with ``BOX_REFLECTION``: ``textureCube(boxReflectionTexture,
    normalize(boxLookup) * vec3(1, -1, 1)) * reflectColor`` (Array4f, linear RGB); one fetch.
    ``R``: the reflected direction after the seed's ``R.y`` clamp."""
    d = dr.normalize(box_lookup(m, B, P.varyingVecWorldPosition, R)) * m.Array3f(1.0, -1.0, 1.0)
    c = B.boxReflectionTexture.sample(m, d.x, d.y, d.z)
    return m.Array4f(*c, 1.0) * C.reflectColor
