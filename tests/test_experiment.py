"""Experiment schema: every bad input names the key and what is allowed."""

import re
from pathlib import Path

import pytest

from study import ExperimentError, load_experiment, validate
from study.config.experiment import SCHEMA, schema_markdown

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize(
    "path", sorted((REPO / "experiments").glob("*.toml")), ids=lambda p: p.stem
)
def test_shipped_experiments_are_valid(path):
    exp = load_experiment(path)
    assert exp["name"] == path.stem


BAD = [
    ({"colour": 1}, r"unknown key.*'colour'"),
    ({"water": {"iorr": 1.3}}, r"'water.iorr' \(did you mean 'water.ior'\?\)"),
    ({"water": {"ior": "high"}}, r"water.ior: expected a number, got 'high'.*Range: \[1.0, 3.0\]"),
    ({"water": {"ior": 0.5}}, r"water.ior: 0.5 is out of range"),
    ({"water": {"ior": float("nan")}}, r"water.ior: nan is not finite"),
    ({"water": {"sigma_t": [0.1, 0.2]}}, r"water.sigma_t: expected a list of 3 numbers"),
    ({"water": {"sigma_t": [0.1, -0.2, 0.0]}}, r"water.sigma_t: -0.2 is out of range"),
    (
        {"floor": {"shape": "bowl"}},
        r"floor.shape: unknown value 'bowl'.*Allowed: flat, slope, steps, terrain",
    ),
    ({"floor": {"steps": 2.5}}, r"floor.steps: expected an integer"),
    ({"floor": {"depth": True}}, r"floor.depth: expected a number, got True"),
    ({"resolution": [256, 0]}, r"resolution: 0 is out of range"),
    ({"waves": {"offsets": [[0, 0]]}}, r"waves.offsets: expected 4 pairs"),
    ({"animation": {"frames": 0}}, r"animation.frames: 0 is out of range"),
    ({"animation": {"velocities": [[0, 0]]}}, r"animation.velocities: expected 4 pairs"),
    ({"animation": {"time_step": -0.1}}, r"animation.time_step: -0.1 is out of range"),
    ({"fit": {"solver": "newton"}}, r"fit.solver: unknown value 'newton'.*levenberg_marquardt"),
    (
        {"fit": {"parameters": ["attenuation_distance", "fresnel"]}},
        r"fit.parameters: unknown entry 'fresnel'",
    ),
    ({"fit": {"resolution": [100, 100]}}, r"fit.resolution \[100, 100\] must divide resolution"),
    ({"camera": {"position": [0, -1, 3]}}, r"camera must be above the water plane"),
    ({"reference": {"spp": "lots"}}, r"reference.spp: expected a number, got 'lots'"),
    ({"constants": {"loop_cap": 0}}, r"constants.loop_cap: 0 is out of range"),
    ({"variant": "metal"}, r"variant: unknown value 'metal'.*cuda_ad_rgb"),
]


@pytest.mark.parametrize("raw,message", BAD, ids=[m[:30] for _, m in BAD])
def test_bad_values_name_the_key(raw, message):
    with pytest.raises(ExperimentError, match=message):
        validate(raw)


def test_a_long_bad_list_is_clipped_in_the_message():
    """A list-of-numbers key given a huge string names the key without echoing all of it."""
    with pytest.raises(ExperimentError, match="tradeoff.loop_cap: expected a non-empty list") as e:
        validate({"tradeoff": {"loop_cap": "ab\n" * 3000}})
    assert len(str(e.value)) < 400


def test_bad_files(tmp_path):
    with pytest.raises(ExperimentError, match="does not exist"):
        load_experiment(tmp_path / "missing.toml")
    broken = tmp_path / "broken.toml"
    broken.write_text("name = \n")
    with pytest.raises(ExperimentError, match="not valid TOML"):
        load_experiment(broken)


def test_overrides():
    exp = validate(
        {},
        [
            "water.ior=1.5",
            "floor.shape=steps",
            "resolution=[64, 32]",
            "fit.resolution=[32, 16]",
            "reference.spp=auto",
        ],
    )
    assert exp["water.ior"] == 1.5 and exp["floor.shape"] == "steps"
    assert exp["resolution"] == [64, 32] and exp["reference.spp"] == "auto"
    with pytest.raises(ExperimentError, match="expected KEY=VALUE"):
        validate({}, ["water.ior"])
    with pytest.raises(ExperimentError, match="unknown key"):
        validate({}, ["water.density=3"])


