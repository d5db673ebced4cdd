"""Slow per-pixel NumPy reference of the two water shaders (the tests' own, not installed).

Written independently of the Dr.Jit port from the GLSL text and the OpenGL texture rules:
one Python loop iteration per covered pixel, float32 arithmetic (``np.float32`` vectors),
``break`` statements as in the GLSL. Uses the same rasterisation (``pipeline.raster``) as the port.
Returns ``(color (H, W, 3) float32, diagnostics dict of (H, W) float32)``; non-finite colours
are returned as they are (not zeroed) so that tests can see them.
"""

from __future__ import annotations

import math

import numpy as np

from shaders_port.inputs import Constants, ShaderInputs
from shaders_port.pipeline.raster import rasterize_water

f32 = np.float32


def _norm(v):
    with np.errstate(all="ignore"):
        return (
            v * f32(1.0 / math.sqrt(float(np.dot(v, v))) if np.dot(v, v) > 0 else f32(np.inf))
        ).astype(f32)


def _mix(x, y, a):
    return (
        (x * (f32(1) - f32(a)) + y * f32(a)).astype(f32)
        if isinstance(x, np.ndarray)
        else f32(x * (f32(1) - f32(a)) + y * f32(a))
    )


def _clamp(x, lo, hi):
    return f32(min(max(x, lo), hi))


def _wrap(i, n, repeat):
    return i % n if repeat else min(max(i, 0), n - 1)


def _tex2d(arr, s, t, linear, repeat):
    """GL texture2D on a (H, W, C) array; returns (C,) float32."""
    H, W = arr.shape[:2]
    if not linear:
        i = _wrap(math.floor(f32(s) * f32(W)), W, repeat)
        j = _wrap(math.floor(f32(t) * f32(H)), H, repeat)
        return arr[j, i].astype(f32)
    u, v = f32(f32(s) * f32(W) - f32(0.5)), f32(f32(t) * f32(H) - f32(0.5))
    fu, fv = math.floor(u), math.floor(v)
    a, b = f32(u - f32(fu)), f32(v - f32(fv))
    i0, i1 = _wrap(fu, W, repeat), _wrap(fu + 1, W, repeat)
    j0, j1 = _wrap(fv, H, repeat), _wrap(fv + 1, H, repeat)
    one = f32(1)
    return (
        (one - a) * (one - b) * arr[j0, i0]
        + a * (one - b) * arr[j0, i1]
        + (one - a) * b * arr[j1, i0]
        + a * b * arr[j1, i1]
    ).astype(f32)


def _cube(cube, d):
    """GL textureCube with table 8.19 (ties: x, then y, then z), bilinear clamp within the face."""
    x, y, z = (f32(c) for c in d)
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax >= ay and ax >= az:
        face, sc, tc, ma = (0, -z, -y, ax) if x >= 0 else (1, z, -y, ax)
    elif ay >= az:
        face, sc, tc, ma = (2, x, z, ay) if y >= 0 else (3, x, -z, ay)
    else:
        face, sc, tc, ma = (4, x, -y, az) if z >= 0 else (5, -x, -y, az)
    s = f32(0.5) * (f32(sc) / ma + f32(1))
    t = f32(0.5) * (f32(tc) / ma + f32(1))
    return _tex2d(cube[face], s, t, True, False)


def _texmat(M, p):
    q = M @ np.array([p[0], p[1], p[2], 1.0], dtype=f32)
    return f32(q[0]), f32(q[1])


