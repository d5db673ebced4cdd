"""The names engines give a vertex shader's attributes and matrices, and their values for the
study's water grid.

A user's own vertex shader (``spirv.vertex``) reads its vertex attributes and uniforms by the
names its engine uses; every name of :data:`ENGINE_NAMES` binds itself to one *meaning* of
:data:`MEANINGS`, any other name through a ``// @study bind NAME MEANING_OR_NAME`` pragma of the
vertex file. Conventions of every value (those of the study, ``shaders_port.inputs``):

* world units, right-handed, ``+y`` up; the water plane is ``y = 0`` and the grid's vertices
  are given in world coordinates, so the model matrix is the identity;
* matrices act on column vectors, ``clip = projection * view * model * vec4(position, 1)``,
  and are uploaded column-major as GL does (``uniform mat4``); the projection is OpenGL's (NDC
  ``z`` in ``[-1, 1]``), the view a rigid transform into an eye space looking down ``-z``;
* the texture coordinate is the one the study's own quad carries, ``(x, z) / normal_tile``
  (``ShaderInputs.normal_tile``: world units per repeat of the normal map).

With ``up`` 'z' (the pair declares ``// @study up z``: ``spirv.engine_inputs.to_up``) every
world-space value is given in the Z-up frame ``(x, y, z) -> (x, -z, y)``: the grid's positions
lie on ``z = 0``, the normal is ``(0, 0, 1)``, the tangent ``(1, 0, 0, -1)`` as before (a
rotation keeps the cross product: ``cross(normal, tangent.xyz) * w`` is ``-y``, the study's
``+z``), a matrix taking world points is multiplied by ``R^T`` on its right, its inverse by ``R``
on its left, the camera position rotated; the texture coordinate and the projection stay.

``view`` and ``projection`` are recovered from the frame's ``view_proj`` and camera position
(``viewpos``): ``view = [R | -R eye]`` with ``R`` the camera's rotation
(``shaders_port.inputs.normal_matrix``), ``projection = view_proj * view^-1``; their product is
``view_proj``. A frame whose ``view_proj`` is not a perspective times a rigid view has no such
split: a shader reading either alone is refused with a message.
"""

from __future__ import annotations

import numpy as np

from ..inputs import ShaderInputs
from .engine_inputs import split_view, to_up

__all__ = [
    "MEANINGS",
    "ENGINE_NAMES",
    "STUDY_VERTEX_NAMES",
    "attribute_values",
    "TRANSPOSED",
    "meaning_of",
    "meaning_values",
]

# meaning -> (GLSL types it can be read as, what it is)
MEANINGS = {
    "position": (("vec3", "vec4"), "vertex position on the water grid, world units, y = 0 "
                 "(a vec4 gets w = 1, as GL fills a missing component)"),
    "uv": (("vec2", "vec3", "vec4"), "texture coordinate (x, z) / normal_tile (z, w = 0, 1)"),
    "normal": (("vec3", "vec4"), "the plane's normal (0, 1, 0)"),
    "tangent": (("vec3", "vec4"), "(1, 0, 0, -1): +x, where u grows; w so that "
                "cross(normal, tangent.xyz) * w = +z, where v grows"),
    "model": (("mat4",), "model -> world: the identity"),
    "view": (("mat4",), "world -> eye (rigid, looking down -z)"),
    "projection": (("mat4",), "eye -> clip (OpenGL, NDC z in [-1, 1])"),
    "viewProjection": (("mat4",), "projection * view: world -> clip"),
    "modelView": (("mat4",), "view * model"),
    "modelViewProjection": (("mat4",), "projection * view * model"),
    "modelInverse": (("mat4",), "inverse of model"),
    "viewInverse": (("mat4",), "inverse of view: eye -> world"),
    "projectionInverse": (("mat4",), "inverse of projection"),
    "viewProjectionInverse": (("mat4",), "inverse of viewProjection"),
    "modelViewInverse": (("mat4",), "inverse of modelView"),
    "modelViewProjectionInverse": (("mat4",), "inverse of modelViewProjection"),
    "normalMatrix": (("mat3",), "inverse transpose of modelView's upper 3x3 (the camera's "
                     "rotation R)"),
    "worldNormalMatrix": (("mat3",), "inverse transpose of model's upper 3x3: the identity"),
    "cameraPosition": (("vec3", "vec4"), "camera position, world units (a vec4 gets w = 1)"),
}  # fmt: skip

