"""Engine targets of the export: GLSL ES 3.00, HLSL 5.0, Metal and SPIR-V by glslang and
SPIRV-Cross, the fitted constants carried as specialization constants, each target checked
(spirv-val, HLSL back through glslang's HLSL front end, the ES profile), and the HLSL run on
llvmpipe against the port for every shader variant."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from shaders_port import CONSTANT_SPECS, Constants
from shaders_port.glsl_text import constants_read, read_source, write_constants
from shaders_port.spirv.tools import missing_tools
from shaders_port.variants import SHIPPED, VARIANTS
from study.export.shaders import export_shaders
from study.export.targets import TARGETS, resolve_targets, target_file
from helpers.synthetic import EXPORT_CONSTANTS as FITTED
from helpers.synthetic import synthetic_baseline_inputs, synthetic_inputs, synthetic_inputs_for

MISSING = missing_tools()
pytestmark = pytest.mark.skipif(
    bool(MISSING), reason=f"the engine targets need {', '.join(MISSING)}"
)


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    """Every variant exported with FITTED and every target."""
    out = tmp_path_factory.mktemp("targets") / "shaders"
    export_shaders(FITTED, out, targets=None)
    return out


def _values(text: str) -> set:
    """float32 of every number in a shader text (float literals printed to full precision)."""
    nums = re.findall(r"(?<![\w.])-?\d+\.\d*(?:[eE][-+]?\d+)?|(?<![\w.])\d+(?![\w.])", text)
    return {np.float32(float(n)) for n in nums}


def _expected(name: str) -> list:
    v = getattr(FITTED, name)
    return [np.float32(x) for x in (v if isinstance(v, tuple) else (v,))]


@pytest.mark.parametrize("target", [t for t in TARGETS if t != "spirv"])
@pytest.mark.parametrize("variant", list(SHIPPED))
def test_every_target_text_holds_the_fitted_constants(export, target, variant):
    v = VARIANTS[variant]
    text = (export / target_file(target, v.name, "frag")).read_text()
    assert "uniform float BumptexMult" not in text and "= 0.9797;" not in text.replace(" ", "")
    got = _values(text)
    for name in constants_read(v.source()):
        for x in _expected(name):
            assert x in got, (target, variant, name, x)


@pytest.mark.parametrize("variant", list(SHIPPED))
def test_spirv_carries_the_fitted_constants_as_specialization_defaults(export, variant):
    refl = json.loads((export / "spirv" / f"{variant}.frag.reflect.json").read_text())
    got = {c["name"]: np.float32(c["default_value"]) for c in refl["specialization_constants"]}
    for name in constants_read(VARIANTS[variant].source()):
        glsl, kind = CONSTANT_SPECS[name][:2]
        names = [f"{glsl}_{c}" for c in "rgba"] if kind.endswith("vec4") else [glsl]
        assert [got[n] for n in names] == _expected(name), (variant, name)


def test_the_tools_accept_the_exported_files(export):
    """The documented chain, run by hand on the exported files."""
    core = export / "core" / "water_refraction.frag"
    spv = export.parent / "raw.spv"
    subprocess.run(
        ["glslangValidator", "-G", "--aml", "--amb", "-o", str(spv), str(core)], check=True
    )
    subprocess.run(["spirv-val", str(spv)], check=True)
    hlsl = subprocess.run(
        ["spirv-cross", str(spv), "--hlsl", "--shader-model", "50"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    assert "float4 main" not in hlsl and "frag_main" in hlsl
    for name in ("water_refraction", "water_reflection", "water_baseline"):
        path = export / "hlsl" / f"{name}.frag.hlsl"
        subprocess.run(
            ["glslangValidator", "-D", "-e", "main", "-S", "frag", "-V", "-o", str(spv), str(path)],
            check=True,
        )
        subprocess.run(["spirv-val", str(export / "spirv" / f"{name}.frag.spv")], check=True)
        subprocess.run(["glslangValidator", str(export / "gles300" / f"{name}.frag")], check=True)
    subprocess.run(["glslangValidator", str(export / "gles300" / "water.vert")], check=True)


def test_vertex_outputs_and_fragment_inputs_share_locations(export):
    """Stages link by location outside GLSL (HLSL TEXCOORDn, Metal locn, Vulkan)."""
    vert = json.loads((export / "spirv" / "water.vert.reflect.json").read_text())
    outs = {o["name"]: o["location"] for o in vert["outputs"]}
    for name in ("water_refraction", "water_reflection", "water_baseline"):
        frag = json.loads((export / "spirv" / f"{name}.frag.reflect.json").read_text())
        for i in frag["inputs"]:
            assert outs[i["name"]] == i["location"], (name, i)


def test_binding_sheets_and_manifest(export):
    manifest = json.loads((export / "targets.json").read_text())
    assert sorted(manifest["targets"]) == sorted(resolve_targets(None))
    assert "no Metal compiler" in manifest["targets"]["msl"]["check"]
    for target in manifest["targets"]:
        sheet = (export / target / "BINDINGS.md").read_text()
        assert "top-down" in sheet and "worldYComponent" in sheet, target
        assert "| `BumptexMult` | 0.9797 |" in sheet, target
        assert "uTextureMatrix0" in sheet and "world (x, y, z, 1) -> (s, t)" in sheet, target
    assert "register" in (export / "hlsl" / "BINDINGS.md").read_text()


def test_the_short_sheet_marks_what_was_fitted(tmp_path):
    """One shader's export: its sheet lists the constants it reads, the fitted ones in bold with
    their status, those it never reads apart; the full reflection is the second sheet."""
    status = {"BumptexMult": "fitted", "waterColor[0]": "bound", "waterColor[1]": "frozen"}
    export_shaders(FITTED, tmp_path, ["water_refraction"], ["gles300"], status=status)
    sheet = (tmp_path / "gles300" / "BINDINGS.md").read_text()
    assert "| 10 | `BumptexMult` | **0.9797** | fitted |" in sheet
    assert "| 12 | `waterColor_r` | **0.0612** | fitted, at its range's bound |" in sheet
    assert "| 13 | `waterColor_g` | 0.2391 | held: not identified by the reference |" in sheet
    assert "| 0 | `ATTENUATION_DISTANCE` | 5.4321 | held at the experiment's value" in sheet
    assert "The 2 fitted are in bold." in sheet
    # water_refraction never reads the absorption of the Beer variants: apart, not in the table
    table, _, rest = sheet.partition("Declared but read by no line of this shader")
    assert "ABSORPTION_R" not in table and "`ABSORPTION_R` (20)" in rest
    full = (tmp_path / "gles300" / "BINDINGS_FULL.md").read_text()
    assert "**Stage inputs and outputs**" in full and "varyingVecEye" in full
    assert "varyingVecEye" not in sheet  # a varying links the stages: nothing to bind


def _hlsl_check(export, variant, inputs):
    from study.export.gl_check import hlsl_check

    try:
        return hlsl_check(variant, inputs, FITTED, export)
    except RuntimeError as exc:
        if "EGL" in str(exc) or "context" in str(exc).lower():
            pytest.skip(f"no headless OpenGL here: {exc}")
        raise


@pytest.fixture(scope="module")
def inputs():
    return synthetic_inputs(width=96, height=72)


@pytest.fixture(scope="module")
def baseline_inputs():
    return synthetic_baseline_inputs(width=96, height=72)


@pytest.mark.parametrize("variant", list(SHIPPED))
def test_hlsl_round_trip_matches_the_port_on_llvmpipe(export, inputs, baseline_inputs, variant):
    """The HLSL, compiled back by glslang -D and translated to GLSL 330, against the port with
    the GL check's thresholds (mean <= 1e-3, 99.9th percentile <= 1e-2, nothing unexplained)."""
    frame = baseline_inputs if VARIANTS[variant].inputs else inputs
    res = _hlsl_check(export, variant, frame)
    assert res["n_water"] > 500
    assert res["passed"], res
    assert res["max_abs"] < 1e-3, res  # measured ~2e-5: float32 rounding only