def test_scene_hash_tracks_scene_keys_only():
    a = validate({})
    assert validate({"water": {"ior": 1.34}}).scene_hash() != a.scene_hash()
    assert validate({"fit": {"solver": "bfgs"}}).scene_hash() == a.scene_hash()
    # shader-input keys do not change the reference image
    assert (
        validate(
            {
                "reference": {"texture_size": 128, "fresnel_transmission": "radiance"},
                "waves": {"normal_map_size": 64},
            }
        ).scene_hash()
        == a.scene_hash()
    )
    assert validate({"waves": {"amplitude": 0.02}}).scene_hash() != a.scene_hash()
    # how the refraction texture is made changes the shader inputs' key, never the reference's
    for ref in (
        {"texture_method": "colour"},
        {"lighting_size": 64},
        {"wall_spp": 64},
        {"texture_spp": 64},
    ):
        b = validate({"reference": ref})
        assert b.scene_hash() == a.scene_hash() and b.inputs_hash() != a.inputs_hash(), ref
    # the reference's sample count changes the reference's key, never the shader inputs' key
    for ref in (
        {"spp": 64},
        {"spp": "auto", "target_noise": 0.02, "max_spp": 512},
        {"sampler": "independent"},
    ):
        b = validate({"reference": ref})
        assert b.scene_hash() != a.scene_hash() and b.inputs_hash() == a.inputs_hash(), ref
    assert (
        validate({"reference": {"seed": 3}}).inputs_hash() != a.inputs_hash()
    )  # seeds the textures too


def test_the_key_page_documents_every_key():
    page = (REPO / "docs" / "experiment-keys.md").read_text()
    assert schema_markdown() in page, "regenerate the docs: python scripts/build_docs.py"
    for key in SCHEMA:
        assert re.search(rf"`{re.escape(key)}`", page)
    assert "docs/experiment-keys.md" in (REPO / "experiments" / "README.md").read_text()


def test_an_unknown_key_sends_the_user_to_the_key_page():
    """The message names the page that lists the keys, and that page lists the suggestion."""
    with pytest.raises(ExperimentError) as err:
        validate({"camera": {"fovy": 40.0}})
    message = str(err.value)
    assert "(did you mean 'camera.fov_y'?)" in message
    assert message.endswith("Every key is listed in docs/experiment-keys.md")
    assert "`camera.fov_y`" in (REPO / "docs" / "experiment-keys.md").read_text()


def test_fit_parameters_default_to_what_the_shader_reads(capfd):
    """Unset, ``fit.parameters`` is every continuous constant the chosen shader reads (not its
    step schedule); so ``--set fit.shader=...`` works with any shader of the registry."""
    from shaders_port.variants import VARIANTS

    for name, v in VARIANTS.items():
        exp = validate({"fit": {"shader": name}})
        reads = set(v.reads())
        assert exp["fit.parameters"] and set(exp["fit.parameters"]) <= reads, name
        assert not set(exp["fit.parameters"]) & set(v.schedule), name
    base = validate({"fit": {"shader": "water_baseline"}})["fit.parameters"]
    assert "refraction_strength" in base and "bumptex_mult" not in base
    beer = validate({"fit": {"shader": "water_refraction_beer"}})["fit.parameters"]
    assert {"absorption_r", "absorption_g", "absorption_b"} <= set(beer)
    assert "attenuation_distance" not in beer  # the Beer-Lambert variant does not read it


def test_a_listed_constant_the_shader_does_not_read_is_dropped_with_a_note(capfd):
    from study.config import experiment

    experiment._NOTED.clear()  # the note is printed once per process and shader
    exp = load_experiment(REPO / "experiments" / "default.toml", ['fit.shader="water_baseline"'])
    listed = load_experiment(REPO / "experiments" / "default.toml")["fit.parameters"]
    assert "bumptex_mult" in listed and "bumptex_mult" not in exp["fit.parameters"]
    assert exp["fit.parameters"] == [p for p in listed if p != "bumptex_mult"]
    assert "water_baseline does not read bumptex_mult; not fitted" in capfd.readouterr().err
    with pytest.raises(ExperimentError, match="reads none of them"):
        validate({"fit": {"shader": "water_baseline", "parameters": ["bumptex_mult"]}})
    with pytest.raises(ExperimentError, match="unknown entry 'fresnel'"):  # still an error
        validate({"fit": {"shader": "water_baseline", "parameters": ["fresnel"]}})
