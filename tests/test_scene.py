"""The Mitsuba scene and the shader see the same world: camera, sky, textures."""

import numpy as np
import pytest
from helpers.experiments import small_experiment

from study.scene.geometry import cubemap_directions, envmap_image, sky_radiance
from study.scene.mitsuba_scene import build_scene, camera_view_proj, sky_params


def test_mitsuba_camera_matches_gl_projection(mi):
    exp = small_experiment(**{"resolution": "[40, 24]", "fit.resolution": "[40, 24]"})
    w, h = 40, 24
    sensor = build_scene(exp).sensors()[0]
    vp = camera_view_proj(exp, w, h).astype(np.float64)
    for i, j in [(0, 0), (39, 0), (0, 23), (17, 9), (39, 23)]:
        ray, _ = sensor.sample_ray(
            0.0, 0.0, mi.Point2f((i + 0.5) / w, (j + 0.5) / h), mi.Point2f(0.5, 0.5)
        )
        p = np.array(ray.o).ravel() + 3.0 * np.array(ray.d).ravel()
        clip = vp @ np.append(p, 1.0)
        ndc = clip[:2] / clip[3]
        px = ((ndc[0] + 1) / 2 * w, (1 - ndc[1]) / 2 * h)  # row 0 at the top
        assert px == pytest.approx((i + 0.5, j + 0.5), abs=1e-3)


def test_envmap_matches_sky_function(mi):
    exp = small_experiment()
    sky = sky_params(exp, with_sun=False)
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(envmap_image(256, **sky))})
    rng = np.random.default_rng(0)
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = d[np.abs(d[:, 1]) > 0.05]  # away from the horizon's kink
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*[mi.Float(-d[:, k].astype(np.float32)) for k in range(3)])
    got = np.array(emitter.eval(si))
    got = got.T if got.shape[0] == 3 else got
    np.testing.assert_allclose(got, sky_radiance(d, **sky), rtol=0.03, atol=0.01)


def test_cubemap_directions_follow_gl_face_table():
    d = cubemap_directions(4)
    major = np.argmax(np.abs(d), axis=-1)
    sign = np.take_along_axis(d, major[..., None], -1)[..., 0] > 0
    for face, (axis, positive) in enumerate([(0, 1), (0, 0), (1, 1), (1, 0), (2, 1), (2, 0)]):
        assert (major[face] == axis).all() and (sign[face] == bool(positive)).all()
    # +Z face: s grows with +x, t grows with -y (GL table 8.19)
    assert d[4, 0, -1, 0] > d[4, 0, 0, 0] and d[4, -1, 0, 1] < d[4, 0, 0, 1]


def test_water_bsdf_terms_and_row_crop(mi):
    """``build_scene(water_bsdf=..., rows=...)`` (benchmarks/bench_grazing.py): the crop renders
    the named rows, and the water's dielectric takes the overrides -- with neither reflection nor
    transmission every pixel whose camera ray meets the water first is black, with either one
    alone it is not, and the two alone add up to at most the full render (paths that do both are
    missing from each)."""
    from study._metrics import erode
    from study.scene.reference import water_mask

    exp = small_experiment(**{"resolution": "[32, 24]", "fit.resolution": "[32, 24]"})
    rows = (6, 18)
    water = erode(water_mask(exp, 32, 24), 1)[
        rows[0] : rows[1]
    ]  # whole pixel footprints on the water
    assert water.sum() > 50

    def render(**bsdf):
        img = np.array(mi.render(build_scene(exp, water_bsdf=bsdf, rows=rows), spp=16, seed=3))
        assert img.shape == (rows[1] - rows[0], 32, 3)
        return img

    full = render()
    refl = render(specular_transmittance=0.0)
    trans = render(specular_reflectance=0.0)
    black = render(specular_transmittance=0.0, specular_reflectance=0.0)
    assert np.all(black[water] == 0.0) and np.all(full[water].sum(-1) > 0)
    assert refl[water].mean() > 0.01 and trans[water].mean() > 0.01
    assert (refl + trans)[water].mean() <= full[water].mean() * 1.05
