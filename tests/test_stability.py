"""The stability study: Latin-hypercube starts, failure classes, the analysis of multi-start and
noise tables on hand-made rows (exact answers), the log residual's Jacobian against central
differences, and a tiny ``study stability`` through the CLI (slow)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from helpers import REPO, experiments
from helpers.experiments import replaced, sets
from study.studies.stability import analyse_loss, analyse_multistart, analyse_noise
from study.studies.stability_jobs import BOX, failure_class, latin_hypercube


def test_latin_hypercube_one_point_per_stratum():
    names = ["attenuation_distance", "water_color[1]"]
    pts = latin_hypercube(names, 8, seed=3)
    assert len(pts) == 8
    for n in names:
        lo, hi, log = BOX[n]
        v = np.array([p[n] for p in pts])
        assert np.all((v >= lo) & (v <= hi))
        q = (
            (np.log(v) - math.log(lo)) / (math.log(hi) - math.log(lo))
            if log
            else (v - lo) / (hi - lo)
        )
        assert sorted(np.floor(q * 8).astype(int).tolist()) == list(range(8))  # every stratum once
    with pytest.raises(ValueError, match="no start box"):
        latin_hypercube(["loop_cap"], 2)


def test_failure_classes():
    assert failure_class(True, "converged after 5 steps", 5, 100) == "converged"
    assert (
        failure_class(False, "maximum number of steps reached (max_steps=100)", 100, 100)
        == "step_cap"
    )
    assert (
        failure_class(False, "solver aborted (NonFiniteResidualError): ...", 3, 100) == "nonfinite"
    )
    assert failure_class(False, "something else", 3, 100) == "error"


def _row(scene, solver, loss, seconds, trace, failure="converged", lr=None, fitted=1.0):
    return {
        "status": "ok",
        "job.experiment": scene,
        "job.solver": solver,
        "job.lr": lr,
        "loss": loss,
        "fit_seconds": seconds,
        "failure": failure,
        "iterations": len(trace),
        "trace_loss": [t[0] for t in trace],
        "trace_seconds": [t[1] for t in trace],
        "fitted.a": fitted,
    }


def test_analyse_multistart_success_basin_and_time_to_target():
    rows = [
        _row("s", "lm", 1.0, 3.0, [(5.0, 1.0), (1.0005, 2.0), (1.0, 3.0)]),
        _row("s", "lm", 1.5, 2.0, [(5.0, 1.0), (1.5, 2.0)]),  # another basin
        _row("s", "nm", 4.0, 9.0, [(4.0, 9.0)], failure="step_cap"),
        _row("s", "adam", 1.0008, 8.0, [(2.0, 4.0), (1.0008, 8.0)], lr=0.1),
        _row("s", "adam", 3.0, 8.0, [(3.0, 8.0)], failure="step_cap", lr=0.01),
    ]
    ms = analyse_multistart(rows)
    lm = ms["solvers"]["lm"]
    assert ms["best_loss"]["s"] == 1.0
    assert lm["success_rate"] == 0.5 and lm["classes"] == {"success": 1, "another_basin": 1}
    assert lm["time_to_target_median"] == 2.0  # 1.0005 <= 1.001 at 2 s
    assert ms["solvers"]["nm"]["classes"] == {"step_cap": 1}
    assert ms["best_adam"] == "adam lr=0.1" and ms["reported"] == ["lm", "nm", "adam lr=0.1"]


def test_analyse_noise_bias_agreement_and_cheapest():
    rows = []
    for spp, vals in {64: [2.0, 2.2], 256: [2.9, 3.1], 1024: [3.0, 3.2]}.items():
        for s, v in enumerate(vals):
            rows.append(
                {
                    "status": "ok",
                    "job.which": "reference",
                    "job.spp": spp,
                    "job.seed": s,
                    "value.a": v,
                    "status.a": "fitted",
                }
            )
    nz = analyse_noise(rows)["reference"]
    st = nz["stats"]
    assert st[64]["a"]["bias"] == pytest.approx(-1.0) and st[256]["a"]["bias"] == pytest.approx(
        -0.1
    )
    assert st[256]["a"]["bias_se"] == pytest.approx(math.sqrt(2) * 0.1)  # std 0.1414/sqrt(2) each
    assert nz["agrees"] == {64: False, 256: True, 1024: True}
    assert nz["cheapest_agreeing"] == 256
    # a constant bound at 0 on every seed (no spread) agrees; one that moves without spread does not
    for r in rows:
        r["value.b"], r["status.b"] = 0.0, "bound"
    assert analyse_noise(rows)["reference"]["agrees"] == {64: False, 256: True, 1024: True}
    for r in rows:
        r["value.b"] = 0.5 if r["job.spp"] == 256 else 0.0
    assert analyse_noise(rows)["reference"]["agrees"] == {64: False, 256: False, 1024: True}


def test_plan_noise_varies_the_chosen_inputs_only():
    from study.studies.stability import plan_noise

    path = str(REPO / "experiments" / "default.toml")
    jobs = plan_noise(path, [], [64, 256], 1024, 2, 48, inputs=("reference",))
    assert len(jobs) == 4 and {j["which"] for j in jobs} == {"reference"}
    assert {(j["spp"], j["seed"]) for j in jobs} == {
        (64, 1000),
        (64, 1001),
        (256, 1000),
        (256, 1001),
    }
    assert all("reference.texture_spp=1024" in j["scene"]["overrides"] for j in jobs)
    both = plan_noise(path, [], [64], 1024, 1, 48)
    assert [j["which"] for j in both] == ["reference", "texture"]


def test_analyse_loss_picks_lower_mean_flip():
    rows = [
        {"status": "ok", "job.experiment": e, "job.loss": l, "flip": f, "rmse": 0.1}
        for e, l, f in [
            ("a", "linear", 0.2),
            ("a", "log", 0.18),
            ("b", "linear", 0.3),
            ("b", "log", 0.31),
        ]
    ]
    ls = analyse_loss(rows)
    assert ls["wins"] == {"linear": 1, "log": 1} and ls["winner"] == "log"


def test_log_residual_jacobian_matches_central_differences():
    from helpers.synthetic import synthetic_inputs
    from shaders_port import Constants
    from shaders_port.ports import water_refraction
    from study.fit.losses import transformed
    from study.fit.model import ShaderModel, with_values

    inputs = synthetic_inputs(width=32, height=24)
    target = water_refraction.render(inputs, Constants(attenuation_distance=5.0)).numpy()["color"]
    model = transformed(ShaderModel("water_refraction", inputs, target), "log")
    names = ["attenuation_distance", "water_color[1]"]
    c = Constants(attenuation_distance=6.0, water_color=(0.05, 0.27, 0.3, 1.0))
    r, J = model.residual_and_jacobian(c, names)
    assert np.allclose(r, model.residual(c), atol=1e-5)
    for j, (n, h) in enumerate(zip(names, [1e-2, 1e-3])):
        v = {"attenuation_distance": 6.0, "water_color[1]": 0.27}[n]
        fd = (
            model.residual(with_values(c, {n: v + h})) - model.residual(with_values(c, {n: v - h}))
        ) / (2 * h)
        assert np.linalg.norm(J[:, j] - fd) < 2e-2 * np.linalg.norm(fd), n
    with pytest.raises(NotImplementedError, match="Adam"):
        model.loss_ad(c)
    with pytest.raises(ValueError, match="unknown fit.loss 'l1'"):
        transformed(model.base, "l1")


def test_log_loss_calibration_recovers_a_synthetic_target():
    """``calibrate_experiment`` on the log-residual model (``fit.loss = "log"``) runs end to end
    (it reads the model's variant and reference standard error through the wrapper) and
    recovers the constants a synthetic target was rendered with."""
    from helpers.synthetic import synthetic_inputs
    from shaders_port import Constants
    from shaders_port.ports import water_refraction
    from study import load_experiment
    from study.fit.calibrate import calibrate_experiment
    from study.fit.losses import transformed
    from study.fit.model import ShaderModel

    inputs = synthetic_inputs(width=32, height=24)
    truth = Constants(attenuation_distance=5.0, water_color=(0.05, 0.2, 0.3, 1.0))
    target = water_refraction.render(inputs, truth).numpy()["color"]
    stderr = np.full_like(target, 1e-3)
    model = transformed(
        ShaderModel("water_refraction", inputs, target, reference_stderr=stderr), "log"
    )
    assert model.variant is model.base.variant and model.reference_stderr.shape == target.shape
    exp = load_experiment(
        REPO / "experiments" / "default.toml",
        ['fit.parameters=["attenuation_distance", "water_color"]'],
    )
    cal = calibrate_experiment(model, exp)
    p = cal.parameters
    assert p["attenuation_distance"]["fitted"] == pytest.approx(5.0, rel=1e-2)
    assert p["water_color[1]"]["fitted"] == pytest.approx(0.2, rel=1e-2)
    assert p["water_color[2]"]["fitted"] == pytest.approx(0.3, rel=1e-2)


TINY = replaced(experiments.TINY, "reference.spp=8")


@pytest.mark.slow
def test_stability_cli_tiny(tmp_path):
    from study.cli import main

    out = tmp_path / "stab"
    argv = [
        "stability",
        str(REPO / "experiments" / "default.toml"),
        "--out",
        str(out),
        *sets(TINY),
        "--starts",
        "2",
        "--solvers",
        "levenberg_marquardt",
        "nelder_mead",
        "--max-steps",
        "8",
        "--noise-spp",
        "4",
        "8",
        "--noise-fixed-spp",
        "4",
        "--noise-seeds",
        "2",
        "--noise-resolution",
        "24",
        "--workers",
        "1",
    ]
    assert main(argv) == 0
    s = json.loads((out / "summary.json").read_text())
    assert set(s["multistart"]["solvers"]) == {"levenberg_marquardt", "nelder_mead"}
    assert s["multistart"]["solvers"]["levenberg_marquardt"]["runs"] == 2
    assert set(s["loss"]["per_scene"]["default"]) == {"linear", "log"}
    assert s["noise"]["reference"]["levels"] == [4, 8]
    for f in ("solvers.png", "spread.png", "noise.png", "stability.md", "multistart.parquet"):
        assert (out / f).is_file(), f
    # a re-run resumes: every job is already in the tables
    assert main(argv) == 0


def test_adam_is_left_out_of_a_users_spirv_shader_with_a_note():
    """A user's shader runs through SPIR-V (forward-mode derivatives only): the multi-start plan
    gives it no Adam job, and says why; the study's shader keeps every solver."""
    from study import load_experiment
    from study.studies.stability import SOLVERS, plan_multistart, solver_left_out

    user = load_experiment(REPO / "experiments" / "my_water.toml")
    study = load_experiment(REPO / "experiments" / "default.toml")
    assert "forward-mode derivatives only" in solver_left_out(user, "adam")
    assert all(solver_left_out(e, s) is None for e in (user, study) for s in SOLVERS[:-1])
    assert solver_left_out(study, "adam") is None
    specs = [{"name": "user"}, {"name": "study"}]
    jobs = plan_multistart(specs, [user, study], 2, SOLVERS, (0.05,), 5, 10)
    per = {(j["scene"]["name"], j["solver"]) for j in jobs}
    assert ("user", "adam") not in per and ("study", "adam") in per
    assert {s for n, s in per if n == "user"} == set(SOLVERS) - {"adam"}
