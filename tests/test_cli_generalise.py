"""``study calibrate A.toml B.toml`` (joint fit, exported like a single fit) and ``study
generalise`` (leave-one-scene-out table) through the CLI on two tiny experiments (24x24)."""

from __future__ import annotations

import json

import pytest

from helpers import REPO, experiments
from helpers.experiments import replaced, sets
from study.cli import main

TINY = replaced(
    experiments.TINY,
    "reference.spp=8",
    "fit.max_steps=8",
    'fit.parameters=["attenuation_distance","water_color"]',
)
EXPS = [str(REPO / "experiments" / "default.toml"), str(REPO / "experiments" / "murky.toml")]


@pytest.mark.slow
def test_generalise_writes_joint_constants_and_loso_table(tmp_path):
    out = tmp_path / "gen"
    assert main(["generalise", *EXPS, "--out", str(out), *sets(TINY)]) == 0
    joint = json.loads((out / "constants.json").read_text())
    assert joint["joint"] and joint["scenes"] == ["default", "murky"]
    assert set(joint["error"]) == {"default", "murky"}
    assert (out / "shaders" / "compat").is_dir() and (out / "report.md").is_file()
    gen = json.loads((out / "generalise.json").read_text())
    rows = gen["leave_one_out"]
    assert [r["scene"] for r in rows] == ["default", "murky"]
    for r in rows:
        for k in ("seed", "others", "own"):
            assert 0 <= r[k]["flip"] <= 1 and r[k]["rmse"] >= 0
    # every constant by its GLSL name, in the joint record and in the validation alike
    assert "ATTENUATION_DISTANCE" in rows[0]["own_constants"]
    assert set(gen["universality"]) <= set(joint["parameters"])
    md = (out / "generalise.md").read_text()
    assert "| left-out scene |" in md and "verdict" in md
    # the exported constants load back through `study export`
    assert main(["export", str(out / "constants.json"), "--out", str(tmp_path / "exp")]) == 0


@pytest.mark.slow
def test_joint_calibrate_through_cli(tmp_path):
    out = tmp_path / "joint"
    assert main(["calibrate", *EXPS, "--out", str(out), *sets(TINY)]) == 0
    joint = json.loads((out / "constants.json").read_text())
    assert joint["joint"] and len(joint["weights"]) == 2
    from study.export.result import CalibrationResult

    result = CalibrationResult.from_json(joint)
    assert result.joint and result.to_json() == joint and result.experiment is None
    assert joint["constants"]["ATTENUATION_DISTANCE"] > 0  # named as the GLSL names it
    assert "Joint calibration over 2 scenes" in (out / "report.md").read_text()
