"""Export of fitted constants into the shipped GLSL: both dialects compile, the constants block
holds the constants and nothing else changes, the exported shader runs on llvmpipe like the
port, constants files are checked, and a refused export leaves nothing behind."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from helpers.synthetic import synthetic_inputs
from shaders_port import CONSTANT_SPECS, Constants, compile_check, read_constants, read_source
from shaders_port.glsl_text import BEGIN_MARKER, END_MARKER, declared_constants
from study.export.shaders import export_shaders, load_constants_json
from study.commands import run_export
from study.export.gl_check import gl_check
from shaders_port.variants import VARIANTS, get_variant

# every constant away from its default; 0.1, 0.3, 0.7, 0.76 and the fitted-looking
# attenuation are not exact in float32
EXPORTED = Constants(
    attenuation_distance=4.999999836762939,
    steps_grazing=8.0,
    steps_steep=2.5,
    loop_cap=50,
    refl_steps_steep=0.75,
    refl_steps_grazing=3.5,
    refl_loop_cap=48,
    refl_height_cut=0.7,
    specular_strength=1.5,
    specular_exponent=128.0,
    bumptex_mult=0.7,
    refr_coeff=0.76,
    water_color=(0.1, 0.3, 0.2, 1.0),
    reflect_color=(0.9, 0.95, 1.0, 1.0),
    absorption_r=0.3,
    absorption_g=0.07,
    absorption_b=0.05,
    specular_roughness=0.15,
    sun_disc_radius=4.5,
    sun_disc_softness=0.2,
    sun_disc_radiance=6.0,
    refine_steps=2,
    reflect_distortion=0.07,
)
# the shader files, then one file per variant compiled with preprocessor names
FILES = [
    (d, n, s)
    for d in ("compat", "core")
    for n, s in (
        ("water", "vert"),
        ("water_refraction", "frag"),
        ("water_reflection", "frag"),
        ("water_baseline", "frag"),
    )
]
VARIANT_FILES = [
    (d, v.name, "frag") for d in ("compat", "core") for v in VARIANTS.values() if v.name != v.shader
]


def _split_block(text: str) -> tuple[str, list[str], str]:
    """(text up to and including the BEGIN line, lines inside the block, text from END on)."""
    lines = text.split("\n")
    b = [i for i, ln in enumerate(lines) if ln.strip() == BEGIN_MARKER]
    e = [i for i, ln in enumerate(lines) if ln.strip() == END_MARKER]
    assert len(b) == 1 and len(e) == 1, "one constants block expected"
    return "\n".join(lines[: b[0] + 1]), lines[b[0] + 1 : e[0]], "\n".join(lines[e[0] :])


def _f32(v):
    return [np.float32(x) for x in v] if isinstance(v, (tuple, list)) else np.float32(v)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "shaders"
    paths = export_shaders(EXPORTED, out)
    return out, paths


def test_writes_both_dialects_and_they_compile(exported):
    out, paths = exported
    assert sorted(paths) == sorted(out / d / f"{n}.{s}" for d, n, s in FILES + VARIANT_FILES)
    for p in paths:
        compile_check(p)  # raises RuntimeError with the compiler log


@pytest.mark.parametrize("dialect", ["compat", "core"])
@pytest.mark.parametrize("name", ["water_refraction", "water_reflection"])
def test_block_holds_constants_and_nothing_else_changes(exported, dialect, name):
    out, _ = exported
    text = (out / dialect / f"{name}.frag").read_text(encoding="utf-8")
    shipped = read_source(name, "frag", dialect)
    # the constants round trip (float32, as the GPU sees them) for every name the shader declares
    declared = declared_constants(text)
    assert {"attenuation_distance", "water_color"} <= set(declared) or name == "water_reflection"
    assert len(declared) >= 5, declared
    back = read_constants(text)
    for n in declared:
        assert _f32(getattr(back, n)) == _f32(getattr(EXPORTED, n)), n
        assert _f32(getattr(back, n)) != _f32(CONSTANT_SPECS[n][2]), f"{n} still at its default"
    # outside the block: byte for byte the shipped file; inside: only the values changed
    head, block, tail = _split_block(text)
    head0, block0, tail0 = _split_block(shipped)
    assert head.encode() == head0.encode() and tail.encode() == tail0.encode()
    assert len(block) == len(block0)
    for new, old in zip(block, block0):
        if old.strip().startswith("//") or not old.strip():
            assert new == old
        else:
            assert new.split("=")[0] == old.split("=")[0] and new.endswith(";") == old.endswith(";")


def test_vertex_shaders_copied_as_shipped(exported):
    out, _ = exported
    for dialect in ("compat", "core"):
        assert (out / dialect / "water.vert").read_bytes() == read_source(
            "water", "vert", dialect
        ).encode("utf-8")


def test_default_constants_reproduce_the_shipped_files(tmp_path):
    paths = export_shaders(Constants(), tmp_path / "shaders")
    assert len(paths) == len(FILES) + len(VARIANT_FILES)
    for d, n, s in FILES:
        assert (tmp_path / "shaders" / d / f"{n}.{s}").read_text(encoding="utf-8") == read_source(
            n, s, d
        )
    for d, n, s in VARIANT_FILES:  # the shader file with the variant's #define lines
        v = get_variant(n)
        text = (tmp_path / "shaders" / d / f"{n}.{s}").read_text(encoding="utf-8")
        assert text == v.source(d)
        assert text.split("\n")[1 : 1 + len(v.defines)] == [
            f"#define {x}" for x in reversed(v.defines)
        ]


@pytest.mark.parametrize("name", ["water_refraction_beer_ggx", "water_refraction_secant"])
def test_exported_variant_file_runs_like_the_variant(exported, name):
    """``gl_check`` runs ``core/<variant>.frag`` exactly as exported: its #define lines select the
    variant; with them removed the same file no longer matches the variant's port."""
    out, _ = exported
    inputs = synthetic_inputs(width=48, height=36)
    res = gl_check(name, inputs, EXPORTED, out)
    assert res["passed"] and res["n_water"] > 500, res
    bare = out.parent / "bare"
    (bare / "core").mkdir(parents=True, exist_ok=True)
    text = (out / "core" / f"{name}.frag").read_text()
    for d in get_variant(name).defines:
        text = text.replace(f"#define {d}\n", "")
    (bare / "core" / f"{name}.frag").write_text(text)
    res = gl_check(name, inputs, EXPORTED, bare)
    assert not res["passed"] and res["mean_abs"] > 1e-3, res


