"""The Dr.Jit port's shared checks: tolerances and constants of the central differences, the
NumPy reference comparison, and hand-made inputs (a flat pool, a degenerate light)."""

from __future__ import annotations

import numpy as np

from golden.regenerate import CUSTOM
from helpers.images import save_comparison
from helpers.synthetic import synthetic_inputs
from shaders_port import (
    Constants,
    ShaderInputs,
    fresnel_lut,
    ortho_tex_matrix,
    perspective_view_proj,
)

PRIMAL_ATOL = 5e-5  # port vs NumPy reference, linear RGB (both float32)
FD_RTOL, FD_NOISE = 0.1, 4e-6  # finite differences: relative truncation, float32 colour noise
FD_EPS = {  # relative step of the central differences
    "attenuation_distance": 1e-3,
    "bumptex_mult": 3e-4,
    "water_color[1]": 1e-3,
    "water_color[2]": 1e-3,
    "reflect_color[0]": 1e-3,
    "reflect_color[2]": 1e-3,
    "specular_strength": 1e-3,
    "specular_exponent": 1e-3,
    "refr_coeff": 3e-4,
    "steps_grazing": 3e-4,
    "steps_steep": 3e-4,
}
FD_CONSTANTS = Constants(attenuation_distance=2.0, specular_exponent=32.0)

# every constant away from the seed's defaults, the variants' own ones too
VARIANT_CUSTOM = CUSTOM.replace(
    absorption_r=0.45, absorption_g=0.12, absorption_b=0.08, specular_roughness=0.12, refine_steps=4
)


def small_inputs():
    """The synthetic scene at 48x36."""
    return synthetic_inputs(width=48, height=36)


def assert_matches_reference(shader: str, out: dict, ref, ref_diag, tag: str) -> None:
    err = np.abs(out["color"] - ref).max(-1)
    if not err.max() <= PRIMAL_ATOL:
        save_comparison(tag, out["color"], ref)
    assert err.max() <= PRIMAL_ATOL, f"{tag}: max |port - reference| = {err.max():.3g}"
    for k, v in ref_diag.items():
        tol = 1e-6 if k == "denominator" else 0.0
        bad = np.abs(out[k] - v) > tol
        assert not bad.any(), f"{tag}: diagnostic {k} differs at {bad.sum()} pixels"


def perturbed(constants: Constants, name: str, delta: float) -> tuple[Constants, float]:
    """``constants`` with ``name`` (``key`` or ``key[i]``) moved by ``delta`` relative (at least
    ``delta`` absolute), and the step taken."""
    if name.endswith("]"):
        base, i = name[:-1].split("[")
        comps = list(getattr(constants, base))
        x = comps[int(i)]
        comps[int(i)] = x + delta * max(1.0, abs(x))
        return constants.replace(**{base: tuple(comps)}), delta * max(1.0, abs(x))
    x = getattr(constants, name)
    h = delta * max(1.0, abs(x))
    return constants.replace(**{name: x + h}), h


def check_jacobian_column(
    render,
    base: dict,
    J: np.ndarray,
    constants: Constants,
    name: str,
    decision_keys: tuple[str, ...],
    eps: float | None = None,
) -> None:
    """Central differences of ``render`` vs the forward-mode column ``J`` for ``name``.

    Compared on water pixels whose decision diagnostics (crossing step index, ...) are equal
    at -eps, 0 and +eps and whose one-sided slopes agree (no other jump, e.g. a depth texel
    boundary under the crossing, lies within the stencil). The relative step is ``eps``, by
    default ``FD_EPS[name]``."""
    eps = FD_EPS[name] if eps is None else eps
    cp, h = perturbed(constants, name, eps)
    cm, _ = perturbed(constants, name, -eps)
    p, m = render(cp), render(cm)
    same = base["mask"] > 0
    for k in decision_keys:
        same &= (p[k] == m[k]) & (p[k] == base[k])
    fd = (p["color"] - m["color"]) / (2 * h)
    fp, fm = (p["color"] - base["color"]) / h, (base["color"] - m["color"]) / h
    noise = FD_NOISE / h
    smooth = same & (np.abs(fp - fm) <= 0.2 * np.abs(fd) + 2 * noise).all(-1)
    assert smooth.sum() >= 0.8 * (base["mask"] > 0).sum(), (
        f"{name}: only {smooth.sum()} of {(base['mask'] > 0).sum()} water pixels are comparable"
    )
    err = np.abs(J - fd)
    bad = smooth & ~(err <= 2 * noise + FD_RTOL * np.abs(fd)).all(-1)
    assert np.abs(fd[smooth]).max() > 10 * noise, f"{name}: colour does not depend on it here"
    assert not bad.any(), (
        f"{name}: forward-mode derivative differs from central differences at "
        f"{bad.sum()} pixels (worst |err| {err.max(-1)[bad].max():.3g})"
    )