# name a shader declares -> (meaning, engines that use the name)
ENGINE_NAMES = {
    # attributes
    "position": ("position", "three.js, Babylon.js"),
    "inPosition": ("position", "jMonkeyEngine"),
    "iPos": ("position", "Urho3D"),
    "vertex": ("position", "OGRE"),
    "aVertex": ("position", "the study's water.vert"),
    "uv": ("uv", "three.js, Babylon.js"),
    "inTexCoord": ("uv", "jMonkeyEngine"),
    "iTexCoord": ("uv", "Urho3D"),
    "uv0": ("uv", "OGRE"),
    "aMultiTexCoord0": ("uv", "the study's water.vert"),
    "normal": ("normal", "three.js, Babylon.js, OGRE"),
    "inNormal": ("normal", "jMonkeyEngine"),
    "iNormal": ("normal", "Urho3D"),
    "tangent": ("tangent", "three.js, Babylon.js, OGRE"),
    "inTangent": ("tangent", "jMonkeyEngine"),
    "iTangent": ("tangent", "Urho3D"),
    # matrices
    "modelMatrix": ("model", "three.js"),
    "world": ("model", "Babylon.js, OGRE"),
    "g_WorldMatrix": ("model", "jMonkeyEngine"),
    "cModel": ("model", "Urho3D"),
    "WaterTransformationMatrix": ("model", "the study's water.vert"),
    "viewMatrix": ("view", "three.js"),
    "view": ("view", "Babylon.js"),
    "g_ViewMatrix": ("view", "jMonkeyEngine"),
    "cView": ("view", "Urho3D"),
    "projectionMatrix": ("projection", "three.js"),
    "projection": ("projection", "Babylon.js"),
    "g_ProjectionMatrix": ("projection", "jMonkeyEngine"),
    "viewProjection": ("viewProjection", "Babylon.js"),
    "g_ViewProjectionMatrix": ("viewProjection", "jMonkeyEngine"),
    "cViewProj": ("viewProjection", "Urho3D"),
    "viewProj": ("viewProjection", "OGRE"),
    "modelViewMatrix": ("modelView", "three.js"),
    "worldView": ("modelView", "Babylon.js, OGRE"),
    "g_WorldViewMatrix": ("modelView", "jMonkeyEngine"),
    "worldViewProjection": ("modelViewProjection", "Babylon.js"),
    "g_WorldViewProjectionMatrix": ("modelViewProjection", "jMonkeyEngine"),
    "worldViewProj": ("modelViewProjection", "OGRE"),
    "uModelViewProjectionMatrix": ("modelViewProjection", "the study's water.vert"),
    "g_WorldMatrixInverse": ("modelInverse", "jMonkeyEngine"),
    "g_ViewMatrixInverse": ("viewInverse", "jMonkeyEngine"),
    "cViewInv": ("viewInverse", "Urho3D"),
    "invView": ("viewInverse", "Babylon.js"),
    "g_ProjectionMatrixInverse": ("projectionInverse", "jMonkeyEngine"),
    "g_ViewProjectionMatrixInverse": ("viewProjectionInverse", "jMonkeyEngine"),
    "g_WorldViewMatrixInverse": ("modelViewInverse", "jMonkeyEngine"),
    "g_WorldViewProjectionMatrixInverse": ("modelViewProjectionInverse", "jMonkeyEngine"),
    "normalMatrix": ("normalMatrix", "three.js"),
    "g_NormalMatrix": ("normalMatrix", "jMonkeyEngine"),
    "g_WorldNormalMatrix": ("worldNormalMatrix", "jMonkeyEngine"),
    # the camera
    "cameraPosition": ("cameraPosition", "three.js"),
    "vEyePosition": ("cameraPosition", "Babylon.js (w = 1)"),
    "g_CameraPosition": ("cameraPosition", "jMonkeyEngine"),
    "cCameraPos": ("cameraPosition", "Urho3D"),
    "eyePosition": ("cameraPosition", "OGRE"),
}

