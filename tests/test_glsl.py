"""The shipped GLSL: compiles, core == compat through the table, seed fixes, constants block."""

from __future__ import annotations

import math
import re
import shutil

import numpy as np
import pytest

from shaders_port import CONSTANT_SPECS, Constants
from shaders_port import glsl_text as _glsl
from shaders_port.glsl_text import (
    BEGIN_MARKER,
    END_MARKER,
    compat_to_core,
    compile_check,
    declared_constants,
    glsl_path,
    read_constants,
    read_source,
    with_define,
    write_constants,
)

SHADERS = [
    ("water", "vert"),
    ("water_refraction", "frag"),
    ("water_reflection", "frag"),
    ("water_baseline", "frag"),
]
FRAGS = ["water_refraction", "water_reflection"]
BANNERS = [
    "Eye and light vectors",
    "Normal map: average four layers, bump scaling",
    "Refraction vector and step schedule",
    "Raycast the ground",
    "Interpolate the crossing",
    "Attenuation",
    "Reflection",
    "Specular highlight",
    "Fresnel combine",
]
REFL_ONLY = {"refl_steps_steep", "refl_steps_grazing", "refl_loop_cap", "refl_height_cut"}
# constants only the baseline shader (seeds 001-004, tests/test_water_baseline.py) declares
# (and water_refraction's PLANAR_REFLECTION variant its reflect_distortion)
BASELINE_ONLY = {
    "reflect_distortion",
    "refraction_index",
    "refraction_strength",
    "chromatic_dispersion",
}

CUSTOM = Constants(
    attenuation_distance=3.25,
    steps_grazing=17.0,
    steps_steep=2.5,
    loop_cap=77,
    refl_steps_steep=0.75,
    refl_steps_grazing=6.5,
    refl_loop_cap=90,
    refl_height_cut=1.5,
    specular_strength=0.3,
    specular_exponent=64.0,
    bumptex_mult=0.4,
    refr_coeff=0.7,
    water_color=(0.1, 0.2, 0.35, 0.9),
    reflect_color=(0.9, 0.95, 1.0, 1.0),
)

needs_glslang = pytest.mark.skipif(
    shutil.which("glslangValidator") is None,
    reason="glslangValidator missing: apt-get install glslang-tools",
)


def f32(c: Constants) -> dict:
    return {k: np.float32(v).tolist() for k, v in c.to_dict().items()}


@needs_glslang
@pytest.mark.parametrize("dialect", ["compat", "core"])
@pytest.mark.parametrize("name,stage", SHADERS)
def test_shipped_shader_compiles(name, stage, dialect):
    compile_check(glsl_path(name, stage, dialect))


@needs_glslang
@pytest.mark.parametrize("dialect", ["compat", "core"])
def test_noreflection_variant_compiles(dialect):
    src = with_define(read_source("water_refraction", "frag", dialect), "NOREFLECTION")
    assert src.split("\n")[1] == "#define NOREFLECTION"
    compile_check(src, "frag")


@needs_glslang
@pytest.mark.parametrize("dialect", ["compat", "core"])
def test_box_reflection_variant_compiles(dialect):
    src = with_define(read_source("water_refraction", "frag", dialect), "BOX_REFLECTION")
    compile_check(src, "frag")


@needs_glslang
@pytest.mark.parametrize("dialect", ["compat", "core"])
def test_ssr_reflection_variant_compiles(dialect):
    src = with_define(read_source("water_refraction", "frag", dialect), "SSR_REFLECTION")
    compile_check(src, "frag")


@pytest.mark.parametrize("name,stage", SHADERS)
def test_core_is_compat_through_substitution_table(name, stage):
    compat = read_source(name, stage, "compat")
    core = read_source(name, stage, "core")
    assert compat.startswith("#version 120\n") and core.startswith("#version 330 core\n")
    assert compat_to_core(compat, stage) == core
    # no compatibility built-in survives in the core file
    assert not re.search(
        r"\bgl_(TexCoord|TextureMatrix|FragColor|Vertex|MultiTexCoord0|"
        r"ModelViewProjectionMatrix|ModelViewProjectionMatrixInverse|NormalMatrix)\b|"
        r"texture2D|textureCube|^varying",
        core,
        re.M,
    )


@pytest.mark.parametrize("name", FRAGS)
def test_block_banners_in_order(name):
    src = read_source(name)
    pos = [src.find(f"// ---- [{i}] {t} ----") for i, t in enumerate(BANNERS, 1)]
    assert all(p >= 0 for p in pos), dict(zip(BANNERS, pos))
    assert pos == sorted(pos)


@pytest.mark.parametrize("name", FRAGS)
def test_seed_fixes_applied_and_quirks_kept(name):
    src = read_source(name)
    code = "\n".join(ln.split("//")[0] for ln in src.split("\n"))  # without comments
    for bad in (
        "varyingVecworldPosition",
        "waterTransformationMatrix",
        "waterDepth",
        "reflectionTop",
        "cpy-cpy",
        "texture2D(fresnelLookup, NdotV)",
    ):
        assert bad not in code, bad
    assert code.count("(cpoy-olddepth) / (cpoy-cpy+depth-olddepth)") == (
        1 if name == "water_refraction" else 2
    )
    assert "texture2D(fresnelLookup, vec2(NdotV, 0.5))" in code
    # quirks of the seed that are kept
    # (the screen-space reflection's fallback reads the sky cube map the same way)
    assert code.count("normalize(R)*vec3(1,-1,1)") == (2 if name == "water_refraction" else 1)
    assert "R.y = max(R.y,0.001);" in code and "clamp y to 0.0001" in src
    assert "olddepth=0;" in code
    assert "float NdotV = clamp( dot(vEye, vBumpTex),0,1);" in code
    assert "vec4(pow(clamp(dot(rLight, vEye),0,1),SPECULAR_EXPONENT)*lightcolor,1)" in code
    assert "mix(STEPS_GRAZING,STEPS_STEEP,-R.y)" in code
    assert "clamp( travelLength/ATTENUATION_DISTANCE, 0,1)" in code
    if name == "water_reflection":
        assert "mix(REFL_STEPS_STEEP,REFL_STEPS_GRAZING,1-R.y)" in code
        assert "current_position.y>REFL_HEIGHT_CUT" in code
        assert "i<REFL_LOOP_CAP" in code and "noHit=false;" in code