def flat_pool(depth: float, normal=(0.0, 1.0, 0.0), size: int = 9, **kw) -> ShaderInputs:
    """A flat floor at y = -depth of constant colour, camera 3 units straight above it."""
    tex = 32
    x0, z0, x1, z1 = -2.0, -2.0, 2.0, 2.0
    n = np.asarray(normal, np.float32)
    nm = np.broadcast_to(0.5 * n + 0.5, (8, 8, 3)).copy()
    args = dict(
        refraction_texture=np.full((tex, tex, 3), (0.2, 0.4, 0.6), np.float32),
        world_y=np.full((tex, tex), -depth, np.float32),
        tex_matrix0=ortho_tex_matrix(x0, z0, x1, z1),
        normal_map=nm,
        cubemap=np.full((6, 4, 4, 3), 0.5, np.float32),
        fresnel_lut=fresnel_lut(),
        refl_world_y=np.full((tex, tex), -1e3, np.float32),
        refl_texture=np.zeros((tex, tex, 3), np.float32),
        tex_matrix1=ortho_tex_matrix(x0, z0, x1, z1),
        water_rect=(-1.0, -1.0, 1.0, 1.0),
        normal_tile=1.0,
        waves=np.zeros((4, 2)),
        view_proj=perspective_view_proj((0, 3, 0), (0, 0, 0), up=(0, 0, -1), fov_y_deg=2.0),
        viewpos=np.array([0.0, 3.0, 0.0]),
        lightpos=np.array([0.0, 10.0, 5.0]),
        lightcolor=np.array([1.0, 1.0, 1.0]),
        width=size,
        height=size,
    )
    args.update(kw)
    return ShaderInputs(**args)


def degenerate_light_inputs():
    """Light placed exactly on the surface point of one water pixel: varyingVecLight = 0 there,
    so vLight = normalize(0) is NaN (no constant within its valid range can force a NaN)."""
    from shaders_port.pipeline.raster import rasterize_water

    base = flat_pool(0.9)
    r = rasterize_water(base)
    k = len(r.index) // 2
    inputs = flat_pool(0.9, lightpos=r.world[k].astype(np.float64))
    assert np.array_equal(rasterize_water(inputs).world[k], r.world[k])
    return inputs, divmod(int(r.index[k]), inputs.width)


def assert_variant_jacobian_columns(v, inputs, constants, names, h: float = 1e-3):
    """The registered variant ``v``'s forward-mode Jacobian columns for the scalar constants
    ``names`` (``name`` or ``name[i]``) against central differences of step ``h`` on ``inputs``:
    each column carries signal (|fd| > 1e-2 somewhere) and 90 % of the water pixels agree
    within 1 % of the difference plus 2e-3 (bilinear texel edges and other kinks put a few
    stencils across a corner). Returns (the render's ``numpy()`` dict, the water mask)."""
    out, J = v.render_with_jacobian(inputs, constants, names)
    water = out.numpy()["mask"] > 0
    for j, name in enumerate(names):
        key, _, idx = name.partition("[")
        base = getattr(constants, key)
        if idx:
            i = int(idx[0])
            plus = constants.replace(**{key: tuple(b + h * (k == i) for k, b in enumerate(base))})
            minus = constants.replace(**{key: tuple(b - h * (k == i) for k, b in enumerate(base))})
        else:
            plus, minus = constants.replace(**{key: base + h}), constants.replace(**{key: base - h})
        fd = v.render(inputs, plus).numpy()["color"] - v.render(inputs, minus).numpy()["color"]
        fd = fd / (2 * h)
        err = np.abs(J[..., j] - fd).max(-1)[water]
        scale = np.abs(fd).max(-1)[water]
        assert scale.max() > 1e-2, name
        assert np.mean(err <= 1e-2 * scale + 2e-3) >= 0.9, (name, np.median(err))
    return out.numpy(), water