# ---- the exported shader on llvmpipe against the port -------------------------------------


@pytest.mark.parametrize("shader", ["water_refraction", "water_reflection"])
def test_exported_core_shader_runs_like_the_port(exported, shader):
    """``gl_check`` runs the exported core shader with its own block (uniforms at their
    initialisers) on llvmpipe and compares it with the port given the same constants."""
    out, _ = exported
    inputs = synthetic_inputs(width=48, height=36)
    res = gl_check(shader, inputs, EXPORTED, out)
    assert res["n_water"] > 500
    assert res["mean_abs"] <= 1e-3 and res["p999"] <= 1e-2, res
    assert res["unexplained"] == 0, res


def test_gl_check_sees_constants_that_differ(exported):
    """The check can fail: the same exported shader against the port with the defaults."""
    out, _ = exported
    res = gl_check("water_refraction", synthetic_inputs(width=48, height=36), Constants(), out)
    assert res["mean_abs"] > 1e-3, res


def test_gl_renderer_on_exported_text_matches_port(exported):
    """The same comparison by hand: GLRenderer(source=exported text).render(None) vs the port."""
    from shaders_port.ports import water_refraction
    from shaders_port.gl.renderer import GLRenderer

    out, _ = exported
    inputs = synthetic_inputs(width=48, height=36)
    with GLRenderer(
        "water_refraction", inputs, source=(out / "core" / "water_refraction.frag").read_text()
    ) as r:
        rgba, gl_mask = r.render(None)
    port = water_refraction.render(inputs, EXPORTED).numpy()
    both = gl_mask & (port["mask"] > 0.5)
    d = np.abs(rgba[..., :3] - port["color"]).max(-1)[both]
    assert both.sum() > 500
    if not (d.mean() <= 1e-3 and np.percentile(d, 99.9) <= 1e-2):
        from helpers.images import save_failure

        save_failure(
            "export_gl_vs_port",
            gl=rgba[..., :3],
            port=port["color"],
            error=np.abs(rgba[..., :3] - port["color"]),
        )
    assert d.mean() <= 1e-3 and np.percentile(d, 99.9) <= 1e-2, (d.mean(), np.percentile(d, 99.9))


# ---- constants files --------------------------------------------------------------------------


def _write(tmp_path, text, name="c.json") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_load_calibrate_style_file(tmp_path):
    data = {
        "experiment": "x",
        "error": {"rmse": {"default": 0.2, "fitted": 0.1}},
        "constants": EXPORTED.to_dict(),
    }
    c = load_constants_json(_write(tmp_path, json.dumps(data)))
    assert c.to_dict() == EXPORTED.to_dict()


def test_load_reads_the_glsl_named_file_and_the_older_layout(tmp_path):
    """constants.json names constants as the GLSL does, what the shader reads apart from the rest
    of the block; files older versions wrote (the study's names, all in one table) still load."""
    from study.export.result import glsl_named

    new = glsl_named({"shader": "water_refraction", "constants": EXPORTED.to_dict()})
    assert "ATTENUATION_DISTANCE" in new["constants"] and "ABSORPTION_R" not in new["constants"]
    assert "ABSORPTION_R" in new["constants_not_read"]["values"]
    assert glsl_named(new) == new  # idempotent
    for data in (new, {"shader": "water_refraction", "constants": EXPORTED.to_dict()}):
        c = load_constants_json(_write(tmp_path, json.dumps(data)))
        assert c.to_dict() == EXPORTED.to_dict()
    both = {"constants": {"bumptex_mult": 0.9, "BumptexMult": 0.8}}
    with pytest.raises(ValueError, match="BumptexMult and bumptex_mult are two names of one"):
        load_constants_json(_write(tmp_path, json.dumps(both)))


