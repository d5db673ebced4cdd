"""The reference's water surface made from a user's shader (``waves.source = "shader"``).

An engine's water shader makes its waves its own way (taps of its own normal-map image at its
own scales and speeds, a DuDv distortion, noise). With ``waves.source = "shader"`` the
reference's water has those waves, not the study's height field (``geometry.Waves``):

1. **Read.** The shader (``fit.shader``, through its vertex shader where it has one) runs at its
   start values over a regular grid of the water plane: a camera straight above the pool
   (:func:`probe_inputs`) whose pixel centres are the grid's points, ``waves.shader_grid``
   along the water's longer side. The variable its declaration names
   (``// @study normal NAME [world|tangent]``) is read where ``main`` returns
   (``shaders_port.spirv.probe``), as a unit normal ``n`` in the study's frame (``+y`` up).
2. **Integrate.** Its slopes ``(-n_x / n_y, -n_z / n_y)`` are integrated into the height field
   ``H`` whose differences fit them best in least squares (:func:`integrate`: the normal
   equations are the Neumann Laplacian, solved exactly by a type-II DCT). The field's mean
   is 0 (the water plane ``y = 0``).
3. **Scale.** ``H`` is multiplied by ``waves.height_scale`` (1: the shader's own waves), a
   known factor for a fit to recover.

The surface (:class:`ShaderWaves`) answers ``height_and_gradient(x, z)`` as ``Waves`` does
(bilinear interpolation of ``H`` and of its central differences), so the water mesh of the
reference and of every input derived from the waves (the floor's light through the surface,
its caustics, the top-down renders) is this surface. What no surface has, the curl of the
shader's normal field, is measured (:attr:`ShaderWaves.stats`): the mean and 99th-percentile
angle between the shader's normals and the integrated surface's. Every input that does not
come from the waves (textures, sky, camera) plays no part in the normals: the probe gives the
shader placeholders for them, and a shader whose normal reads one of them gets its waves from
those placeholders.
"""

from __future__ import annotations

import math

import numpy as np

from shaders_port import ShaderInputs, perspective_view_proj
from shaders_port.spirv.probe import surface_normals

from ..config.experiment import Experiment
from ..config.user_shader import load_user_shader
from .geometry import Waves

_SURFACES: dict = {}  # scene hash -> ShaderWaves (the last few)
# the probe camera's field of view, degrees: it stands d = 115 half-extents above the water, so
# a point a vertex shader lifts by y is seen off its own (x, z) by y / d of its distance from
# the centre
PROBE_FOV_DEG = 1.0


def integrate(gx: np.ndarray, gz: np.ndarray, dx: float, dz: float) -> np.ndarray:
    """(Nz, Nx) float64 height field ``H`` (mean 0) on the grid of the slopes ``gx = dH/dx``,
    ``gz = dH/dz`` ((Nz, Nx), rows along z, columns along x, spacings ``dx``, ``dz`` world
    units) minimising ``sum (H[i, j+1] - H[i, j] - dx (gx[i, j] + gx[i, j+1]) / 2)^2 +
    sum (H[i+1, j] - H[i, j] - dz (gz[i, j] + gz[i+1, j]) / 2)^2``: exact for a gradient
    field up to the trapezoid rule's error, the least-squares surface for any other. The
    normal equations ``(Dx^T Dx + Dz^T Dz) H = Dx^T bx + Dz^T bz`` have the Neumann Laplacian,
    which the orthonormal type-II DCT diagonalises (eigenvalues ``2 - 2 cos(pi k / N)``)."""
    from scipy.fft import dctn, idctn

    nz, nx = gx.shape
    bx = 0.5 * dx * (gx[:, :-1] + gx[:, 1:])
    bz = 0.5 * dz * (gz[:-1, :] + gz[1:, :])
    rhs = np.zeros((nz, nx))
    rhs[:, 1:] += bx
    rhs[:, :-1] -= bx
    rhs[1:, :] += bz
    rhs[:-1, :] -= bz
    lam = (2 - 2 * np.cos(np.pi * np.arange(nz) / nz))[:, None] + (
        2 - 2 * np.cos(np.pi * np.arange(nx) / nx)
    )[None, :]
    spec = dctn(rhs, type=2, norm="ortho")
    lam[0, 0] = 1.0
    spec /= lam
    spec[0, 0] = 0.0  # the mean: the water plane
    return idctn(spec, type=2, norm="ortho")


def angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles in degrees between the unit vectors ``a`` and ``b`` (..., 3)."""
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


class ShaderWaves:
    """A water surface sampled on a regular grid: ``h`` (Nz, Nx) float64 heights, world units,
    at ``x = x0 + j dx``, ``z = z0 + i dz``; ``stats`` what was measured on the way (see
    :func:`shader_waves`)."""

    def __init__(self, h: np.ndarray, x0: float, z0: float, dx: float, dz: float, stats: dict):
        self.h, self.x0, self.z0, self.dx, self.dz = h, x0, z0, dx, dz
        gz, gx = np.gradient(h, dz, dx)
        self.gx, self.gz, self.stats = gx, gz, stats

    def normals(self) -> np.ndarray:
        """(Nz, Nx, 3) unit normals of the surface at its grid points."""
        n = np.stack([-self.gx, np.ones_like(self.gx), -self.gz], -1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def height_and_gradient(self, x, z):
        """Height and gradient (dH/dx, dH/dz) at world (x, z), bilinear between the grid's
        points, clamped at its edges; arrays of x's shape (float64)."""
        x, z = np.asarray(x, np.float64), np.asarray(z, np.float64)
        nz, nx = self.h.shape
        u = np.clip((x - self.x0) / self.dx, 0, nx - 1)
        v = np.clip((z - self.z0) / self.dz, 0, nz - 1)
        j = np.minimum(np.floor(u).astype(int), nx - 2)
        i = np.minimum(np.floor(v).astype(int), nz - 2)
        fu, fv = u - j, v - i

        def at(a):
            return (1 - fv) * ((1 - fu) * a[i, j] + fu * a[i, j + 1]) + fv * (
                (1 - fu) * a[i + 1, j] + fu * a[i + 1, j + 1]
            )

        return at(self.h), at(self.gx), at(self.gz)


def probe_grid(exp: Experiment) -> tuple[int, int]:
    """``(Nx, Nz)`` samples of the water's extent, ``waves.shader_grid`` along the longer side."""
    hx, hz = exp.pool.half_extent
    n = int(exp.waves.shader_grid)
    return (n, max(8, round(n * hz / hx))) if hx >= hz else (max(8, round(n * hx / hz)), n)