def assert_user_jacobian(shader, inputs, smooth_share: float, moves_coverage: bool = False):
    """A user's shader's (``UserShader``, with or without its own vertex shader) forward-mode
    Jacobian in every declared scalar against central differences of step 1e-3 (relative):
    the render with it equals the plain one; each column carries signal; on every water pixel
    without a kink in its stencil (a bilinear texel edge crossed, an edge between two triangles
    moved over the pixel), at least ``smooth_share`` of them, it agrees within the float32
    noise and :data:`FD_RTOL`. ``moves_coverage``: the scalars may move the water's coverage
    (a vertex shader's constants): pixels covered by all three renders only, 99 % of them."""
    from study.fit.model import get_value

    names = shader.scalar_names()
    base = shader.render(inputs).numpy()
    out, J = shader.render_with_jacobian(inputs, None, names)
    assert np.array_equal(out.numpy()["mask"], base["mask"])
    assert np.abs(out.numpy()["color"] - base["color"]).max() <= 1e-6
    v = shader.defaults()
    for j, s in enumerate(names):
        x = get_value(v, s)
        h = 1e-3 * max(abs(x), 1.0)
        p = shader.render(inputs, shader.with_scalars(v, {s: x + h})).numpy()
        m = shader.render(inputs, shader.with_scalars(v, {s: x - h})).numpy()
        fd = (p["color"] - m["color"]) / (2 * h)
        fp, fm = (p["color"] - base["color"]) / h, (base["color"] - m["color"]) / h
        noise = FD_NOISE / h
        water = base["mask"] > 0
        if moves_coverage:
            water &= (p["mask"] > 0) & (m["mask"] > 0)
            assert water.sum() >= 0.99 * (base["mask"] > 0).sum(), s
        smooth = water & (np.abs(fp - fm) <= 0.2 * np.abs(fd) + 2 * noise).all(-1)
        assert smooth.sum() >= smooth_share * water.sum(), (s, int(smooth.sum()), int(water.sum()))
        assert np.abs(fd[water]).max() > 10 * noise, s
        bad = smooth & ~(np.abs(J[..., j] - fd) <= 2 * noise + FD_RTOL * np.abs(fd)).all(-1)
        assert not bad.any(), (s, int(bad.sum()))


def assert_residual_jacobian(model, constants, steps: dict, atol: float) -> None:
    """A fit model's (``residual``, ``residual_and_jacobian``) at ``constants``: the two
    residuals agree within ``atol``, and each column of the Jacobian for the constants of
    ``steps`` (name -> relative step) is the residual's central difference within 2 % (norm)."""
    from study.fit.model import get_value, with_values

    names = list(steps)
    res, J = model.residual_and_jacobian(constants, names)
    np.testing.assert_allclose(res, model.residual(constants), rtol=0, atol=atol)
    for j, n in enumerate(names):
        v = get_value(constants, n)
        h = steps[n] * max(abs(v), 1.0)
        fd = (
            model.residual(with_values(constants, {n: v + h}))
            - model.residual(with_values(constants, {n: v - h}))
        ) / (2 * h)
        assert np.linalg.norm(fd) > 0, n
        assert np.linalg.norm(J[:, j] - fd) < 2e-2 * np.linalg.norm(fd), n


def port_normals(inputs, layers: int = 4, slopes: bool = False, normals: str | None = None):
    """((N, 2) world x, z of the water pixels of ``inputs``, (N, 3) the port's unit normal there:
    block [2], ``shaders_port.ports.normals.normal_map_block``, at ``BumptexMult = 1``; its
    ``normals`` choice: ``normals``, else slopes or the original's average)."""
    from shaders_port.pipeline.raster import prepare
    from shaders_port.pipeline.texture import backend_types
    from shaders_port.ports.normals import normal_map_block

    m = backend_types("llvm")
    from shaders_port.pipeline.normal_maps import with_lean

    normals = normals or ("slopes" if slopes else "average")
    P = prepare(inputs, m)
    P = with_lean(m, P) if normals == "lean" else P
    n, _, _ = normal_map_block(m, P, 1.0, layers, normals)
    xz = P.raster.world[:, [0, 2]].astype(np.float64)
    return xz, np.array(n.numpy()).T.reshape(-1, 3)
