"""Every command takes a user's own GLSL shader as it takes the study's: ``--set fit.shader=...``
on any shipped experiment, for a still, joint or animated calibration, ``generalise``,
``failures``, ``stability`` and ``export`` (engine targets included). Each run is tiny (24x24);
the tests of one module share their references through one cache."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from study._io import repo_path

from helpers import REPO
from helpers.experiments import TINY, replaced, sets
from study.cli import main

EXPERIMENTS = REPO / "experiments"
MY_WATER = EXPERIMENTS / "shaders" / "my_water.frag"
MIRROR = Path(__file__).parent / "shaders" / "mirror_water.frag"
# the CLI runs' tiny scene, with the lighting texture's and walls' samples of a fit's
OVERRIDES = replaced(TINY, "reference.lighting_size=32", "reference.wall_spp=8", "fit.max_steps=8")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("shared_cache")


def _run(args: list, cache: Path, shader: Path, extra=()) -> None:
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("STUDY_CACHE", str(cache))
        assert main(args + sets([*OVERRIDES, f'fit.shader="{shader}"', *extra])) == 0


def _falls(error: dict) -> None:
    """The fitted RMSE (what the fit minimises) below the start's; both FLIPs reported."""
    assert error["rmse"]["fitted"] < error["rmse"]["default"], error
    assert all(0 < error["flip"][k] < 1 for k in ("default", "fitted")), error


def test_a_shipped_experiment_with_a_users_reflection_shader(cache, tmp_path):
    """``experiments/default.toml`` (whose ``fit.parameters`` names the study's constants) with
    a shader that binds the mirrored camera's image (``reflection_sampler``, a screen buffer the
    frame is built with on demand): fitted, exported to every engine target, checked on GL."""
    out = tmp_path / "c"
    _run(["calibrate", str(EXPERIMENTS / "default.toml"), "--out", str(out)], cache, MIRROR)
    res = json.loads((out / "constants.json").read_text())
    _falls(res["error"])
    assert res["shader"] == "mirror_water.frag" and set(res["parameters"]) == {
        "DISTORT",
        "REFLECTIVITY",
        "TINT[0]",
        "TINT[1]",
        "TINT[2]",
    }
    assert all(p["status"] in ("fitted", "bound", "frozen") for p in res["parameters"].values())
    assert (out / "shaders" / "core" / "mirror_water.frag").is_file()
    assert {"hlsl", "msl", "spirv", "gles300"} & set(res["engine_targets"])
    hlsl = res["engine_targets"].get("hlsl", {}).get("llvmpipe", {"ran": False})
    if hlsl["ran"]:  # the HLSL's uniform block and combined samplers, bound by the declaration
        assert hlsl["passed"], hlsl
    if res["gl_check"]["ran"]:
        assert res["gl_check"]["passed"], res["gl_check"]
    # study export takes the user's constants.json back, into the same files (the manifest's
    # translation seconds aside)
    again = tmp_path / "e"
    assert main(["export", str(out / "constants.json"), "--out", str(again)]) == 0
    for f in (out / "shaders").rglob("*"):
        twin = again / "shaders" / f.relative_to(out / "shaders")
        if f.name == "targets.json":
            ours, theirs = (json.loads(p.read_text())["targets"] for p in (f, twin))
            assert ours == theirs
        elif f.is_file():
            assert twin.read_bytes() == f.read_bytes(), f


def test_joint_calibration_and_generalise(cache, tmp_path):
    out = tmp_path / "g"
    scenes = [str(EXPERIMENTS / "default.toml"), str(EXPERIMENTS / "murky.toml")]
    _run(["generalise", *scenes, "--out", str(out)], cache, MY_WATER)
    summary = json.loads((out / "generalise.json").read_text())
    joint = summary["joint"]
    # recorded relative to the repository (study._io.repo_relative), read back as the file
    assert joint["shader"] == "my_water.frag" and repo_path(joint["shader_file"]) == MY_WATER
    assert not Path(joint["shader_file"]).is_absolute()
    for scene in joint["scenes"]:
        e = joint["error"][scene]
        assert e["fitted"]["rmse"] < e["default"]["rmse"], (scene, e)
    assert len(summary["leave_one_out"]) == 2
    assert set(summary["universality"]) <= set(joint["parameters"])
    assert (out / "shaders" / "core" / "my_water.frag").is_file()
    assert "my_water.frag" in (out / "generalise.md").read_text()
    # the joint calibration's own result, as `study calibrate A.toml B.toml` writes it
    written = json.loads((out / "constants.json").read_text())
    assert written["joint"] and written["scenes"] == joint["scenes"]
    assert {p["status"] for p in written["parameters"].values()} <= {"fitted", "bound", "frozen"}


def test_animated_calibration(cache, tmp_path):
    out = tmp_path / "a"
    _run(
        ["calibrate", str(EXPERIMENTS / "animated.toml"), "--out", str(out)],
        cache,
        MY_WATER,
        ["animation.frames=2"],
    )
    res = json.loads((out / "constants.json").read_text())
    _falls(res["error"])
    scores = res["animation"]["scores"]
    assert len(scores["all_frames"]["flip"]) == 2
    assert len(res["gl_check"]["frames"]) == 2
    assert (out / "shaders" / "core" / "my_water.frag").is_file()


def test_failures(cache, tmp_path):
    from study.sweep import read_table

    out = tmp_path / "f"
    _run(
        ["failures", str(EXPERIMENTS / "default.toml"), "--out", str(out), "--workers", "1"],
        cache,
        MY_WATER,
    )
    rows = read_table(out / "failures.parquet")
    classes = {r["class"] for r in rows}
    # the scene's classes and the shader's non-finite pixels; none of the seed's raycast steps
    assert classes == {"invalid_refraction", "depth_complexity", "grazing", "none"}, classes
    shares = [r["pixel_share"] for r in rows]
    assert all(0 <= s <= 1 for s in shares) and any(s > 0 for s in shares)
    assert rows[0]["shader"] == "my_water.frag"
    assert (out / "default" / "failures.png").is_file() and (out / "report.md").is_file()


def test_stability_multistart_and_loss(cache, tmp_path):
    from study.sweep import read_table

    out = tmp_path / "s"
    args = ["stability", str(EXPERIMENTS / "default.toml"), "--out", str(out), "--workers", "1"]
    args += ["--phases", "multistart", "loss", "--starts", "2"]
    args += ["--solvers", "levenberg_marquardt", "dogleg"]
    _run(args, cache, MY_WATER)
    runs = read_table(out / "multistart.parquet")
    assert len(runs) == 4 and all(r["status"] == "ok" for r in runs), runs
    # the starts drawn from the declared ranges
    shader_ranges = {"FOG_DENSITY": (0.01, 4.0), "BUMP": (0.05, 4.0)}
    for r in runs:
        for name, (lo, hi) in shader_ranges.items():
            assert lo <= r[f"job.start.{name}"] <= hi
        assert np.isfinite(r["loss"]) and r["loss"] <= r["loss_start"]
    losses = read_table(out / "loss.parquet")
    assert {r["job.loss"] for r in losses} == {"linear", "log"}
    assert all(r["status"] == "ok" and 0 < r["flip"] < 1 for r in losses), losses
    assert (out / "stability.md").is_file()