def test_a_failed_translation_writes_nothing(tmp_path, monkeypatch):
    import shaders_port.spirv.tools as S

    out = tmp_path / "shaders"
    export_shaders(Constants(), out, ["water_refraction"])
    before = sorted(p.relative_to(out) for p in out.rglob("*"))

    def broken(*a, **k):
        raise RuntimeError("spirv-cross failed on hlsl/water.vert.hlsl: (simulated)")

    monkeypatch.setattr(S, "cross", broken)
    with pytest.raises(RuntimeError, match="spirv-cross failed"):
        export_shaders(FITTED, out, ["water_refraction"], targets=["hlsl"])
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shaders"]


def test_resolve_targets(monkeypatch):
    from shaders_port.spirv import wgsl

    # every target whose tools are here: wgsl needs Node.js and naga-wasm besides
    assert resolve_targets(None) == tuple(
        t for t in TARGETS if t != "wgsl" or not wgsl.missing_tools()
    )
    assert resolve_targets([]) == ()
    with pytest.raises(ValueError, match="unknown target.*'dxil'.*gles300"):
        resolve_targets(["dxil"])
    real = shutil.which
    monkeypatch.setattr(shutil, "which", lambda n: None if n == "spirv-cross" else real(n))
    assert resolve_targets(None) == ()
    with pytest.raises(RuntimeError, match="apt-get install spirv-cross"):
        resolve_targets(["hlsl"])


def test_uniform_initializers_become_specialization_constants():
    from shaders_port.spirv.tools import SPEC_IDS, specialize_constants

    src = write_constants(read_source("water_refraction", "frag", "core"), FITTED)
    out = specialize_constants(src)
    assert re.search(r"uniform \w+ \w+\s*=", out) is None
    assert (
        f"layout(constant_id = {SPEC_IDS['BumptexMult']}) const float BumptexMult = 0.9797;" in out
    )
    assert (
        "const vec4 waterColor = vec4(waterColor_r, waterColor_g, waterColor_b, waterColor_a);"
        in out
    )


@pytest.mark.parametrize("seed", range(3))
def test_hlsl_round_trip_of_configurations_nobody_registered(tmp_path, seed):
    """Shaders of the space drawn at random (fixed seeds): exported to every target, and the
    HLSL round trip matches the port on llvmpipe as the registered variants' does."""
    import random

    from shaders_port import space as _space

    c = random.Random(200 + seed).choice(_space.configurations({"refraction": "raycast"}))
    name = _space.name_of(c)
    out = tmp_path / "shaders"
    export_shaders(FITTED, out, [name], targets=None)
    res = _hlsl_check(out, name, synthetic_inputs_for(name, 96, 72))
    assert res["n_water"] > 500 and res["passed"], (name, res)