@pytest.mark.parametrize("dialect", ["compat", "core"])
@pytest.mark.parametrize("name", FRAGS)
def test_shipped_block_holds_the_defaults(name, dialect):
    src = read_source(name, "frag", dialect)
    assert f32(read_constants(src)) == f32(Constants())
    assert write_constants(src, Constants()) == src  # shipped files use the writer's format
    declared = set(declared_constants(src))
    expected = (
        set(CONSTANT_SPECS) - BASELINE_ONLY - (REFL_ONLY if name == "water_refraction" else set())
    )
    if name == "water_refraction":  # PLANAR_REFLECTION's seed-002 distortion
        expected.add("reflect_distortion")
    assert declared == expected


@pytest.mark.parametrize("dialect", ["compat", "core"])
@pytest.mark.parametrize("name", FRAGS)
def test_write_constants_round_trip(name, dialect):
    src = read_source(name, "frag", dialect)
    out = write_constants(src, CUSTOM)
    back = f32(read_constants(out))
    want = f32(CUSTOM)
    for k in declared_constants(src):
        assert back[k] == want[k], k
    a, b = src.split("\n"), out.split("\n")
    assert len(a) == len(b)
    i0, i1 = a.index(BEGIN_MARKER), a.index(END_MARKER)
    assert a[: i0 + 1] == b[: i0 + 1] and a[i1:] == b[i1:]
    changed = [i for i in range(len(a)) if a[i] != b[i]]
    assert changed and all(i0 < i < i1 for i in changed)
    assert "const int LOOP_CAP = 77;" in out and "const float STEPS_GRAZING = 17.0;" in out
    if shutil.which("glslangValidator"):
        compile_check(out, "frag")


def test_float_literals_are_glsl_floats():
    for x in (1e-3, 10000.0, 1e5, 7.5, 1.0 / 1.333, 123456789.0, 3.0):
        s = _glsl._float_literal(x)
        assert re.fullmatch(r"\d+\.\d*([eE][+-]?\d+)?|\d+[eE][+-]?\d+", s), s
        assert np.float32(float(s)) == np.float32(x)


BAD = [
    ("attenuation_distance", float("nan"), "not finite"),
    ("attenuation_distance", float("inf"), "not finite"),
    ("steps_grazing", "1.0; discard", "not a plain number"),
    ("specular_strength", True, "not a plain number"),
    ("attenuation_distance", -1.0, "outside"),
    ("loop_cap", 0, "outside"),
    ("loop_cap", 40.5, "integer"),
    ("refr_coeff", 1.5, "outside"),
    ("water_color", (0.1, 0.2, 0.3), "4 components"),
    ("water_color", (0.1, 0.2, float("nan"), 1.0), "not finite"),
    ("reflect_color", "1,1,1,1", "4 components"),
]


@pytest.mark.parametrize("name,value,why", BAD)
def test_bad_values_refused(name, value, why):
    c = Constants().replace(**{name: value})
    src = read_source("water_reflection")
    with pytest.raises(ValueError) as err:
        write_constants(src, c)
    msg = str(err.value)
    glsl, _, _, (lo, hi) = CONSTANT_SPECS[name]
    assert why in msg and name in msg and glsl in msg, msg
    if why != "4 components":
        assert f"[{lo}, {hi}]" in msg, msg


def test_block_errors_are_clear():
    src = read_source("water_refraction")
    with pytest.raises(ValueError, match="exactly one tunable-constants block"):
        write_constants(src.replace(END_MARKER, "// end"), Constants())
    with pytest.raises(ValueError, match="FOO is not a tunable constant"):
        read_constants(src.replace("const int LOOP_CAP = 40;", "const int FOO = 40;"))
    with pytest.raises(ValueError, match="declared twice"):
        read_constants(
            src.replace(
                "const int LOOP_CAP = 40;", "const int LOOP_CAP = 40;\nconst int LOOP_CAP = 41;"
            )
        )
    with pytest.raises(ValueError, match="expected 'const float'"):
        read_constants(src.replace("const float STEPS_STEEP", "uniform float STEPS_STEEP"))


@needs_glslang
def test_compile_check_reports_the_log():
    src = read_source("water_refraction").replace("float cpy = current_position.y;", "")
    with pytest.raises(RuntimeError, match="cpy"):
        compile_check(src, "frag")


def test_compile_check_names_the_package_when_missing(monkeypatch):
    monkeypatch.setattr(_glsl.shutil, "which", lambda name: None)
    with pytest.raises(RuntimeError, match="apt-get install glslang-tools"):
        compile_check(read_source("water"), "vert")


def test_unknown_names_refused():
    with pytest.raises(ValueError, match="unknown shader"):
        glsl_path("water_foam")
    with pytest.raises(ValueError, match="dialect"):
        glsl_path("water", "vert", "es")
    assert math.isclose(read_constants(read_source("water_refraction")).attenuation_distance, 7.5)