def test_load_flat_file(tmp_path):
    c = load_constants_json(
        _write(
            tmp_path, json.dumps({"attenuation_distance": 5.5, "water_color": [0.1, 0.2, 0.3, 1.0]})
        )
    )
    assert c.attenuation_distance == 5.5 and c.water_color == (0.1, 0.2, 0.3, 1.0)
    assert c.bumptex_mult == Constants().bumptex_mult  # the rest at the defaults


BAD_FILES = {
    "invalid_json": ('{"attenuation_distance": 5.0', r"not valid JSON"),
    "not_an_object": ("[1, 2, 3]", r"expected a JSON object.*list"),
    "constants_not_object": ('{"constants": 3}', r"'constants' must be an object"),
    "unknown": ('{"attenuation_distanse": 5.0}', r"unknown constant.*attenuation_distanse"),
    "nan": ('{"attenuation_distance": NaN}', r"attenuation_distance.*nan.*not a finite"),
    "infinity": ('{"bumptex_mult": Infinity}', r"bumptex_mult.*inf.*not a finite"),
    "string": (
        '{"attenuation_distance": "7.5; discard"}',
        r"attenuation_distance.*7\.5; discard.*not a number",
    ),
    "bool": ('{"specular_strength": true}', r"specular_strength.*True"),
    "null": ('{"specular_strength": null}', r"specular_strength.*None.*not a number"),
    "out_of_range": ('{"attenuation_distance": 1e9}', r"attenuation_distance.*outside"),
    "negative": ('{"specular_strength": -1}', r"specular_strength.*outside"),
    "non_integer_cap": ('{"loop_cap": 40.5}', r"loop_cap.*integer"),
    "vec4_short": ('{"water_color": [0.1, 0.2, 0.3]}', r"water_color.*4 components.*got 3"),
    "vec4_scalar": ('{"water_color": 0.5}', r"water_color.*4 components"),
    "vec4_string": ('{"water_color": [0.1, 0.2, 0.3, "a"]}', r"water_color.*'a'.*not a number"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_constants_file_is_refused(tmp_path, case):
    text, pattern = BAD_FILES[case]
    path = _write(tmp_path, text)
    with pytest.raises(ValueError, match=pattern) as exc:
        load_constants_json(path)
    assert str(path) in str(exc.value)  # the message names the file
    out = tmp_path / "out"
    with pytest.raises(ValueError, match=pattern):
        run_export(path, out)
    assert not out.exists(), list(out.rglob("*"))


def test_missing_file_is_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_constants_json(tmp_path / "nope.json")
    with pytest.raises(FileNotFoundError):
        run_export(tmp_path / "nope.json", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_scalar_given_as_list_is_refused_without_leftovers(tmp_path):
    """A list for a scalar constant must be refused, and nothing may be created."""
    path = _write(tmp_path, '{"attenuation_distance": [1.0, 2.0]}')
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="attenuation_distance"):
        run_export(path, out)
    assert not out.exists(), "a refused export left its output folder behind"


# ---- a failing export keeps a good one -------------------------------------------------------


def _snapshot(folder: Path) -> dict:
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def test_failed_export_keeps_existing_export(tmp_path, monkeypatch):
    good = _write(tmp_path, json.dumps({"constants": EXPORTED.to_dict()}), "good.json")
    out = tmp_path / "out"
    run_export(good, out)
    before = _snapshot(out)
    glsl = [k for k in before if k.split("/")[1] in ("compat", "core")]
    assert len(glsl) == len(FILES) + len(VARIANT_FILES)
    # refused at load
    with pytest.raises(ValueError):
        run_export(_write(tmp_path, '{"attenuation_distance": NaN}', "bad.json"), out)
    assert _snapshot(out) == before
    # refused while writing (a scalar given as a list passes the loader today)
    with pytest.raises(ValueError):
        run_export(_write(tmp_path, '{"attenuation_distance": [1.0, 2.0]}', "bad2.json"), out)
    assert _snapshot(out) == before
    # a shader that does not compile, the fifth of six
    import study.export.shaders as ex

    calls = {"n": 0}
    real = ex.compile_check

    def failing(text, stage):
        calls["n"] += 1
        if calls["n"] == 5:
            raise RuntimeError("glslangValidator rejected <source> (frag): injected")
        return real(text, stage)

    monkeypatch.setattr(ex, "compile_check", failing)
    with pytest.raises(RuntimeError, match="injected"):
        export_shaders(Constants(), out / "shaders")
    assert calls["n"] == 5
    assert _snapshot(out) == before
    assert sorted(p.name for p in out.iterdir()) == ["shaders"]  # no temp or .old folders left
    # a good export replaces the old one completely
    monkeypatch.setattr(ex, "compile_check", real)
    export_shaders(Constants(), out / "shaders")
    assert sorted(p.name for p in out.iterdir()) == ["shaders"]
    assert (out / "shaders" / "core" / "water_refraction.frag").read_text() == read_source(
        "water_refraction", "frag", "core"
    )
