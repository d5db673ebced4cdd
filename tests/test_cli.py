"""The command line: ``study --help``, errors with exit code 2 and a message naming the problem,
and render / preview / calibrate / export on a tiny experiment (24x24, 16 spp), in-process
through ``study.cli.main``."""

from __future__ import annotations

import json
import math
import subprocess

import numpy as np
import pytest

from helpers import REPO
from helpers.experiments import TINY, sets
from study.cli import main

EXPERIMENT = str(REPO / "experiments" / "default.toml")
MAX_STEPS = 5


def test_help_lists_commands():
    res = subprocess.run(
        [str(REPO / ".venv" / "bin" / "study"), "--help"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    for cmd in ("render", "preview", "calibrate", "export"):
        assert cmd in res.stdout, res.stdout


# ---- errors --------------------------------------------------------------------------------

BAD = {
    "missing_experiment": (
        ["render", "{tmp}/nope.toml"],
        r"study render: error: .*nope\.toml does not exist",
    ),
    "unknown_key": (
        ["render", EXPERIMENT, "--set", "water.iorr=1.3"],
        r"unknown key.*'water\.iorr'",
    ),
    "set_syntax": (
        ["preview", EXPERIMENT, "--set", "resolution"],
        r"--set 'resolution': expected KEY=VALUE",
    ),
    "bad_value": (
        ["render", EXPERIMENT, "--set", "resolution=[24"],
        r"resolution: expected a list of 2",
    ),
    "unknown_solver": (
        ["calibrate", EXPERIMENT, "--solver", "newton"],
        r"study calibrate: error: unknown solver 'newton'.*levenberg_marquardt",
    ),
    "bad_constants": (
        ["export", "{tmp}/bad.json"],
        r"study export: error: .*bumptex_mult.*outside",
    ),
    "missing_constants": (
        ["export", "{tmp}/none.json"],
        r"study export: error: .*none\.json does not exist",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_exits_2_with_message(tmp_path, capsys, case):
    argv, pattern = BAD[case]
    (tmp_path / "bad.json").write_text('{"bumptex_mult": 1e6}')
    argv = [a.format(tmp=tmp_path) for a in argv] + ["--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err  # one message, no traceback
    import re

    assert re.search(pattern, err), err


def test_unknown_variant_is_an_argparse_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["render", EXPERIMENT, "--out", str(tmp_path / "out"), "--variant", "metal"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--variant" in err and "invalid choice: 'metal'" in err and "llvm_ad_rgb" in err
    assert not (tmp_path / "out").exists()


# ---- the commands on a tiny experiment --------------------------------------------------------


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """render, preview, calibrate (LM, at most 5 steps) and export of calibrate's constants.json,
    sharing one private reference cache."""
    root = tmp_path_factory.mktemp("cli")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(root / "cache"))
        rc = {
            "render": main(["render", EXPERIMENT, "--out", str(root / "render")] + sets(TINY)),
            "preview": main(["preview", EXPERIMENT, "--out", str(root / "preview")] + sets(TINY)),
            "calibrate": main(
                ["calibrate", EXPERIMENT, "--out", str(root / "calibrate")]
                + sets(TINY + [f"fit.max_steps={MAX_STEPS}"])
            ),
            "decorrelated": main(
                ["calibrate", EXPERIMENT, "--out", str(root / "decorrelated")]
                + sets(TINY + [f"fit.max_steps={MAX_STEPS}", 'fit.input_noise="decorrelate"'])
            ),
        }
        rc["export"] = main(
            ["export", str(root / "calibrate" / "constants.json"), "--out", str(root / "export")]
        )
    return root, rc


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def test_render_writes_reference_inputs_and_summary(runs):
    from shaders_port import ShaderInputs
    from study import read_exr

    root, rc = runs
    assert rc["render"] == 0
    out = root / "render"
    for f in ("reference.exr", "reference.png", "summary.json", "inputs/shader_inputs.npz"):
        assert (out / f).is_file(), f
    img, prov, _ = read_exr(out / "reference.exr")
    assert img.shape == (24, 24, 3) and np.all(np.isfinite(img)) and img.max() > 0
    assert prov["spp"] == 16
    summary = json.loads((out / "summary.json").read_text())
    assert summary["reference"]["spp"] == 16 and "inputs/shader_inputs.npz" in summary["outputs"]
    inputs = ShaderInputs.load(out / "inputs" / "shader_inputs.npz")
    assert (inputs.width, inputs.height) == (24, 24)
    assert inputs.normal_map.shape[:2] == (32, 32)
    # one reference in the private cache, reused by preview and calibrate
    cached = list((root / "cache").rglob("*.exr"))
    assert len(cached) == 1, cached


def test_preview_writes_finite_errors(runs):
    root, rc = runs
    assert rc["preview"] == 0
    p = json.loads((root / "preview" / "preview.json").read_text())
    assert _finite(p["error"]["rmse"]) and _finite(p["error"]["flip"])
    assert 0 < p["error"]["rmse"] and 0 < p["error"]["flip"] < 1
    assert p["water_pixels"] > 100 and p["reference"]["spp"] == 16
    assert (root / "preview" / "preview.png").is_file()


def test_calibrate_writes_constants_json(runs):
    from shaders_port import CONSTANT_SPECS, glsl_scalar
    from shaders_port.variants import get_variant

    root, rc = runs
    assert rc["calibrate"] == 0
    c = json.loads((root / "calibrate" / "constants.json").read_text())
    from study.export.result import CalibrationResult

    result = CalibrationResult.from_json(c)  # the typed record reads back what it wrote
    assert result.to_json() == c and not result.joint and result.extra == {}
    assert result.backend == "llvm_ad_rgb" and result.shader == "water_refraction"
    params = c["parameters"]
    from study import load_experiment
    from study.fit.model import expand_parameters

    requested = load_experiment(REPO / "experiments" / "default.toml")["fit.parameters"]
    # named as the GLSL names them, the study's name beside
    assert set(params) == {glsl_scalar(n) for n in expand_parameters(requested)}
    assert {p["name"] for p in params.values()} == set(expand_parameters(requested))
    # constants: what water_refraction reads; the rest of the block apart, labelled
    reads = {CONSTANT_SPECS[n][0] for n in get_variant("water_refraction").reads()}
    assert set(c["constants"]) == reads and "ATTENUATION_DISTANCE" in reads
    rest = c["constants_not_read"]
    assert set(rest["values"]) == {g for g, *_ in CONSTANT_SPECS.values()} - reads
    assert "read by no line of water_refraction" in rest["why"]
    assert c["constant_names"]["BumptexMult"] == "bumptex_mult"
    for name, p in params.items():
        assert {"default", "fitted", "frozen", "sensitivity"} <= set(p), (name, p)
        assert isinstance(p["frozen"], bool) and _finite(p["default"]) and _finite(p["sensitivity"])
        assert (p["fitted"] is None) == p["frozen"], (name, p)
        if not p["frozen"]:
            base = p["name"].split("[")[0]
            lo, hi = CONSTANT_SPECS[base][3]
            assert _finite(p["fitted"]) and lo <= p["fitted"] <= hi
    assert any(not p["frozen"] for p in params.values())
    for metric in ("rmse", "flip"):
        e = c["error"][metric]
        assert _finite(e["default"]) and _finite(e["fitted"]), e
    # fit and evaluation at the same resolution: LM accepts only steps that lower the loss
    assert c["error"]["rmse"]["fitted"] <= c["error"]["rmse"]["default"]
    assert c["solver"] == "levenberg_marquardt"
    # iterations: over all fit rounds (a constant frozen for its standard error starts another),
    # each capped at MAX_STEPS
    rounds = c["fit"]["iterations_per_round"]
    assert isinstance(c["iterations"], int) and c["iterations"] == sum(rounds) >= 1
    assert all(1 <= n <= MAX_STEPS for n in rounds) and len(rounds) == c["fit"]["rounds"]
    assert all(_finite(v) and v >= 0 for v in c["timings"].values())
    assert {"reference_s", "fit_s", "export_s"} <= set(c["timings"])
    assert (
        c["reference"]["spp"] == 16
        and _finite(c["reference"]["noise"])
        and c["reference"]["noise"] > 0
    )
    gl = c["gl_check"]
    assert gl["mean_abs"] <= 1e-3 and gl["p999"] <= 1e-2 and gl["unexplained"] == 0


def test_calibrate_with_decorrelated_texture_noise(runs):
    """fit.input_noise = "decorrelate": the same reference and inputs (one cache), the refinement's
    record in constants.json and the report."""
    root, rc = runs
    assert rc["decorrelated"] == 0
    c = json.loads((root / "decorrelated" / "constants.json").read_text())
    info = c["fit"]["input_noise"]
    assert (
        info["method"] == "decorrelated" and isinstance(info["accepted"], bool) and info["message"]
    )
    assert set(info["shift"]) <= set(c["parameters"])
    assert "decorrelated" in (root / "decorrelated" / "report.md").read_text()


def test_calibrate_writes_shaders_with_fitted_constants_and_report(runs):
    from shaders_port import read_constants

    root, _ = runs
    out = root / "calibrate"
    c = json.loads((out / "constants.json").read_text())
    for dialect in ("compat", "core"):
        names = sorted(p.name for p in (out / "shaders" / dialect).iterdir())
        # the calibrated shader and its vertex shader only (the constants are fitted for it)
        assert names == ["water.vert", f"{c['shader']}.frag"], names
        got = read_constants((out / "shaders" / dialect / "water_refraction.frag").read_text())
        for name, p in c["parameters"].items():
            if p["frozen"]:
                continue
            base, _, idx = p["name"].partition("[")  # the study's name beside the GLSL's
            v = getattr(got, base)
            v = v[int(idx[:-1])] if idx else v
            assert np.float32(v) == np.float32(p["fitted"]), name
    report = (out / "report.md").read_text()
    assert "levenberg_marquardt" in report
    # each constant by its GLSL name, the study's name beside it
    assert "| `ATTENUATION_DISTANCE` | attenuation_distance |" in report
    assert "| `waterColor[1]` | water_color[1] |" in report
    for fig in ("comparison.png", "diagnostics.png", "loss.png"):
        assert (out / fig).is_file() and fig in report


def test_export_of_calibrate_output_reproduces_its_shaders(runs):
    root, rc = runs
    assert rc["export"] == 0
    # the shader the constants were fitted for, not every shader of the space
    for dialect in ("compat", "core"):
        written = sorted(p.name for p in (root / "export" / "shaders" / dialect).iterdir())
        assert written == ["water.vert", "water_refraction.frag"], (dialect, written)
    for dialect in ("compat", "core"):
        for f in ("water.vert", "water_refraction.frag"):
            assert (root / "export" / "shaders" / dialect / f).read_bytes() == (
                root / "calibrate" / "shaders" / dialect / f
            ).read_bytes(), (dialect, f)


def test_calibrate_ships_the_textures_its_constants_assume(runs):
    """The Fresnel LUT and the normal map the constants were fitted with go with the shaders as
    float EXR, exactly (the GL check runs them from those files), with what an engine must know:
    the LUT's law in constants.json, at the top of every binding sheet and in the report; study
    export carries them on."""
    from shaders_port import ShaderInputs
    from study import read_exr

    root, rc = runs
    assert rc["calibrate"] == 0 and rc["export"] == 0
    inputs = ShaderInputs.load(root / "render" / "inputs" / "shader_inputs.npz")
    for out in (root / "calibrate", root / "export"):
        folder = out / "shaders" / "textures"
        lut, _, _ = read_exr(folder / "fresnel_lut.exr")
        normals, _, _ = read_exr(folder / "normal_map.exr")
        assert np.array_equal(lut[0, :, :2], inputs.fresnel_lut) and not lut[..., 2].any(), out
        assert np.array_equal(normals, inputs.normal_map), out
        assert (
            json.loads((folder / "textures.json").read_text())["fresnel_lut"]["law"] == "radiance"
        )
    res = json.loads((root / "calibrate" / "constants.json").read_text())
    lut = res["textures"]["fresnel_lut"]
    # experiments/default.toml bakes the n^2 law of radiance into the transmission channel
    assert lut["law"] == "radiance" and lut["transmission"] == "(1 - R) / n^2", lut
    sheets = sorted((root / "calibrate" / "shaders").glob("*/BINDINGS.md"))
    assert sheets
    for sheet in sheets:
        lines = sheet.read_text().splitlines()
        # the short sheet: what the shader expects before what to bind, the full one beside it
        assert lines.index("## What this shader expects") < lines.index("## What to bind"), sheet
        # short: what to bind, the constants, the values the fit used and the conventions
        assert len(lines) < 90 and (sheet.parent / "BINDINGS_FULL.md").is_file(), sheet
        # the sheet alone wires the shader: the light, the waves' clock, the top-down camera
        scene = json.loads((root / "calibrate" / "shaders" / "textures" / "textures.json")
                           .read_text())["scene"]  # fmt: skip
        text = sheet.read_text()
        assert "### Values the fit used" in text, sheet
        assert f"`lightcolor` = ({', '.join(f'{x:.6g}' for x in scene['lightcolor'])})" in text
        velocity = scene["wave_velocities"][1]
        assert "`wave2` = " in text and f"t * ({velocity[0]:.6g}, {velocity[1]:.6g})" in text
        assert "`uTextureMatrix0` (rows) = (" in text
        text = "\n".join(lines)
        assert "(1 - R) / n^2" in text and "fresnel_lut.exr" in text, sheet
    hlsl = (root / "calibrate" / "shaders" / "hlsl" / "BINDINGS.md").read_text()
    assert "GetGPUProjectionMatrix" in hlsl and "t -> 1 - t" in hlsl
    gles = (root / "calibrate" / "shaders" / "gles300" / "BINDINGS.md").read_text()
    assert "| `normalMap` | texture | sampler2D | by name |" in gles
    assert "OES_texture_float_linear" in gles and "EXT_color_buffer_float" in gles
    report = (root / "calibrate" / "report.md").read_text()
    assert "## What this shader expects" in report and "1.78x too bright" in report


def test_the_binding_sheets_are_written_again_from_the_export_alone(runs):
    """What the docs show of a real run: the sheets rebuilt from the export's reflections,
    textures.json and constants.json are the sheets the calibration and study export wrote."""
    from study.export.targets import resolve_targets, sheets_of_export

    root, _ = runs
    for out in (root / "calibrate", root / "export"):
        c = json.loads((root / "calibrate" / "constants.json").read_text())
        again = sheets_of_export(out / "shaders", c)
        assert len(again) == 2 * len(resolve_targets(None)), sorted(again)
        assert "hlsl/BINDINGS_FULL.md" in again
        for rel, text in again.items():
            assert (out / "shaders" / rel).read_text() == text, (out, rel)
        assert "**" in again["hlsl/BINDINGS.md"]  # the fitted constants marked


def test_calibration_result_refuses_what_is_not_one():
    from study.export.result import CalibrationResult

    with pytest.raises(ValueError, match="not a calibration result: missing.*'shader'"):
        CalibrationResult.from_json({"constants": {}})


def test_calibrate_writes_engine_targets_checked(runs):
    """The calibrated shader in every engine target; the HLSL ran on llvmpipe and matched."""
    root, _ = runs
    out = root / "calibrate"
    c = json.loads((out / "constants.json").read_text())
    t = c["engine_targets"]
    if not t:
        pytest.skip("the engine targets' tools (glslang, spirv-val, spirv-cross) are absent")
    from study.export.targets import resolve_targets

    made = sorted(resolve_targets(None))  # wgsl where Node.js and naga-wasm are installed
    assert sorted(t) == made and {"gles300", "hlsl", "msl", "spirv"} <= set(made)
    assert (out / "shaders" / "hlsl" / f"{c['shader']}.frag.hlsl").is_file()
    assert t["hlsl"]["llvmpipe"]["passed"], t["hlsl"]["llvmpipe"]
    report = (out / "report.md").read_text()
    assert "## Engine targets" in report and "no Metal compiler" in report
    assert sorted(p.name for p in (root / "export" / "shaders").iterdir()) == sorted(
        ["compat", "core", *made, "targets.json", "textures"]
    )


def test_the_report_says_why_the_reference_has_more_samples_than_asked():
    from study.report.calibration import _header_lines

    ref = {"spp": 140, "spp_asked": 128, "spp_per_pass": 35, "n_seeds": 4,
           "sampler": "multijitter", "noise": 0.02}  # fmt: skip
    summary = {"experiment": "e", "shader": "s", "reference": ref, "fit_resolution": [8, 8],
               "solver": "lm", "iterations": 1, "converged": True,
               "message": "converged"}  # fmt: skip
    head = _header_lines(summary)[2]
    assert head.startswith(
        "Reference: 140 spp (128 asked, rounded up to 4 passes of 35 for the multijitter "
        "sampler), measured noise 0.02"
    )
    same = _header_lines({**summary, "reference": {**ref, "spp": 128, "spp_asked": 128}})[2]
    assert same.startswith("Reference: 128 spp, measured")


def test_the_report_counts_steps_over_rounds_and_gives_each_final_status():
    """The header's step count is the total over the fit's rounds and says so (the last round's
    reason counts its own steps); the identifiability table's decision is the start's, and the
    status beside it the one the Constants table gives."""
    from study.report.calibration import fit_steps_line
    from study.report.identifiability import identifiability_table

    summary = {"iterations": 46, "converged": True, "message": "converged after 6 steps",
               "fit": {"iterations_per_round": [40, 6]}}  # fmt: skip
    line = fit_steps_line(summary)
    assert line.startswith("46 solver steps in 2 rounds (40 + 6: ")
    assert line.endswith("refitted); the last round converged after 6 steps.")
    one = fit_steps_line({**summary, "iterations": 6, "fit": {"iterations_per_round": [6]}})
    assert one == "6 solver steps, converged after 6 steps."  # "converged" said once
    capped = {**summary, "converged": False, "message": "maximum number of steps reached"}
    assert fit_steps_line(capped).endswith(
        ", NOT converged; the last round stopped: maximum number of steps reached."
    )
    ident = {
        "start": {"names": ["a"], "sensitivity": [0.1], "decision": ["identified (0.1)"]},
        "solution": {"names": [], "sensitivity": []},
    }
    rows = identifiability_table(ident, {"a": {"status": "bound"}})
    assert "decision at the start | status |" in rows[0]
    assert rows[2].endswith("| identified (0.1) | bound |"), rows[2]