# names of matrices their engine uploads row-major as GL's column-major (glUniformMatrix4fv
# without transpose) and its shaders multiply `vec4(p, 1.0) * cViewProj`: given transposed
TRANSPOSED = frozenset({"cModel", "cView", "cViewInv", "cViewProj"})  # Urho3D

# the study's uniforms a vertex shader may read besides (values from ``translated``)
STUDY_VERTEX_NAMES = ("wave1", "wave2", "wave3", "wave4")


def meaning_of(name: str, bindings: dict | None = None) -> str | None:
    """The meaning of the declared ``name``: through ``bindings`` (name -> a meaning or an
    engine name) first, then :data:`ENGINE_NAMES`; None when it has none."""
    target = (bindings or {}).get(name, name)
    if target in MEANINGS and target != name:
        return target
    hit = ENGINE_NAMES.get(target)
    return hit[0] if hit else (target if target in MEANINGS else None)


def attribute_values(grid, meaning: str, up: str = "y") -> np.ndarray:
    """(V, k) float64 per-vertex values of the attribute ``meaning`` ('position', 'uv',
    'normal', 'tangent') on ``grid`` (``pipeline.interpolate.Grid``), in the world frame
    ``up``."""
    n = len(grid.position)
    if meaning == "uv":
        return np.asarray(grid.uv, np.float64)
    if meaning == "tangent":
        return np.tile([1.0, 0.0, 0.0, -1.0], (n, 1))
    base = {"position": np.asarray(grid.position, np.float64),
            "normal": np.tile([0.0, 1.0, 0.0], (n, 1))}[meaning]  # fmt: skip
    return to_up(up, base, "vector")


_KIND = {
    "view": "matrix", "modelView": "matrix", "viewProjection": "matrix",
    "modelViewProjection": "matrix", "viewInverse": "inverse", "modelViewInverse": "inverse",
    "viewProjectionInverse": "inverse", "modelViewProjectionInverse": "inverse",
    "normalMatrix": "rotation", "cameraPosition": "vector",
}  # fmt: skip


def meaning_values(inputs: ShaderInputs, meaning: str, up: str = "y") -> np.ndarray:
    """The value of a uniform ``meaning`` on a frame, float64, in the world frame ``up`` (see
    the module doc): a (4, 4) or (3, 3) matrix (row-major, acting on column vectors) or a
    vector. ValueError naming the problem when the frame cannot give it."""
    v = _meaning_values(inputs, meaning)
    if meaning == "cameraPosition":
        return np.r_[to_up(up, v[:3], "vector"), 1.0]
    return to_up(up, v, _KIND[meaning]) if meaning in _KIND else v


def _meaning_values(inputs: ShaderInputs, meaning: str) -> np.ndarray:
    """:func:`meaning_values` in the study's Y-up frame."""
    vp = np.asarray(inputs.view_proj, np.float64)
    if meaning == "cameraPosition":
        return np.r_[np.asarray(inputs.viewpos, np.float64), 1.0]
    if meaning in ("model", "modelInverse"):
        return np.eye(4)
    if meaning == "worldNormalMatrix":
        return np.eye(3)
    if meaning in ("viewProjection", "modelViewProjection"):
        return vp
    if meaning in ("viewProjectionInverse", "modelViewProjectionInverse"):
        return np.linalg.inv(vp)
    try:
        view, proj = split_view(inputs)
    except ValueError as exc:
        raise ValueError(
            f"the vertex shader reads the {meaning} matrix, which this frame has not: "
            f"{exc}; read the view-projection product instead"
        ) from None
    table = {
        "view": view,
        "modelView": view,
        "projection": proj,
        "viewInverse": np.linalg.inv(view),
        "modelViewInverse": np.linalg.inv(view),
        "projectionInverse": np.linalg.inv(proj),
        "normalMatrix": view[:3, :3],
    }
    if meaning not in table:
        raise ValueError(f"{meaning!r} is no uniform meaning; the meanings: {', '.join(MEANINGS)}")
    return table[meaning]
