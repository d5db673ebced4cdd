"""Small analytic shader inputs (NumPy only) for tests of the shader layer."""

from __future__ import annotations

import numpy as np

from shaders_port import (
    Constants,
    ShaderInputs,
    fresnel_lut,
    ortho_tex_matrix,
    perspective_view_proj,
)


def synthetic_inputs(
    width: int = 64, height: int = 48, tex: int = 128, seed: int = 0
) -> ShaderInputs:
    """A 4x4 pool, floor sloping from y=-0.4 to y=-1.6, checker floor, sinusoidal normal map,
    gradient sky, a wall rising above the water on one side for the reflection shader."""
    rng = np.random.default_rng(seed)
    x0, z0, x1, z1 = -2.5, -2.5, 2.5, 2.5
    s = (np.arange(tex) + 0.5) / tex
    X = x0 + s[None, :] * (x1 - x0)
    Z = z0 + s[:, None] * (z1 - z0)
    world_y = (-1.0 + 0.3 * X / 2.5 + 0.1 * np.sin(2.0 * Z)).astype(np.float32)
    checker = ((np.floor(X * 2) + np.floor(Z * 2)) % 2)[..., None]
    colour = 0.2 + 0.6 * checker * np.array([0.9, 0.8, 0.6]) + 0.1 * rng.random((tex, tex, 3))
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
        sky[face] = (
            np.linspace(0.3, 1.0, f)[:, None, None] * np.array([0.5, 0.7, 1.0]) * (1 + 0.1 * face)
        )
    refl_y = np.full((tex, tex), -1e3, np.float32)
    refl_y[:, : tex // 6] = 0.6  # a wall along x = x0 .. x0 + 0.8, 0.6 high
    refl_col = np.zeros((tex, tex, 3), np.float32)
    refl_col[:, : tex // 6] = (0.8, 0.3, 0.2)
    eye = (0.3, 2.5, 4.5)
    return ShaderInputs(
        refraction_texture=colour,
        world_y=world_y,
        tex_matrix0=ortho_tex_matrix(x0, z0, x1, z1),
        normal_map=0.5 * nrm + 0.5,
        cubemap=sky,
        fresnel_lut=fresnel_lut(),
        refl_world_y=refl_y,
        refl_texture=refl_col,
        tex_matrix1=ortho_tex_matrix(x0, z0, x1, z1),
        water_rect=(-2.0, -2.0, 2.0, 2.0),
        normal_tile=tile,
        waves=np.array([[0.0, 0.0], [0.31, 0.17], [0.53, 0.71], [0.13, 0.47]]),
        view_proj=perspective_view_proj(
            eye, (0.0, -0.8, 0.0), fov_y_deg=50.0, aspect=width / height
        ),
        viewpos=np.array(eye),
        lightpos=np.array([-3.0, 6.0, -8.0]),
        lightcolor=np.array([1.0, 0.95, 0.8]),
        width=width,
        height=height,
    )


def _synthetic_floor(x, z):
    return -1.0 + 0.3 * x / 2.5 + 0.1 * np.sin(2.0 * z)


def _synthetic_floor_colour(x, z):
    checker = ((np.floor(x * 2) + np.floor(z * 2)) % 2)[..., None]
    return 0.2 + 0.6 * checker * np.array([0.9, 0.8, 0.6]) + 0.05 * np.sin(3 * x + z)[..., None]


def _pixel_rays(vp: np.ndarray, w: int, h: int):
    """Rays through the pixel centres of clip matrix ``vp``, rows in GL order (row 0 = bottom)."""
    inv = np.linalg.inv(vp.astype(np.float64))
    s = (np.arange(w) + 0.5) / w
    t = (np.arange(h) + 0.5) / h
    S, T = np.meshgrid(s, t)

    def unproject(zn):
        q = np.stack([2 * S - 1, 2 * T - 1, np.full_like(S, zn), np.ones_like(S)], -1) @ inv.T
        return q[..., :3] / q[..., 3:4]

    a, b = unproject(-1.0), unproject(1.0)
    return a, b - a


def synthetic_baseline_inputs(width: int = 64, height: int = 48, seed: int = 0) -> ShaderInputs:
    """``synthetic_inputs`` plus the baseline's buffers: the scene without water seen by the
    camera (analytic floor and checker, ray-marched at pixel centres, window depth) and the
    mirrored camera's view above y = 0 (a wall at x < -1.7 up to y = 0.6, gradient sky)."""
    import dataclasses

    from shaders_port.inputs import mirrored_view_proj

    base = synthetic_inputs(width, height, seed=seed)
    vp = base.view_proj.astype(np.float64)
    o, d = _pixel_rays(vp, width, height)  # o on the near plane, o + d on the far plane
    t = np.linspace(0.0, 1.0, 801)[:, None, None]
    p = o[None] + t[..., None] * d[None]
    above = p[..., 1] > _synthetic_floor(p[..., 0], p[..., 2])
    first = np.argmax(~above, axis=0)
    hit = (~above).any(axis=0)
    lo = np.where(hit, t[np.maximum(first - 1, 0), 0, 0], 0.0)
    hi = np.where(hit, t[first, 0, 0], 1.0)
    for _ in range(40):  # bisection to the floor
        mid = 0.5 * (lo + hi)
        q = o + mid[..., None] * d
        up = q[..., 1] > _synthetic_floor(q[..., 0], q[..., 2])
        lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
    q = o + hi[..., None] * d
    clip = np.concatenate([q, np.ones_like(q[..., :1])], -1) @ vp.T
    depth = np.where(hit, 0.5 * clip[..., 2] / clip[..., 3] + 0.5, 1.0)

    def sky(dy):
        return np.array([0.5, 0.7, 1.0]) * (0.4 + 0.5 * np.clip(dy, 0, 1))[..., None]

    dn = d / np.linalg.norm(d, axis=-1, keepdims=True)
    colour = np.where(
        hit[..., None], _synthetic_floor_colour(q[..., 0], q[..., 2]), sky(dn[..., 1])
    )
    # mirrored camera: rays from the mirrored eye, clipped at y = 0 (what is above the water)
    rvp = mirrored_view_proj(base.view_proj)
    ro, rd = _pixel_rays(rvp.astype(np.float64), width, height)
    rdn = rd / np.linalg.norm(rd, axis=-1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        tw = (-1.7 - ro[..., 0]) / rd[..., 0]
    yw = ro[..., 1] + tw * rd[..., 1]
    wall = (rd[..., 0] < 0) & (tw > 0) & (yw > 0.0) & (yw < 0.6)
    wall_col = np.array([0.8, 0.3, 0.2]) * (0.7 + 0.3 * yw / 0.6)[..., None]
    refl = np.where(wall[..., None], wall_col, sky(rdn[..., 1]))
    return dataclasses.replace(
        base,
        scene_color=colour.astype(np.float32),
        scene_depth=depth.astype(np.float32),
        reflection_color=refl.astype(np.float32),
        reflection_view_proj=rvp,
    )


def synthetic_box_inputs(
    width: int = 64, height: int = 48, seed: int = 0, size: int = 32
) -> "ShaderInputs":
    """``synthetic_inputs`` plus the local cube map of ``reflection = box``: the water's box
    (x, z in [-2, 2], walls 0.6 high) captured at (0, 0.6, 0), the walls striped in their own
    coordinates (so a wrong parallax shows), the sky a gradient above; the study's ``y`` flip
    (texel of direction d holds the scene in d * (1, -1, 1))."""
    import dataclasses

    base = synthetic_inputs(width, height, seed=seed)
    lo, hi, capture = np.array([-2.0, -1.6, -2.0]), np.array([2.0, 0.6, 2.0]), np.array([0, 0.6, 0])
    d = _cube_directions(size) * np.array([1.0, -1.0, 1.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d > 0, (hi - capture) / d, (lo - capture) / d)
    t = np.where(np.isfinite(t) & (t > 0), t, np.inf)[..., [0, 2]].min(-1)
    p = capture + t[..., None] * d
    along = np.where(np.abs(np.abs(p[..., 0]) - 2.0) < 1e-6, p[..., 2], p[..., 0])
    wall = (0.5 + 0.4 * np.sin(3.0 * along))[..., None] * np.array([0.9, 0.5, 0.3])
    wall = wall * (0.6 + 0.4 * np.clip(p[..., 1:2] / 0.6, 0.0, 1.0))
    sky = np.array([0.5, 0.7, 1.0]) * (0.4 + 0.5 * np.clip(d[..., 1:2], 0, 1))
    cube = np.where(d[..., 1:2] < 0.0, wall, sky).astype(np.float32)
    return dataclasses.replace(base, box_cubemap=cube, box_min=lo, box_max=hi, box_capture=capture)


def sun_mirrored_at_the_centre(inputs: ShaderInputs) -> ShaderInputs:
    """``inputs`` with the light where calm water mirrors it to the pool's centre (1000 world
    units away): the sun's highlight in view."""
    import dataclasses

    x0, z0, x1, z1 = inputs.water_rect
    centre = np.array([(x0 + x1) / 2, 0.0, (z0 + z1) / 2])
    v = inputs.viewpos - centre
    v /= np.linalg.norm(v)
    return dataclasses.replace(inputs, lightpos=centre + 1e3 * np.array([-v[0], v[1], -v[2]]))


def synthetic_inputs_for(name: str, width: int = 64, height: int = 48) -> "ShaderInputs":
    """The synthetic inputs with whatever extra inputs the shader ``name`` reads."""
    from shaders_port.variants import get_variant

    extra = get_variant(name).inputs
    if "box_cubemap" in extra:
        return synthetic_box_inputs(width, height)
    if "scene_depth" in extra and "reflection_color" not in extra:  # reflection = ssr
        return synthetic_ssr_inputs(width, height)
    return (synthetic_baseline_inputs if extra else synthetic_inputs)(width, height)


def _cube_directions(size: int) -> np.ndarray:
    """(6, size, size, 3) unit directions of a GL cube map's texel centres (GL table 8.19)."""
    c = 2 * (np.arange(size) + 0.5) / size - 1
    s, t = np.meshgrid(c, c)
    one = np.ones_like(s)
    faces = [(one, -t, -s), (-one, -t, s), (s, one, t), (s, -one, -t), (s, -t, one), (-s, -t, -one)]
    out = np.stack([np.stack(f, -1) for f in faces])
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _synthetic_pool_solid(p: np.ndarray) -> np.ndarray:
    """Inside the dry scene of :func:`synthetic_ssr_inputs`: below the floor, or the deck around
    the pool (outside x, z in [-2, 2]) up to the walls' top y = 0.6, at the water's level on the
    camera's side (z > 2: no near wall hides the water)."""
    outside = (np.abs(p[..., 0]) > 2.0) | (np.abs(p[..., 2]) > 2.0)
    top = np.where(p[..., 2] > 2.0, 0.0, 0.6)
    return (p[..., 1] < _synthetic_floor(p[..., 0], p[..., 2])) | (outside & (p[..., 1] < top))


def _synthetic_pool_colour(q: np.ndarray) -> np.ndarray:
    """The dry scene's colour at its surface points ``q``: the floor's checker in the pool, the
    walls' inner faces striped along the wall and shaded with height, the deck grey-green."""
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    floor = _synthetic_floor_colour(x, z)
    along = np.where(np.abs(np.abs(x) - 2.0) < np.abs(np.abs(z) - 2.0), z, x)
    wall = (0.5 + 0.4 * np.sin(3.0 * along))[..., None] * np.array([0.9, 0.5, 0.3])
    wall = wall * (0.6 + 0.4 * np.clip(y / 0.6, 0.0, 1.0))[..., None]
    deck = np.broadcast_to(np.array([0.45, 0.5, 0.4]), q.shape)
    ground = (np.abs(y) < 1e-4) & (z > 2.0)
    inside = (np.abs(x) <= 2.0 + 1e-6) & (np.abs(z) <= 2.0 + 1e-6)
    on_floor = y < _synthetic_floor(x, z) + 1e-3
    return np.where(
        (inside & on_floor)[..., None],
        floor,
        np.where(((y > 0.6 - 1e-4) | ground)[..., None], deck, wall),
    )


def synthetic_ssr_inputs(width: int = 64, height: int = 48, seed: int = 0) -> ShaderInputs:
    """``synthetic_inputs`` plus the camera's buffers of ``reflection = ssr``: the pool (x, z in
    [-2, 2]) sunk in a deck 0.6 above the water, its walls' inner faces striped (so a reflected
    wall shows where SSR finds it), seen without the water by the camera (ray-marched at the
    pixel centres, bisected to the surface; window depth, 1 where the sky is seen)."""
    import dataclasses

    base = synthetic_inputs(width, height, seed=seed)
    vp = base.view_proj.astype(np.float64)
    o, d = _pixel_rays(vp, width, height)  # o on the near plane, o + d on the far plane
    lo, hi = np.zeros(o.shape[:2]), np.ones(o.shape[:2])
    found = np.zeros(o.shape[:2], bool)
    ts = np.linspace(0.0, 1.0, 4001)
    for t0, t1 in zip(ts[:-1], ts[1:]):  # the first sample inside, per pixel
        new = ~found & _synthetic_pool_solid(o + t1 * d)
        lo, hi, found = np.where(new, t0, lo), np.where(new, t1, hi), found | new
    for _ in range(40):  # bisection to the surface
        mid = 0.5 * (lo + hi)
        inside = _synthetic_pool_solid(o + mid[..., None] * d)
        lo, hi = np.where(inside, lo, mid), np.where(inside, mid, hi)
    q = o + hi[..., None] * d
    clip = np.concatenate([q, np.ones_like(q[..., :1])], -1) @ vp.T
    depth = np.where(found, 0.5 * clip[..., 2] / clip[..., 3] + 0.5, 1.0)
    dn = d / np.linalg.norm(d, axis=-1, keepdims=True)
    sky = np.array([0.5, 0.7, 1.0]) * (0.4 + 0.5 * np.clip(dn[..., 1], 0, 1))[..., None]
    colour = np.where(found[..., None], _synthetic_pool_colour(q), sky)
    return dataclasses.replace(
        base, scene_color=colour.astype(np.float32), scene_depth=depth.astype(np.float32)
    )


def relative_errors(fitted, truth: dict, names: list[str]) -> dict:
    """Relative error of each fitted scalar of ``names`` against ``truth`` (constant -> value, a
    colour as an RGB(A) tuple whose first three components count): {'water_color[1]': ...}."""
    out = {}
    for name in names:
        want, got = truth[name], getattr(fitted, name)
        if isinstance(want, tuple):
            for i in range(3):
                out[f"{name}[{i}]"] = abs(got[i] / want[i] - 1)
        else:
            out[name] = abs(got / want - 1)
    return out


# a known truth with a strong highlight, a start away from it and the constants a fit of it
# frees (the footprint's and the misregistration's known-truth fits on the synthetic pool)
GLINT_TRUTH = dict(attenuation_distance=5.0, water_color=(0.05, 0.2, 0.2, 1.0),
                   specular_strength=2.0, specular_exponent=300.0, bumptex_mult=1.0)  # fmt: skip
GLINT_START = dict(attenuation_distance=6.0, water_color=(0.06, 0.25, 0.25, 1.0),
                   specular_strength=1.0, specular_exponent=200.0, bumptex_mult=0.8)  # fmt: skip
FITTED = ["attenuation_distance", "water_color", "specular_strength", "specular_exponent",
          "bumptex_mult"]  # fmt: skip


# a constants set whose values differ from every default, with digits to lose: what the export
# tests write into every target and read back
EXPORT_CONSTANTS = Constants(
    attenuation_distance=5.4321,
    steps_grazing=11.0,
    steps_steep=4.0,
    loop_cap=37,
    specular_strength=1.7654,
    specular_exponent=211.5,
    bumptex_mult=0.9797,
    refr_coeff=0.7431,
    water_color=(0.0612, 0.2391, 0.3107, 1.0),
    reflect_color=(0.9321, 0.9123, 0.8912, 1.0),
    absorption_r=0.2113,
    absorption_g=0.1021,
    absorption_b=0.0734,
    specular_roughness=0.1733,
    refine_steps=5,
    refraction_index=0.7433,
    refraction_strength=0.0231,
    chromatic_dispersion=0.00171,
    reflect_distortion=0.0917,
)