def probe_inputs(exp: Experiment, normal_map: np.ndarray) -> ShaderInputs:
    """The shader's inputs for reading its normals: a camera straight above the pool's centre
    (:data:`PROBE_FOV_DEG`, looking down ``-y``, image up ``-z``) whose ``Nx x Nz`` pixel
    centres are the points ``x = -hx + (j + 0.5) 2 hx / Nx``, ``z = -hz + (i + 0.5) 2 hz / Nz``
    of the water plane
    (row ``i`` of the image from the top: a view straight down maps the plane affinely); the
    study's normal map ``normal_map`` ((S, S, 3) encoded, what ``normalMap`` and ``dudv_map``
    give), its wave offsets, ``time`` = ``waves.time``; 8x8 placeholders of no colour for
    every texture that is not the waves'."""
    hx, hz = exp.pool.half_extent
    nx, nz = probe_grid(exp)
    fov = PROBE_FOV_DEG
    d = hz / math.tan(math.radians(fov) / 2)
    eye = (0.0, d, 0.0)
    vp = perspective_view_proj(eye, (0.0, 0.0, 0.0), (0.0, 0.0, -1.0), fov, hx / hz, d / 2, 2 * d)
    z8 = np.zeros((8, 8, 3), np.float32)
    return ShaderInputs(
        refraction_texture=z8,
        world_y=np.full((8, 8), -1.0, np.float32),
        tex_matrix0=np.eye(4, dtype=np.float32),
        normal_map=np.asarray(normal_map, np.float32),
        cubemap=np.zeros((6, 8, 8, 3), np.float32),
        fresnel_lut=np.zeros((8, 2), np.float32),
        refl_world_y=np.full((8, 8), -1e3, np.float32),
        refl_texture=z8,
        tex_matrix1=np.eye(4, dtype=np.float32),
        water_rect=(-hx, -hz, hx, hz),
        normal_tile=exp.waves.normal_tile,
        waves=np.asarray(exp.waves.offsets, np.float32),
        view_proj=vp,
        viewpos=np.asarray(eye, np.float32),
        lightpos=np.asarray((0.0, 1000.0, 0.0), np.float32),
        lightcolor=np.ones(3, np.float32),
        width=nx,
        height=nz,
        scene_color=z8,
        scene_depth=np.ones((8, 8), np.float32),
        reflection_color=z8,
        reflection_view_proj=vp,
        time=float(exp.waves.time),
    )


def shader_waves(exp: Experiment) -> ShaderWaves:
    """The surface of ``exp``'s shader (see the module doc), kept for the last few scenes.

    ``stats``: ``curl_mean_deg``, ``curl_p99_deg`` (angle between the shader's normals and the
    integrated surface's, before the height scale: the part of the field no surface has),
    ``slope_rms`` (RMS slope of the surface, after the scale), ``height_scale``, ``grid``
    ``[Nx, Nz]``, ``normal`` (the variable and its frame), ``shader``."""
    key = exp.scene_hash()
    hit = _SURFACES.get(key)
    if hit is not None:
        return hit
    shader = load_user_shader(exp.values)
    w = exp.section("waves")
    study = Waves(w["amplitude"], w["normal_tile"], w["components"], w["seed"], w["offsets"],
                  w["slope_scale"])  # fmt: skip
    inputs = probe_inputs(exp, study.normal_map(exp.waves.normal_map_size))
    n, mask = surface_normals(shader, inputs)
    if not mask.all():
        raise ValueError(
            f"{shader.label}: its water covers {int(mask.sum())} of the {mask.size} points of "
            "the water plane seen from above; its vertex shader must cover the water quad"
        )
    hx, hz = exp.pool.half_extent
    nx, nz = inputs.width, inputs.height
    dx, dz = 2 * hx / nx, 2 * hz / nz
    h = integrate(-n[..., 0] / n[..., 1], -n[..., 2] / n[..., 1], dx, dz)
    surface = ShaderWaves(h, -hx + dx / 2, -hz + dz / 2, dx, dz, {})
    curl = angles_deg(n, surface.normals())
    scale = float(exp.waves.height_scale)
    surface = ShaderWaves(scale * h, surface.x0, surface.z0, dx, dz, {})
    surface.stats = {
        "shader": shader.label,
        "normal": list(shader.normal),
        "grid": [nx, nz],
        "curl_mean_deg": float(curl.mean()),
        "curl_p99_deg": float(np.percentile(curl, 99)),
        "slope_rms": float(np.sqrt((surface.gx**2 + surface.gz**2).mean())),
        "height_scale": scale,
    }
    while len(_SURFACES) >= 4:
        _SURFACES.pop(next(iter(_SURFACES)))
    _SURFACES[key] = surface
    return surface


def wave_extremes(exp: Experiment) -> tuple[float, float]:
    """``(trough, crest)``, world y: bounds of the reference's water surface, the study's
    ``-+waves.amplitude`` or the lowest and highest point of the shader's surface."""
    if exp.waves.source == "shader":
        h = shader_waves(exp).h
        return float(h.min()), float(h.max())
    a = float(exp.waves.amplitude)
    return -a, a
