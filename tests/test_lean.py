"""LEAN mapping (``normals = "lean"``, ``LEAN_NORMALS``): the slope-moment maps hold the normal
map's slopes and their squares (known truth: a sinusoid's), the port matches llvmpipe and the
SPIR-V executor in both raycast files with the level of detail llvmpipe takes, its derivatives
match central differences with the sun in view, one sample of the widened highlight is nearer
the pixel's mean highlight than one sample of the sharp one, and the space names it."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
from helpers.gl import check_gl_match, compare_or_skip
from helpers.port_checks import VARIANT_CUSTOM, assert_variant_jacobian_columns
from helpers.synthetic import sun_mirrored_at_the_centre, synthetic_inputs

from shaders_port.pipeline.frame import FrozenReplayWarning
from shaders_port.pipeline.normal_maps import slope_moments, with_lean
from shaders_port.pipeline.raster import prepare
from shaders_port.pipeline.texture import backend_types, box_mip_chain
from shaders_port.variants import get_variant

# a soft disc a few degrees wide: the footprint's slopes move it by about its size
DISC = VARIANT_CUSTOM.replace(sun_disc_radius=3.0, sun_disc_softness=0.2, sun_disc_radiance=3.0)
NAMES = [
    "water_refraction_beer_disc_walls_lean",
    "water_reflection_beer_ggx_2layers_lean",
    "water_refraction_1layer_lean",
]


def test_the_moments_are_a_sinusoids_slopes_and_the_top_level_their_variance():
    """Known truth: ``h = a sin(2 pi 3 u)`` on a 256-texel tile (u in tile units) has the slope
    ``dh/du = 6 pi a cos(2 pi 3 u)``; the map's level 0 holds it and its square, and the 1 x 1
    level the means over the tile: 0 and ``(6 pi a)^2 / 2``."""
    S, a = 256, 0.01
    u = (np.arange(S) + 0.5) / S
    slope = np.broadcast_to(6 * np.pi * a * np.cos(2 * np.pi * 3 * u)[None, :], (S, S))
    n = np.stack([-slope, np.ones_like(slope), np.zeros_like(slope)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    level0 = slope_moments(0.5 * n + 0.5)
    np.testing.assert_allclose(level0[..., 0], slope, atol=1e-6)
    np.testing.assert_allclose(level0[..., 2], slope * slope, atol=1e-6)
    assert np.abs(level0[..., [1, 3]]).max() < 1e-6
    top = box_mip_chain(level0)[-1][0, 0]
    assert top.shape == (4,) and abs(top[0]) < 1e-6
    np.testing.assert_allclose(top[2] - top[0] ** 2, (6 * np.pi * a) ** 2 / 2, rtol=1e-4)


def _inputs(name: str, w: int = 96, h: int = 72, calm: float = 1.0):
    """The synthetic scene with the sun in view, its normal map's slopes times ``calm``."""
    inputs = sun_mirrored_at_the_centre(synthetic_inputs(w, h))
    n = 2.0 * inputs.normal_map - 1.0
    n[..., [0, 2]] *= calm
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return dataclasses.replace(inputs, normal_map=(0.5 * n + 0.5).astype(np.float32))


@pytest.mark.parametrize("name", NAMES)
def test_lean_matches_opengl_and_the_executor(name):
    """The port against llvmpipe running the GLSL file with ``LEAN_NORMALS`` (trilinear lookups
    of the mipmapped moments over levels 1.6 to 3.6 here), four, two and one layers, the
    refraction and the reflection file, Phong, GGX and the disc; the SPIR-V executor's run of
    the same file (its level of detail from the frame's quads) equals the port exactly; and the
    choice changes the image."""
    from shaders_port.spirv import translated

    inputs = _inputs(name)
    m = backend_types("llvm")
    lod = np.array(with_lean(m, prepare(inputs, m)).slopeLod[0].numpy())
    assert lod.min() > 1.0 and lod.max() - lod.min() > 1.5, (lod.min(), lod.max())
    check_gl_match(compare_or_skip(inputs, DISC, name), f"gl_{name}")
    v = get_variant(name)
    ours = v.render(inputs, DISC).numpy()
    spec = translated.builtin_spec(v.shader, v.defines)
    with warnings.catch_warnings():  # recorded and replayed over the quads' helper lanes too
        warnings.simplefilter("error", FrozenReplayWarning)
        translated.render(inputs, DISC, spec=spec)
        executed = translated.render(inputs, DISC, spec=spec).numpy()
    assert np.array_equal(executed["color"], ours["color"])
    assert np.array_equal(executed["fetches"], ours["fetches"])
    other = get_variant(name.replace("_lean", "_slopes" if "1layer" not in name else ""))
    assert np.abs(ours["color"] - other.render(inputs, DISC).numpy()["color"]).max() > 1e-2


