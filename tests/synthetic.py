"""Small analytic shader inputs (NumPy only) for tests of the shader layer."""
from __future__ import annotations

import numpy as np

from shaders_port import ShaderInputs, fresnel_lut, ortho_tex_matrix, perspective_view_proj


def synthetic_inputs(width: int = 64, height: int = 48, tex: int = 128, seed: int = 0) -> ShaderInputs:
    """A 4x4 pool, floor sloping from y=-0.4 to y=-1.6, checker floor, sinusoidal normal map,
    gradient sky, a wall rising above the water on one side for the reflection shader."""
    rng = np.random.default_rng(seed)
    x0, z0, x1, z1 = -2.5, -2.5, 2.5, 2.5
    s = (np.arange(tex) + 0.5) / tex
    X = x0 + s[None, :] * (x1 - x0)
    Z = z0 + s[:, None] * (z1 - z0)
    world_y = (-1.0 + 0.3 * X / 2.5 + 0.1 * np.sin(2.0 * Z)).astype(np.float32)
    checker = ((np.floor(X * 2) + np.floor(Z * 2)) % 2)[..., None]
    colour = (0.2 + 0.6 * checker * np.array([0.9, 0.8, 0.6]) + 0.1 * rng.random((tex, tex, 3)))
    # normal map of h(u, v) = a sin(2 pi u) sin(2 pi 2 v), tile 1.25 world units
    n = 64
    u = (np.arange(n) + 0.5) / n
    U, V = np.meshgrid(u, u)
    tile, a = 1.25, 0.04
    hx = a * 2 * np.pi * np.cos(2 * np.pi * U) * np.sin(4 * np.pi * V) / tile
    hz = a * 4 * np.pi * np.sin(2 * np.pi * U) * np.cos(4 * np.pi * V) / tile
    nrm = np.stack([-hx, np.ones_like(hx), -hz], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    f = 16
    sky = np.zeros((6, f, f, 3), np.float32)
    for face in range(6):
        sky[face] = np.linspace(0.3, 1.0, f)[:, None, None] * np.array([0.5, 0.7, 1.0]) * (1 + 0.1 * face)
    refl_y = np.full((tex, tex), -1e3, np.float32)
    refl_y[:, : tex // 6] = 0.6          # a wall along x = x0 .. x0 + 0.8, 0.6 high
    refl_col = np.zeros((tex, tex, 3), np.float32)
    refl_col[:, : tex // 6] = (0.8, 0.3, 0.2)
    eye = (0.3, 2.5, 4.5)
    return ShaderInputs(
        refraction_texture=colour, world_y=world_y, tex_matrix0=ortho_tex_matrix(x0, z0, x1, z1),
        normal_map=0.5 * nrm + 0.5, cubemap=sky, fresnel_lut=fresnel_lut(),
        refl_world_y=refl_y, refl_texture=refl_col, tex_matrix1=ortho_tex_matrix(x0, z0, x1, z1),
        water_rect=(-2.0, -2.0, 2.0, 2.0), normal_tile=tile,
        waves=np.array([[0.0, 0.0], [0.31, 0.17], [0.53, 0.71], [0.13, 0.47]]),
        view_proj=perspective_view_proj(eye, (0.0, -0.8, 0.0), fov_y_deg=50.0, aspect=width / height),
        viewpos=np.array(eye), lightpos=np.array([-3.0, 6.0, -8.0]), lightcolor=np.array([1.0, 0.95, 0.8]),
        width=width, height=height)
