"""The failure catalogue (study.studies.failures): one provoking case per class, found by the
classifier, and a benign case where it is not; the diagnostics never change the colour.

Synthetic ShaderInputs (NumPy) wherever the class is a property of the shader's inputs; the
depth-complexity class needs the scene's geometry (a tiny Mitsuba scene, no reference render).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from shaders_port import (
    Constants,
    ShaderInputs,
    fresnel_lut,
    ortho_tex_matrix,
    perspective_view_proj,
)
from shaders_port.ports import water_reflection, water_refraction
from study.studies.failures import (
    CLASS_KEYS,
    DENOMINATOR_EPS,
    GRAZING_RY,
    classify,
    failure_table,
    primary_class,
)
from helpers.synthetic import synthetic_inputs


def pool(
    depth=0.9,
    normal=(0.0, 1.0, 0.0),
    eye=(0.0, 3.0, 0.0),
    target=(0.0, 0.0, 0.0),
    up=(0, 0, -1),
    fov=2.0,
    size=9,
    tex=32,
    extent=(-2.0, -2.0, 2.0, 2.0),
    **kw,
) -> ShaderInputs:
    """A pool with a flat floor at y = -depth (or ``world_y``), constant normal, a pinhole
    camera."""
    n = np.asarray(normal, np.float64)
    n /= np.linalg.norm(n)
    args = dict(
        refraction_texture=np.full((tex, tex, 3), (0.2, 0.4, 0.6), np.float32),
        world_y=np.full((tex, tex), -depth, np.float32),
        tex_matrix0=ortho_tex_matrix(*extent),
        normal_map=np.broadcast_to(0.5 * n + 0.5, (8, 8, 3)).astype(np.float32),
        cubemap=np.full((6, 4, 4, 3), 0.5, np.float32),
        fresnel_lut=fresnel_lut(),
        refl_world_y=np.full((tex, tex), -1e3, np.float32),
        refl_texture=np.zeros((tex, tex, 3), np.float32),
        tex_matrix1=ortho_tex_matrix(*extent),
        water_rect=(-1.0, -1.0, 1.0, 1.0),
        normal_tile=1.0,
        waves=np.zeros((4, 2)),
        view_proj=perspective_view_proj(eye, target, up=up, fov_y_deg=fov),
        viewpos=np.array(eye, np.float64),
        lightpos=np.array([0.0, 10.0, 5.0]),
        lightcolor=np.array([1.0, 1.0, 1.0]),
        width=size,
        height=size,
    )
    args.update(kw)
    return ShaderInputs(**args)


def diagnose(inputs, constants=None, shader=water_refraction, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out = shader.render(inputs, constants or Constants(), diagnose=True, **kw).numpy()
    water = out["mask"] > 0.5
    assert water.any()
    extra = {}
    if "refl_exit" in out:
        from shaders_port.pipeline.raster import rasterize_water
        from study.studies.failures import reflection_would_hit

        r = rasterize_water(inputs)
        dirs = np.stack([out[f"refl_dir_{c}"].ravel()[r.index] for c in "xyz"], 1)
        missed = np.zeros(inputs.width * inputs.height, bool)
        missed[r.index] = reflection_would_hit(inputs, r.world, dirs)
        extra = dict(refl_missed=missed.reshape(inputs.height, inputs.width))
    return out, water, classify(out, water, **extra)


def share(classes, key, water):
    return classes[key][water].mean()


BENIGN = pool()  # straight down onto a flat floor 0.9 deep: crossed at step 3, denominator 1/3


def test_benign_pool_is_in_no_class():
    out, water, c = diagnose(BENIGN)
    for k, m in c.items():
        assert not m.any(), k
    np.testing.assert_allclose(out["denominator"][water], 1 / 3, rtol=2e-3)
    np.testing.assert_allclose(out["interp_weight"][water], 0.7, atol=2e-3)  # (-2/3 + 0.9) / (1/3)
    np.testing.assert_allclose(out["refr_dir_y"][water], -1.0, atol=5e-4)  # 2 degree fov
    label = primary_class(c, water)
    assert set(np.unique(label[water])) == {0} and np.all(label[~water] == -1)


@pytest.mark.parametrize(
    "shader,kw",
    [
        (water_refraction, {}),
        (water_refraction, {"defines": ("NOREFLECTION",)}),
        (water_reflection, {}),
    ],
)
def test_diagnostics_do_not_change_the_colour(shader, kw):
    inputs = synthetic_inputs(32, 24)
    a = shader.render(inputs, Constants(), **kw).numpy()
    b = shader.render(inputs, Constants(), diagnose=True, **kw).numpy()
    assert np.array_equal(a["color"], b["color"])
    assert set(a) < set(b) and all(np.array_equal(a[k], b[k]) for k in a)


def test_no_crossing_within_loop_cap():
    _, water, c = diagnose(BENIGN, Constants(loop_cap=2))  # 2 steps reach y = -2/3 > -0.9
    assert c["no_crossing"][water].all()
    assert not diagnose(BENIGN, Constants(loop_cap=3))[2]["no_crossing"].any()


def test_nonfinite_vector_is_invalid_refraction():
    from shaders_port.pipeline.raster import rasterize_water

    r = rasterize_water(BENIGN)
    k = len(r.index) // 2
    inputs = pool(lightpos=r.world[k].astype(np.float64))  # vLight = normalize(0) = NaN there
    out, water, c = diagnose(inputs)
    row, col = divmod(int(r.index[k]), inputs.width)
    assert out["nonfinite"][row, col] == 1
    assert np.argwhere(c["invalid_refraction"]).tolist() == [[row, col]]


def test_back_facing_normal_is_invalid_refraction():
    # a low eye on +x, the normal tilted 70 degrees towards -x: dot(vEye, N) < 0
    a = np.radians(70)
    inputs = pool(normal=(-np.sin(a), np.cos(a), 0.0), eye=(3.0, 0.5, 0.0), up=(0, 1, 0), fov=5.0)
    out, water, c = diagnose(inputs)
    assert (out["cos_eye_normal"][water] < 0).all() and c["invalid_refraction"][water].all()
    # TIR cannot occur air -> water (refrCoeff <= 1): k stays positive
    assert (out["refract_k"][water] > 0).all()


def test_grazing_refraction():
    # eye 80 degrees from vertical on -x, normal tilted 75 degrees towards it: R ~ 11 degrees
    # below horizontal (front-facing: incidence 5 degrees), so R.y ~ -0.2 > -GRAZING_RY
    a = np.radians(75)
    eye = (-3.0 * np.sin(np.radians(80)), 3.0 * np.cos(np.radians(80)), 0.0)
    inputs = pool(normal=(-np.sin(a), np.cos(a), 0.0), eye=eye, up=(0, 1, 0), fov=3.0)
    out, water, c = diagnose(inputs)
    assert (out["cos_eye_normal"][water] > 0).all()
    assert (out["refr_dir_y"][water] > -GRAZING_RY).all() and c["grazing"][water].all()
    assert not c["invalid_refraction"].any()


def test_lookups_outside_the_textures():
    # the top-down textures cover x, z in [-0.5, 0.5] only; the water is [-1, 1]^2
    eye = (0.0, 6.0, 0.0)
    inputs = pool(eye=eye, fov=25.0, extent=(-0.5, -0.5, 0.5, 0.5), size=16)
    out, water, c = diagnose(inputs)
    from shaders_port.pipeline.raster import rasterize_water

    r = rasterize_water(inputs)
    start_outside = np.zeros(inputs.width * inputs.height, bool)
    start_outside[r.index] = (np.abs(r.world[:, 0]) > 0.5) | (np.abs(r.world[:, 2]) > 0.5)
    start_outside = start_outside.reshape(inputs.height, inputs.width)
    assert start_outside.any() and (~start_outside & water).any()
    # straight-down rays: outside exactly where they start outside
    assert np.array_equal(c["outside_textures"], start_outside & water)


def test_small_denominator_where_the_floor_falls_with_the_ray():
    # an eye 70 degrees from vertical on -x, flat water: the refracted rays descend at ~45
    # degrees. The floor is a plane parallel to the central ray, 0.3 below it: the ray never
    # crosses it and cpoy - cpy + depth - olddepth = 0 up to the depth texels (1e-3 wide)
    phi = np.radians(70)
    eye = np.array([-3.0 * np.sin(phi), 3.0 * np.cos(phi), 0.0])
    I = -eye / np.linalg.norm(eye)
    nrm = np.array([0.0, 1.0, 0.0])
    eta = 1 / 1.333
    d = nrm @ I
    R = eta * I - (eta * d + np.sqrt(1 - eta**2 * (1 - d**2))) * nrm
    slope = R[1] / R[0]  # dy/dx along the ray
    tex, ext = 2048, (-1.0, -1.0, 1.0, 1.0)
    x = ext[0] + (np.arange(tex) + 0.5) / tex * (ext[2] - ext[0])
    world_y = np.broadcast_to(-0.3 + slope * x, (tex, tex)).astype(np.float32)
    inputs = pool(
        eye=tuple(eye),
        up=(0, 1, 0),
        fov=1.0,
        world_y=world_y,
        tex=tex,
        extent=ext,
        water_rect=(-0.1, -0.1, 0.1, 0.1),
        refraction_texture=np.full((tex, tex, 3), 0.5, np.float32),
        refl_world_y=np.full((8, 8), -1e3, np.float32),
        refl_texture=np.zeros((8, 8, 3), np.float32),
    )
    out, water, c = diagnose(inputs, Constants(loop_cap=6))  # 6 steps of 0.14 in x: inside
    assert c["no_crossing"][water].all()  # parallel: never crosses
    assert c["small_denominator"][water].mean() > 0.2
    small = c["small_denominator"]
    assert np.all(np.abs(out["denominator"][small]) < DENOMINATOR_EPS)
    # the weight (cpoy - olddepth) / denominator ~ 0.3 / 1e-3 throws the crossing far away
    assert np.all(np.abs(out["interp_weight"][small]) > 100) and c["outside_textures"][small].all()
    assert not diagnose(BENIGN)[2]["small_denominator"].any()


def test_reflection_rays_leave_the_textures_or_stop_short():
    inputs = synthetic_inputs(32, 24)  # a wall 0.6 high along x = -2.5 .. -2.08
    out0, water, c0 = diagnose(inputs, shader=water_reflection)
    hits = (out0["refl_exit"] == 0) & water
    assert hits.any() and not c0["refl_no_hit"][hits].any()
    # rays towards the open sides leave the textures: classed so, and not as missed hits
    left = c0["refl_left_textures"]
    assert left.any() and (left & ~c0["refl_no_hit"]).any()
    # loop cap 1: the rays that hit the wall with the seed's cap now stop short: all counted
    out1, water1, c1 = diagnose(inputs, Constants(refl_loop_cap=1), shader=water_reflection)
    short = hits & (out1["refl_exit"] == 3)
    assert short.any() and c1["refl_no_hit"][short].all()
    # a height cut below the wall's top (0.6) stops rays short of it: counted; of the rays cut
    # above the wall (0.9) only those whose coarse steps jumped over a corner of the wall are
    out2, _, c2 = diagnose(inputs, Constants(refl_height_cut=0.3), shader=water_reflection)
    cut = hits & (out2["refl_exit"] == 2)
    assert cut.any() and c2["refl_no_hit"][cut].all()
    out3, _, c3 = diagnose(inputs, Constants(refl_height_cut=0.9), shader=water_reflection)
    cut2, cut3 = out2["refl_exit"] == 2, out3["refl_exit"] == 2
    assert c3["refl_no_hit"][cut3].sum() < c2["refl_no_hit"][cut2].sum()


def test_failure_table_shares():
    water = np.ones((2, 3), bool)
    flip = np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.5]])
    a = np.array([[1, 1, 0], [0, 0, 0]], bool)
    b = np.array([[0, 1, 1], [0, 0, 0]], bool)
    rows = {r["class"]: r for r in failure_table({"a": a, "b": b}, flip, water)}
    assert rows["a"]["pixels"] == 2 and rows["a"]["pixel_share"] == pytest.approx(2 / 6)
    assert rows["a"]["flip_share"] == pytest.approx(0.3 / 2.0)
    assert rows["a"]["flip_inside"] == pytest.approx(0.15)
    assert rows["a"]["flip_outside"] == pytest.approx(1.7 / 4)
    assert rows["none"]["pixels"] == 3 and rows["none"]["flip_share"] == pytest.approx(1.4 / 2.0)
    label = primary_class({"no_crossing": a, "grazing": b}, water)
    assert label[0, 1] == CLASS_KEYS.index("no_crossing") + 1  # catalogue order decides
    assert label[0, 2] == CLASS_KEYS.index("grazing") + 1 and label[1, 0] == 0


def test_classify_refuses_plain_diagnostics():
    out = water_refraction.render(BENIGN, Constants()).numpy()
    with pytest.raises(ValueError, match="diagnose=True"):
        classify(out, out["mask"] > 0)


# ---- depth complexity: needs the scene's geometry ------------------------------------------


def ledge_experiment(ledge):
    from helpers import REPO
    from study import load_experiment

    return load_experiment(
        REPO / "experiments" / "failures_ledge.toml",
        [
            f"floor.ledge={ledge}",
            "resolution=[24, 24]",
            "fit.resolution=[24, 24]",
            "reference.water_mesh=16",
            "waves.amplitude=0.0",
        ],
    )


def test_depth_complexity_found_under_the_ledge(mi):
    from study.studies.failures import hidden_from_top_down

    exp = ledge_experiment("[-1.4, 0.2, -0.35, 0.15]")
    # rays from the water plane: straight down beside the ledge, straight down onto it, and
    # slanted under it from its +x side (enter below the underside at y = -0.5)
    o = np.array([[1.0, 0.0, 0.0], [-0.5, 0.0, 0.3], [0.5, 0.0, 0.0], [0.3, 0.0, 1.0]])
    d = np.array([[0.0, -1.0, 0.0], [0.0, -1.0, 0.0], [-0.6, -0.8, 0.0], [0.0, 1.0, 0.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # ray 3 reaches x = 0.2 at y = -0.4 (the ledge's side): its hit is visible from above only
    # if the side faces up; a side is vertical, so not hidden. Lower it: start at x = 0.6
    o[2, 0] = 0.6  # reaches x = 0.2 at y = -0.53, below the underside: floor under the ledge
    hid = hidden_from_top_down(exp, o, d)
    assert hid.tolist() == [False, False, True, False]
    flat = ledge_experiment("[0.0, 0.0, 0.0, 0.0]")
    assert not hidden_from_top_down(flat, o, d).any()


def test_ledge_is_in_the_top_down_textures_and_the_scene_key(mi):
    from study.scene.topdown import texture_extent, top_down_world_y

    exp, flat = (
        ledge_experiment("[-1.4, 0.2, -0.35, 0.15]"),
        ledge_experiment("[0.0, 0.0, 0.0, 0.0]"),
    )
    ext = texture_extent(exp)
    y = top_down_world_y(exp, ext, 32)
    x = ext[0] + (np.arange(32) + 0.5) / 32 * (ext[2] - ext[0])
    z = ext[1] + (np.arange(32) + 0.5) / 32 * (ext[3] - ext[1])
    over = (x > -1.35) & (x < 0.15)  # columns over the ledge
    rows = np.abs(z) < 2.4  # rows inside the pool (the ledge spans z)
    np.testing.assert_allclose(y[np.ix_(rows, over)], -0.35, atol=1e-4)  # its top, not the floor
    np.testing.assert_allclose(top_down_world_y(flat, ext, 32)[np.ix_(rows, over)], -1.6, atol=1e-4)
    assert exp.scene_hash() != flat.scene_hash() and exp.inputs_hash() != flat.inputs_hash()


def test_ledge_is_validated():
    from study import ExperimentError

    with pytest.raises(ExperimentError, match="floor.ledge"):
        ledge_experiment("[-1.4, 0.2, -0.35, 2.0]")  # underside below the floor
    with pytest.raises(ExperimentError, match="wave troughs"):
        ledge_experiment("[-1.4, 0.2, 0.1, 0.1]")
    with pytest.raises(ExperimentError, match="inside the pool"):
        ledge_experiment("[-3.0, 0.2, -0.35, 0.1]")


# ---- frozen kernels: a change of loop cap or of diagnostics never replays another recording ----


@pytest.mark.parametrize(
    "shader,kw,cap", [(water_refraction, {}, "loop_cap"), (water_reflection, {}, "refl_loop_cap")]
)
def test_frozen_renders_follow_the_loop_cap(shader, kw, cap, monkeypatch):
    """Measured on Dr.Jit 1.5.0 before shaders_port.pipeline.frame.frozen: loop_cap 3 after 2
    replayed the 2-step recording (iterations stayed 2)."""
    from shaders_port.pipeline import frame as _frame

    inputs = synthetic_inputs(32, 24)
    key = "iterations" if cap == "loop_cap" else "refl_iterations"
    monkeypatch.setattr(_frame, "USE_FROZEN", True)
    frozen_runs = [
        shader.render(inputs, Constants(**{cap: c}), diagnose=d, **kw).numpy()
        for c, d in ((2, False), (3, False), (4, True), (3, True), (2, False))
    ]
    monkeypatch.setattr(_frame, "USE_FROZEN", False)
    traced = [
        shader.render(inputs, Constants(**{cap: c}), diagnose=d, **kw).numpy()
        for c, d in ((2, False), (3, False), (4, True), (3, True), (2, False))
    ]
    for f, t in zip(frozen_runs, traced):
        assert set(f) == set(t)
        assert np.array_equal(f[key], t[key]) and np.array_equal(f["color"], t["color"])
    assert frozen_runs[1][key].max() == 3 and frozen_runs[2][key].max() == 4


# ---- the study through the CLI (sweep engine, one worker) ----------------------------------


@pytest.mark.slow
def test_failures_cli_tiny(tmp_path):
    """Two tiny scenes through ``study failures``: per-scene figure, tidy table, report; the
    ledge scene shows depth complexity, the capped-loop scene no-crossing rays."""
    from helpers import REPO
    from study.cli import main
    from study.sweep import read_table

    small = [
        "resolution=[24,24]",
        "fit.resolution=[24,24]",
        "reference.spp=4",
        "reference.water_mesh=32",
        "reference.texture_size=32",
        "reference.texture_spp=2",
        "waves.normal_map_size=32",
    ]
    args = [
        "failures",
        str(REPO / "experiments" / "failures_ledge.toml"),
        str(REPO / "experiments" / "failures_steps.toml"),
        "--out",
        str(tmp_path),
        "--workers",
        "1",
    ]
    args += [a for s in small for a in ("--set", s)]
    assert main(args) == 0
    rows = read_table(tmp_path / "failures.parquet")
    by = {(r["experiment"], r["class"]): r for r in rows}
    assert by[("failures_ledge", "depth_complexity")]["pixels"] > 0
    assert by[("failures_steps", "no_crossing")]["pixels"] > 0
    assert ("failures_steps", "refl_left_textures") in by and (
        "failures_ledge",
        "refl_no_hit",
    ) not in by
    for name in ("failures_ledge", "failures_steps"):
        shares = [
            r["pixel_share"] for r in rows if r["experiment"] == name and r["class"] != "none"
        ]
        assert all(0 <= s <= 1 for s in shares)
        assert (tmp_path / name / "failures.png").stat().st_size > 5_000
    report = (tmp_path / "report.md").read_text()
    assert "## failures_ledge (water_refraction)" in report and "`depth_complexity`" in report