@pytest.mark.parametrize(
    "name,names",
    [
        ("water_refraction_beer_disc_walls_lean", ["sun_disc_radius", "sun_disc_radiance"]),
        ("water_refraction_lean", ["specular_strength", "bumptex_mult"]),
    ],
)
def test_lean_derivatives_match_central_differences(name, names):
    """With the synthetic waves' slopes at a third (steep waves widen the lobes until they
    carry little signal: 23 degrees for the disc's 3 here); Phong's exponent is checked in
    test_variants' central differences."""
    constants = DISC.replace(specular_exponent=64.0, specular_strength=1.5)
    inputs = _inputs(name, calm=1.0 / 3.0)
    assert_variant_jacobian_columns(get_variant(name), inputs, constants, names)


def _highlight(name: str, inputs, constants) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) the disc's contribution (summed RGB) and the water mask."""
    on = get_variant(name).render(inputs, constants).numpy()
    off = get_variant(name.replace("disc", "nospecular")).render(inputs, constants).numpy()
    return (on["color"] - off["color"]).sum(-1), on["mask"] > 0


@pytest.mark.parametrize("radius", [1.0, 3.0])
def test_one_lean_sample_is_nearer_the_pixels_mean_highlight(radius):
    """Known truth of the footprint: the disc off the slope-blended normal at 8 x 8 samples a
    pixel, box-averaged, is the pixel's mean highlight. At 24 x 18 pixels (levels of detail 2.6
    and more) one sample of LEAN's widened disc is nearer it than one sample of the sharp disc
    (measured: mean |error| 0.0017 against 0.0067 at 1 degree, 0.0094 against 0.0171 at 3)."""
    w, h, s = 24, 18, 8
    C = DISC.replace(sun_disc_radius=radius)
    fine, water = _highlight("water_refraction_disc_slopes", _inputs("", w * s, h * s), C)
    mean = fine.reshape(h, s, w, s).mean((1, 3))
    water = water.reshape(h, s, w, s).all((1, 3))
    sharp, _ = _highlight("water_refraction_disc_slopes", _inputs("", w, h), C)
    lean, _ = _highlight("water_refraction_disc_lean", _inputs("", w, h), C)
    e_sharp, e_lean = (np.abs(x - mean)[water].mean() for x in (sharp, lean))
    assert e_lean < 0.75 * e_sharp, (e_lean, e_sharp)


def test_the_space_names_and_refuses_lean():
    from shaders_port import space

    c = space.choices_of("water_refraction_beer_disc_walls_lean")
    assert c["normals"] == "lean" and c["layers"] == 4
    assert "LEAN_NORMALS" in space.realise(c)[1]
    assert space.name_of({"normals": "lean", "layers": 1}) == "water_refraction_1layer_lean"
    with pytest.raises(space.Unrealisable, match="four layers averaged"):
        space.realise({"refraction": "planar", "reflection": "planar", "normals": "lean"})
    from shaders_port.ports import water_refraction

    with pytest.raises(ValueError, match="SLOPE_NORMALS and #define LEAN_NORMALS both choose"):
        water_refraction.render(synthetic_inputs(16, 12), defines=("SLOPE_NORMALS", "LEAN_NORMALS"))
    assert {"normals": "lean"} in space.ALONE.values()