def _pixel(inp, C, world, eye, light, tcs, reflection, raycast_reflections):
    diag = {}
    M0 = inp.tex_matrix0
    wy = inp.world_y[..., None]
    # [1]
    vEye, vLight = _norm(eye), _norm(light)
    # [2]
    bumps = [_tex2d(inp.normal_map, tc[0], tc[1], True, True) for tc in tcs]
    vBumpTex = _norm((f32(2) * (bumps[0] + bumps[1] + bumps[2] + bumps[3]) - f32(4)).astype(f32))
    vBumpTexMore = _norm((vBumpTex * np.array([1, C.bumptex_mult, 1], f32)).astype(f32))
    # [3]
    I, N, eta = -vEye, vBumpTexMore, f32(C.refr_coeff)
    d = f32(np.dot(N, I))
    k = f32(1) - eta * eta * (f32(1) - d * d)
    R = np.zeros(3, f32) if k < 0 else (eta * I - (eta * d + f32(math.sqrt(k))) * N).astype(f32)
    R = _norm(R)
    numsteps = _mix(f32(C.steps_grazing), f32(C.steps_steep), -R[1])
    R = (R * (f32(1) / numsteps)).astype(f32)
    # [4]
    cp = world.copy()
    cpo = cp.copy()
    olddepth = f32(0)
    depth = _tex2d(wy, *_texmat(M0, cp), False, False)[0]
    it, crossed = 0, False
    for _ in range(C.loop_cap):
        it += 1
        cpo = cp.copy()
        cp = (cp + R).astype(f32)
        olddepth = depth
        depth = _tex2d(wy, *_texmat(M0, cp), False, False)[0]
        if depth > cp[1]:
            crossed = True
            break
    # [5]
    cpoy, cpy = cpo[1], cp[1]
    den = f32(cpoy - cpy + depth - olddepth)
    with np.errstate(all="ignore"):
        cp = _mix(cpo, cp, f32((cpoy - olddepth) / den))
    vRefraction = np.append(_tex2d(inp.refraction_texture, *_texmat(M0, cp), True, False), f32(1))
    # [6]
    travelLength = _clamp(
        f32(math.sqrt(float(np.dot(cp - world, cp - world)))) / f32(C.attenuation_distance), 0, 1
    )
    vRefraction = _mix(vRefraction, np.array(C.water_color, f32), travelLength)
    fetches = 4 + 1 + it + 1
    diag.update(iterations=it, crossed=float(crossed), denominator=abs(float(den)))
    if not reflection:
        diag["fetches"] = fetches
        return vRefraction[:3], diag
    # [7]
    R = _norm((I - f32(2) * f32(np.dot(N, I)) * N).astype(f32))
    R[1] = max(R[1], f32(0.001))
    refl_color = np.array(C.reflect_color, f32)
    if not raycast_reflections:
        vReflection = (
            np.append(_cube(inp.cubemap, _norm(R) * np.array([1, -1, 1], f32)), f32(1)) * refl_color
        )
    else:
        vReflection, rdiag, rfetches = _raycast_reflection(inp, C, world, R, refl_color)
        diag.update(rdiag)
        fetches += rfetches
    # [8]
    rLight = (f32(np.dot(f32(2) * vBumpTex, vLight)) * vBumpTex - vLight).astype(f32)
    c = _clamp(f32(np.dot(rLight, vEye)), 0, 1)
    p = f32(0) if c <= 0 else f32(2.0 ** (float(C.specular_exponent) * math.log2(float(c))))
    specular = np.append(p * inp.lightcolor, f32(1)).astype(f32)
    vReflection = (vReflection + specular * f32(C.specular_strength)).astype(f32)
    # [9]
    NdotV = _clamp(f32(np.dot(vEye, vBumpTex)), 0, 1)
    F = _tex2d(inp.fresnel_lut[None], NdotV, 0.5, False, False)
    diag["fetches"] = fetches + 2
    return (vReflection * F[1] + vRefraction * F[0])[:3].astype(f32), diag


def _raycast_reflection(inp, C, world, R, refl_color):
    """Block [7] of water_reflection for one pixel: the reflection ray ``R`` (unit, float32)
    raycast against the bottom-up textures, the cube map where nothing is hit. Returns
    ``(vReflection`` (4,) float32, diagnostics, texture fetches)."""
    M1 = inp.tex_matrix1
    R = _norm(R)
    numsteps = _mix(f32(C.refl_steps_steep), f32(C.refl_steps_grazing), f32(1) - R[1])
    R = (R * (f32(1) / numsteps)).astype(f32)
    ry = inp.refl_world_y[..., None]
    cp = world.copy()
    cpo = cp.copy()
    olddepth = f32(0)
    depth = _tex2d(ry, *_texmat(M1, cp), False, False)[0]
    noHit, rit = True, 0
    fetches = 1
    for _ in range(C.refl_loop_cap):
        rit += 1
        cpo = cp.copy()
        cp = (cp + R).astype(f32)
        s, t = _texmat(M1, cp)
        if s < 0 or s > 1 or t < 0 or t > 1:
            break
        olddepth, depth = depth, _tex2d(ry, s, t, False, False)[0]
        fetches += 1
        if depth > cp[1]:
            noHit = False
            break
        if cp[1] > f32(C.refl_height_cut):
            break
    if not noHit:
        cpoy, cpy = cpo[1], cp[1]
        with np.errstate(all="ignore"):
            cp = _mix(cpo, cp, f32((cpoy - olddepth) / (cpoy - cpy + depth - olddepth)))
        vReflection = (
            np.append(_tex2d(inp.refl_texture, *_texmat(M1, cp), True, False), f32(1)) * refl_color
        )
    else:
        vReflection = (
            np.append(_cube(inp.cubemap, _norm(R) * np.array([1, -1, 1], f32)), f32(1)) * refl_color
        )
    return vReflection, {"refl_iterations": rit, "refl_hit": float(not noHit)}, fetches


def render_reference(
    name: str, inputs: ShaderInputs, constants: Constants | None = None, *, reflection: bool = True
):
    """Per-pixel reference of ``name`` ('water_refraction' or 'water_reflection')."""
    C = (constants or Constants()).validate()
    if name not in ("water_refraction", "water_reflection"):
        raise ValueError(f"unknown shader {name!r}")
    r = rasterize_water(inputs)
    H, W = inputs.height, inputs.width
    color = np.zeros((H * W, 3), np.float32)
    keys = ["iterations", "fetches", "crossed", "denominator"]
    if name == "water_reflection":
        keys += ["refl_iterations", "refl_hit"]
    diag = {k: np.zeros(H * W, np.float32) for k in keys}
    for n, idx in enumerate(r.index):
        col, d = _pixel(
            inputs,
            C,
            r.world[n],
            r.vec_eye[n],
            r.vec_light[n],
            r.texcoord[:, n],
            reflection or name == "water_reflection",
            name == "water_reflection",
        )
        color[idx] = col
        for k, v in d.items():
            diag[k][idx] = v
    return color.reshape(H, W, 3), {k: v.reshape(H, W) for k, v in diag.items()}
