"""Physics no one here invented, checked on the reference renderer and scene:
Fresnel reflectance of water at normal incidence (~0.0204), the critical angle (~48.6 deg),
and the apparent depth of a flat pool seen from straight above (real depth / 1.333)."""

import math

import numpy as np
import pytest
from helpers.experiments import small_experiment

from shaders_port import fresnel_unpolarized
from study.scene.mitsuba_scene import build_scene, camera_view_proj

IOR = 1.333


def test_fresnel_normal_incidence_formula():
    assert fresnel_unpolarized(1.0, IOR) == pytest.approx(((IOR - 1) / (IOR + 1)) ** 2, rel=1e-9)
    assert fresnel_unpolarized(1.0, IOR) == pytest.approx(0.0204, abs=1e-4)


def test_our_fresnel_matches_mitsuba(mi):
    c = np.linspace(0.01, 1.0, 50)
    r_mi = np.array(mi.fresnel(mi.Float(c.astype(np.float32)), IOR)[0])
    np.testing.assert_allclose(fresnel_unpolarized(c, IOR), r_mi, atol=2e-6)


def test_critical_angle(mi):
    crit = math.degrees(math.asin(1 / IOR))
    assert crit == pytest.approx(48.6, abs=0.05)
    # from inside the water (cos_theta_i < 0 in Mitsuba's convention): total internal reflection
    # just beyond the critical angle, partial transmission just inside it
    for angle, total in [(crit - 0.2, False), (crit + 0.2, True)]:
        r = float(np.array(mi.fresnel(mi.Float(-math.cos(math.radians(angle))), IOR)[0])[0])
        assert (r == pytest.approx(1.0, abs=1e-6)) == total, (angle, r)


def test_rendered_reflectance_at_normal_incidence(mi):
    """Flat water under a uniform unit sky, black floor and walls, seen from straight above:
    the pixel value is the Fresnel reflectance (transmitted light is absorbed). Mitsuba's smooth
    dielectric picks reflection with probability R per sample, so the mean over N samples has a
    binomial standard error sqrt(R (1 - R) / N); the bound is 4 of those."""
    exp = small_experiment(
        **{
            "resolution": "[8, 8]",
            "fit.resolution": "[8, 8]",
            "camera.position": "[0.0, 4.0, 0.001]",
            "camera.target": "[0.0, 0.0, 0.0]",
            "camera.fov_y": "5.0",
            "waves.amplitude": "0.0",
            "sky.zenith": "[1, 1, 1]",
            "sky.horizon": "[1, 1, 1]",
            "sky.ground": "[1, 1, 1]",
            "sun.radiance": "[0, 0, 0]",
            "floor.tile_albedo": "[0, 0, 0]",
            "floor.tile_albedo2": "[0, 0, 0]",
            "pool.wall_albedo": "[0, 0, 0]",
            "water.sigma_t": "[5, 5, 5]",
        }
    )
    spp = 2048
    img = np.array(mi.render(build_scene(exp), spp=spp))
    r = fresnel_unpolarized(1.0, IOR)
    sigma = math.sqrt(r * (1 - r) / (img.shape[0] * img.shape[1] * spp))
    assert img.mean() == pytest.approx(r, abs=4 * sigma)


def test_apparent_depth_from_above(mi):
    """Grout lines of a flat floor seen through flat water from straight above appear where a
    floor at depth / 1.333 would put them (paraxial). The view strip runs along the middle of
    a row of tiles (z = 0.25) and crosses the grout lines at x = +-0.5."""
    depth, h, w = 1.5, 3.0, 512
    exp = small_experiment(
        **{
            "resolution": f"[{w}, 16]",
            "fit.resolution": f"[{w}, 16]",
            "camera.position": f"[0.0, {h}, 0.251]",
            "camera.target": "[0.0, 0.0, 0.25]",
            "camera.fov_y": "1.6",
            "waves.amplitude": "0.0",
            "floor.shape": "flat",
            "floor.depth": str(depth),
            "floor.tile_size": "0.5",
            "floor.tile_albedo": "[0.8, 0.8, 0.8]",
            "floor.tile_albedo2": "[0.8, 0.8, 0.8]",
            "water.sigma_t": "[0, 0, 0]",
            "sun.radiance": "[0, 0, 0]",
            "reference.water_mesh": "16",
        }
    )
    img = np.array(mi.render(build_scene(exp), spp=128, seed=3))
    row = img[6:10].mean(axis=(0, 2))
    inv = np.linalg.inv(camera_view_proj(exp, w, 16).astype(np.float64))

    def water_x(col: float) -> float:
        ndc = 2 * (col + 0.5) / w - 1
        a = inv @ [ndc, 0.0, -1.0, 1.0]
        b = inv @ [ndc, 0.0, 1.0, 1.0]
        a, b = a[:3] / a[3], b[:3] / b[3]
        t = -a[1] / (b[1] - a[1])
        return float(a[0] + t * (b[0] - a[0]))

    x_w = np.array([water_x(c) for c in range(w)])
    apparent = []
    for x_edge in (0.5, -0.5):  # grout lines at +-1 tile from the centre
        expect_w = x_edge * h / (h + depth / IOR)
        near = np.abs(x_w - expect_w) < 0.06
        dip = np.clip(np.median(row[near]) - row[near], 0, None)
        centre = float((x_w[near] * dip).sum() / dip.sum())
        apparent.append(h * (x_edge / centre - 1))
    for d_app in apparent:
        assert d_app == pytest.approx(depth / IOR, rel=0.03), apparent
        assert abs(d_app - depth) > 0.3  # clearly not the real depth
