"""Several views of one scene (``camera.views``): one still experiment per view, cached as an
experiment with that camera alone; the scene's inputs built once and seen from each camera;
``study calibrate`` fits one constants block over the views and ``study generalise`` leaves each
out in turn, both through the joint fit's path."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import REPO, experiments
from helpers.experiments import DEFAULT, SMALL_OVERRIDES, replaced, sets
from study import load_experiment
from study.config.errors import ExperimentError
from study.scene.views import view_experiments, view_inputs

VIEWS = "camera.views=[[[3.0, 2.5, 5.5], [0.0, -1.0, 0.0]], [[-4.0, 3.5, 4.0], [0.0, -1.0, 0.0]]]"


def test_each_view_is_an_experiment_with_that_camera():
    exp = load_experiment(DEFAULT, SMALL_OVERRIDES + [VIEWS])
    views = view_experiments(exp)
    assert [v.camera.position for v in views] == [
        exp.camera.position, [3.0, 2.5, 5.5], [-4.0, 3.5, 4.0]]  # fmt: skip
    assert all(v.camera.views == [] for v in views)
    # the first view is the experiment without its other views: the same cached reference
    assert views[0].scene_hash() == load_experiment(DEFAULT, SMALL_OVERRIDES).scene_hash()
    other = load_experiment(DEFAULT, SMALL_OVERRIDES + ["camera.position=[3.0, 2.5, 5.5]"])
    assert views[1].scene_hash() == other.scene_hash()
    assert view_experiments(views[1]) == [views[1]]


def test_views_are_checked():
    with pytest.raises(ExperimentError, match=r"camera.views\[0\].*above the water"):
        load_experiment(DEFAULT, ["camera.views=[[[0.0, -1.0, 3.0], [0.0, -1.0, 0.0]]]"])
    with pytest.raises(ExperimentError, match="camera.views: expected a list of"):
        load_experiment(DEFAULT, ["camera.views=[[0.0, 1.0, 3.0]]"])
    animated = load_experiment(DEFAULT, [VIEWS, "animation.frames=2"])
    with pytest.raises(ExperimentError, match="camera.views and animation.frames"):
        view_experiments(animated)


def test_a_views_inputs_are_the_scenes_seen_from_its_camera(mi, tmp_path):
    from study.scene.shader_inputs import build_shader_inputs

    exp = load_experiment(DEFAULT, SMALL_OVERRIDES + [VIEWS])
    first, second, _ = view_experiments(exp)
    base = build_shader_inputs(first)
    seen = view_inputs(second, base)
    own = build_shader_inputs(second)  # built for that camera from scratch
    for field in ("refraction_texture", "world_y", "normal_map", "cubemap", "refl_texture"):
        assert getattr(seen, field) is getattr(base, field)  # shared, not rebuilt
        np.testing.assert_array_equal(getattr(seen, field), getattr(own, field))
    for field in ("view_proj", "viewpos", "lightpos", "tex_matrix0"):
        np.testing.assert_array_equal(getattr(seen, field), getattr(own, field))
    assert not np.array_equal(seen.view_proj, base.view_proj)


TINY = replaced(experiments.TINY, "reference.spp=8", "fit.max_steps=8",
                'fit.parameters=["attenuation_distance","water_color"]')  # fmt: skip
TWO_VIEWS = "camera.views=[[[3.0, 2.5, 5.5], [0.0, -1.0, 0.0]]]"


@pytest.mark.slow
def test_calibrate_and_generalise_over_views(tmp_path):
    from study.cli import main

    exp = str(REPO / "experiments" / "default.toml")
    out = tmp_path / "gen"
    assert main(["generalise", exp, "--out", str(out), *sets(TINY + [TWO_VIEWS])]) == 0
    gen = json.loads((out / "generalise.json").read_text())
    assert gen["scenes"] == ["default-view0", "default-view1"]
    for r in gen["leave_one_out"]:
        for k in ("seed", "others", "own", "first"):
            assert 0 <= r[k]["flip"] <= 1
    # the first view's own fit, scored on the first view, is its own fit
    row0 = gen["leave_one_out"][0]
    assert row0["first"] == row0["own"]
    assert "default-view0's fit" in (out / "generalise.md").read_text()
    one = tmp_path / "one"
    assert main(["calibrate", exp, "--out", str(one), *sets(TINY + [TWO_VIEWS])]) == 0
    joint = json.loads((one / "constants.json").read_text())
    assert joint["scenes"] == ["default-view0", "default-view1"]
    assert joint["constants"] == gen["joint"]["constants"]  # the same joint fit


@pytest.mark.slow
def test_the_tradeoff_judges_its_shaders_on_every_view(tmp_path):
    """``study tradeoff`` on an experiment with two views: one scene per view, the
    recommendation judged over both (the study's joint points)."""
    from study.cli import main

    tiny = SMALL_OVERRIDES + [
        'tradeoff.variants=["water_refraction"]', "tradeoff.steps_grazing=[5.0]",
        "tradeoff.steps_steep=[3.0]", "tradeoff.loop_cap=[20]", "tradeoff.scales=[0.5,1.0]",
        "tradeoff.converged_scale=2.0", "tradeoff.gl_repeats=3", "fit.max_steps=3", TWO_VIEWS,
    ]  # fmt: skip
    out = tmp_path / "t"
    args = ["tradeoff", str(DEFAULT), "--out", str(out), "--workers", "1",
            "--search", "exhaustive", *sets(tiny)]  # fmt: skip
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert sorted(summary["scenes"]) == ["default-view0", "default-view1"]
    assert all(summary["scenes"][n]["recommended"] for n in summary["scenes"])
