"""The calibration pipeline is one: a sweep point and ``study calibrate`` fit the same constants,
and the result, the scorer and the export with its GL check are each written in one place."""

from __future__ import annotations

import ast
import json

import pytest

from helpers import REPO
from shaders_port import Constants
from study.calibration.shader import Shader
from study.cli import main
from study.calibration.fitting import frame_models
from study.calibration.frames import load_frames
from study.fit.model import get_value
from study.studies.tradeoff_jobs import point_job
from study.sweep import scene_spec

RECOMMENDED = "water_refraction_beer_disc_walls"  # the default tradeoff's recommendation
SCHEDULE = {"steps_grazing": 5.0, "steps_steep": 1.5, "loop_cap": 20}
SMALL = [
    "resolution=[64,64]",
    "fit.resolution=[32,32]",
    "reference.spp=16",
    "reference.water_mesh=96",
    "reference.texture_size=64",
    "reference.texture_spp=8",
    "waves.normal_map_size=64",
    "fit.max_steps=8",
    "tradeoff.gl_repeats=3",
]


def test_a_tradeoff_point_and_study_calibrate_fit_the_same_constants(tmp_path, monkeypatch):
    """The recommended configuration of the default tradeoff, fitted as a tradeoff point
    (``point_job``) and by ``study calibrate`` with that shader and schedule, from the same
    start: the same constants within 1e-6 relative (the same fit, options and scorer)."""
    monkeypatch.setenv("STUDY_CACHE", str(tmp_path / "cache"))
    experiment = REPO / "experiments" / "default.toml"
    sets = (
        SMALL
        + [f'fit.shader="{RECOMMENDED}"']
        + [f"constants.{k}={v}" for k, v in SCHEDULE.items()]
    )
    args = ["calibrate", str(experiment), "--out", str(tmp_path / "c")]
    assert main(args + [a for s in sets for a in ("--set", s)]) == 0
    saved = json.loads((tmp_path / "c" / "constants.json").read_text())

    frames = load_frames(experiment, sets)  # the calibration's, from the cache
    exp, shader = frames.first.exp, Shader.of(frames.first.exp)
    assert saved["shader"] == shader.label == RECOMMENDED
    (model,) = frame_models(frames, shader, frames.variant)
    start = model.start_constants(exp)  # what study calibrate starts from
    job = {"scene": scene_spec(experiment, sets), "experiment": exp.name, "kind": "point",
           "variant": RECOMMENDED, "scale": None, "start": start.to_dict(),
           "schedule": SCHEDULE}  # fmt: skip
    point = point_job(job)
    fitted = Constants.from_dict(point["fitted"])
    checked = 0
    for name, p in saved["parameters"].items():
        if p["status"] in ("fitted", "bound"):
            assert get_value(fitted, p["name"]) == pytest.approx(p["fitted"], rel=1e-6, abs=1e-9), (
                name
            )
            checked += 1
    assert checked >= 3, saved["parameters"]
    assert point["status_of"] == {p["name"]: p["status"] for p in saved["parameters"].values()}
    assert point["flip"] == pytest.approx(saved["error"]["flip"]["fitted"], rel=1e-6)


def _calls(name: str, methods: bool = True) -> set[str]:
    """The files of ``study/`` that call ``name`` (a function or class; ``methods`` False: as a
    bare name only, not ``x.name(...)``)."""
    found = set()
    for path in sorted((REPO / "study").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                fn = node.func
                called = fn.id if isinstance(fn, ast.Name) else None
                if methods and isinstance(fn, ast.Attribute):
                    called = fn.attr
                if called == name:
                    found.add(str(path.relative_to(REPO)))
    return found


def test_the_result_the_score_and_the_export_are_each_written_once():
    """``CalibrationResult`` is built by the pipeline's one builder (its own reader aside), the
    error of a render is taken by the one scorer (the screen's reduced-resolution FLIP map and
    the temporal error aside), and the GL check of an export runs from the one export."""
    assert _calls("CalibrationResult") == {"study/calibration/result.py"}
    assert _calls("errors") == {"study/calibration/scoring.py"}
    assert _calls("write_export") == {"study/calibration/run.py"}
    checks = ("gl_check", "gl_check_user", "target_checks", "hlsl_check_user", "gles_check_user")
    found = set().union(*(_calls(c, methods=False) for c in checks))
    assert found == {"study/calibration/shader.py"}
    assert _calls("export_shaders") | _calls("export_user_shader") <= {
        "study/calibration/shader.py",
        "study/commands/export.py",  # study export: constants written again, no fit
        "study/export/shaders.py",
        "study/export/viewer/user.py",  # the viewer's start constants, into a temporary folder
    }
