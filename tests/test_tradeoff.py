"""The speed-versus-accuracy study: Pareto fronts and the recommendation, the schedule plan, the
analysis of a table, and a tiny `study tradeoff` end to end through the CLI (interrupted by
Ctrl-C and resumed on the way)."""

import json
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from shaders_port import Constants
from study.fit.model import get_value
from study.studies.tradeoff_analysis import constants_of
from study.studies.tradeoff_export import point_row

from helpers import REPO
from helpers.experiments import SMALL_OVERRIDES, sets
from study.studies.pareto import pareto_front, recommend


def _pts(pairs):
    return [{"name": n, "cost": c, "err": e} for n, c, e in pairs]


def test_pareto_front_hand_checked():
    pts = _pts(
        [
            ("a", 10, 0.30),
            ("b", 12, 0.25),
            ("c", 12, 0.27),
            ("d", 15, 0.25),
            ("e", 20, 0.20),
            ("f", 25, 0.22),
            ("g", 8, 0.40),
            ("h", 30, 0.19),
            ("nan", 5, float("nan")),
            ("none", 4, None),
        ]
    )
    front = [p["name"] for p in pareto_front(pts, "cost", "err")]
    # c is dominated by b (same cost, more error); d by b (costlier, same error); f by e
    assert front == ["g", "a", "b", "e", "h"]


def test_recommendation_hand_checked():
    pts = _pts([("a", 10, 0.30), ("b", 12, 0.2029), ("e", 20, 0.20), ("h", 30, 0.199)])
    assert recommend(pts, "cost", "err", 0.02)["name"] == "b"  # 0.2029 <= 1.02 * 0.199 = 0.20298
    assert recommend(pts, "cost", "err", 0.0)["name"] == "h"
    assert recommend(pts, "cost", "err", 1.0)["name"] == "a"
    assert recommend([], "cost", "err", 0.02) is None
    with pytest.raises(ValueError, match="tolerance"):
        recommend(pts, "cost", "err", -0.1)


@pytest.mark.parametrize("seed", range(40))
def test_recommended_point_is_on_the_front_and_within_tolerance(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    # coarse values make ties in cost and in error common
    pts = _pts(
        [(str(i), float(rng.integers(1, 8)), float(rng.integers(1, 6)) / 10) for i in range(n)]
    )
    tol = float(rng.choice([0.0, 0.02, 0.3, 2.0]))
    front = pareto_front(pts, "cost", "err")
    rec = recommend(pts, "cost", "err", tol)
    best = min(p["err"] for p in pts)
    assert rec["err"] <= best * (1 + tol)
    assert (rec["cost"], rec["err"]) in {(p["cost"], p["err"]) for p in front}
    for p in front:  # no point dominates a front point
        assert not any(
            q["cost"] <= p["cost"]
            and q["err"] <= p["err"]
            and (q["cost"], q["err"]) != (p["cost"], p["err"])
            for q in pts
        )
    for p in pts:  # every point off the front is dominated or ties a front point
        if p not in front:
            assert any(q["cost"] <= p["cost"] and q["err"] <= p["err"] for q in front)


def test_schedules_hold_the_seed_halvings_and_the_grid():
    from study import load_experiment
    from study.studies.tradeoff_jobs import schedules

    exp = load_experiment(REPO / "experiments" / "default.toml")
    s = schedules(exp, "water_refraction")
    scales = {x["scale"]: x["schedule"] for x in s if x["kind"] == "scale"}
    assert scales[1.0] == {"steps_grazing": 10.0, "steps_steep": 3.0, "loop_cap": 40}
    assert scales[0.5] == {"steps_grazing": 5.0, "steps_steep": 1.5, "loop_cap": 20}
    grid = [x for x in s if x["kind"] == "grid"]
    assert len(s) == len({json.dumps(x["schedule"], sort_keys=True) for x in s})  # distinct
    # the grid's points that equal a scaled schedule are kept once, as the scaled one
    assert len(grid) == 2 * 2 * 2 - 1
    conv = [x for x in s if x["kind"] == "converged"]
    assert conv[0]["schedule"]["loop_cap"] == 640
    r = schedules(exp, "water_reflection")
    assert {x["scale"]: x["schedule"] for x in r if x["kind"] == "scale"}[2.0][
        "refl_loop_cap"
    ] == 120


def _row(exp, variant, kind, scale, g, s, c, flip, fetches, ratio=1.0, crossed=0.0):
    return {
        "job.experiment": exp,
        "job.variant": variant,
        "job.kind": kind,
        "job.scale": scale,
        "job.schedule.steps_grazing": g,
        "job.schedule.steps_steep": s,
        "job.schedule.loop_cap": c,
        "status": "ok",
        "error": None,
        "flip": flip,
        "rmse": flip / 2,
        "fetches_mean": fetches,
        "fetches_p99": fetches + 2,
        "gl_ratio_1080p": ratio,
        "gl_ref_ms_1080p": 40.0,
        "port_ms_512": fetches / 4,
        "not_crossed": crossed,
        "n_fitted": 7,
        "bic": -1000.0 * (1 - flip),
    }


def test_analysis_of_a_table():
    from study.studies.tradeoff_analysis import analyse

    rows = [
        _row("A", "water_refraction", "scale", 0.5, 5, 1.5, 20, 0.170, 12.0, crossed=0.02),
        _row("A", "water_refraction", "scale", 1.0, 10, 3, 40, 0.166, 17.0),
        _row("A", "water_refraction", "scale", 2.0, 20, 6, 80, 0.165, 25.0),
        _row("A", "water_refraction", "converged", 16.0, 160, 48, 640, 0.1649, 150.0),
        _row("A", "water_refraction_noreflection", "scale", 1.0, 10, 3, 40, 0.30, 15.0),
        _row("A", "water_refraction_beer", "scale", 1.0, 10, 3, 40, 0.150, 17.0),
        _row("A", "water_refraction_beer", "scale", 2.0, 20, 6, 80, 0.140, 25.0),
        _row("B", "water_refraction", "scale", 0.5, 5, 1.5, 20, 0.120, 12.0),
        _row("B", "water_refraction", "scale", 1.0, 10, 3, 40, 0.110, 17.0),
        {
            **_row("B", "water_refraction", "scale", 2.0, 20, 6, 80, 0.0, 0.0),
            "status": "error",
            "error": "RuntimeError: boom",
            "flip": None,
        },
    ]
    summary, recs = analyse(rows, ["A", "B"], 0.02)
    a = summary["scenes"]["A"]
    assert (
        a["recommended"]["label"] == "water_refraction_beer (20, 6, 80)"
    )  # only it is within 1.02 * 0.140
    assert a["seed"]["flip"] == 0.166
    # at no more fetches than the seed's 17: beer at the seed's schedule, not its 25-fetch point
    assert a["best_within_seed_budget"]["label"] == "water_refraction_beer (10, 3, 40)"
    assert a["simplest_variant_within_tolerance"] == "water_refraction_beer"
    # parsimony per variant at the seed's schedule
    assert set(a["parsimony"]) == {
        "water_refraction",
        "water_refraction_noreflection",
        "water_refraction_beer",
    }
    assert a["parsimony"]["water_refraction_beer"] == {"n_fitted": 7, "bic": -850.0, "flip": 0.150}
    assert a["error_floor_by_variant"]["water_refraction"] == 0.1649
    assert a["smallest_crossing_loop_cap"]["water_refraction"] == 40  # cap 20 misses 2 %
    assert [r["label"] for r in a["front"]] == [
        "water_refraction (5, 1.5, 20)",
        "water_refraction_beer (10, 3, 40)",
        "water_refraction_beer (20, 6, 80)",
    ]
    assert (
        summary["n_failed"] == 1 and summary["failures"][0]["error_message"] == "RuntimeError: boom"
    )
    # the joint front holds only configurations measured on both scenes
    assert {r["label"] for r in summary["joint"]["front"]} <= {
        "water_refraction (5, 1.5, 20)",
        "water_refraction (10, 3, 40)",
    }
    assert summary["joint"]["recommended"]["flip"] == pytest.approx((0.166 + 0.110) / 2)
    assert all("label" in r for r in recs)


def test_tradeoff_cli_tiny_interrupted_resumed_and_exported(tmp_path, capsys):
    """A few points at 32x32 through the CLI, stopped by Ctrl-C once its first row is in: the
    table at the interrupt is valid and the re-run computes only the missing points. Then the
    finished sweep's table, chart, report and recommended shaders; a wider plan runs only its
    new point."""
    from study.cli import main
    from study.sweep import read_table

    small = SMALL_OVERRIDES + [
        'tradeoff.variants=["water_refraction"]',
        "tradeoff.steps_grazing=[5.0]",
        "tradeoff.steps_steep=[3.0]",
        "tradeoff.loop_cap=[20]",
        "tradeoff.scales=[0.5,1.0]",
        "tradeoff.converged_scale=4.0",
        "tradeoff.gl_repeats=3",
        "fit.max_steps=5",
    ]
    args = [
        "tradeoff",
        str(REPO / "experiments" / "default.toml"),
        "--out",
        str(tmp_path),
        "--workers",
        "1",
        "--search",
        "exhaustive",
    ] + sets(small)
    table = tmp_path / "tradeoff.parquet"
    done = _interrupt_after_the_first_row(args, table)
    assert not list(tmp_path.glob(".*.tmp"))
    capsys.readouterr()
    (tmp_path / "policy").mkdir()  # a level-of-detail policy of an earlier run
    (tmp_path / "policy" / "policy.frag").write_text("// stale\n")
    assert main(args) == 0  # the re-run: only the points the interrupted one did not finish
    m = re.search(
        rf"points: {len(done)} of (\d+) jobs already in \S+tradeoff.parquet; running (\d+)",
        capsys.readouterr().err,
    )
    assert m and int(m.group(2)) == int(m.group(1)) - len(done) > 0, m
    rows = read_table(table)
    assert all(r["seconds"] == done[r["key"]]["seconds"] for r in rows if r["key"] in done)
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows), [r.get("error") for r in rows]
    assert all(r["fetches_mean"] > 0 and 0 < r["flip"] < 1 for r in rows)
    assert all(
        r["gl_ms_512"] > 0 and r["gl_ratio_1080p"] > 0 for r in rows if r["job.kind"] != "converged"
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    rec = summary["scenes"]["default"]["recommended"]
    assert rec["label"] in {r["label"] for r in summary["scenes"]["default"]["front"]}
    assert summary["exports"]["default"]["gl_check"]["passed"]
    recommended = tmp_path / summary["exports"]["default"]["folder"]
    assert recommended == tmp_path / "recommended"
    assert (recommended / "shaders" / "core" / "water_refraction.frag").is_file()
    # tradeoff.lod=false (SMALL_OVERRIDES): no policy, and none of an earlier run left behind
    assert "lod" not in summary["scenes"]["default"] and not (tmp_path / "policy").exists()
    # the recommendation calibrated as study calibrate calibrates: every constant's status (the
    # refitted ones marked so in constants.json and the binding sheets), a report and a viewer
    saved = json.loads((recommended / "constants.json").read_text())
    assert saved["shader"] == rec["variant"] and saved["textures"]["fresnel_lut"]["law"]
    statuses = {n: p["status"] for n, p in saved["parameters"].items()}
    assert "fitted" in statuses.values() and statuses == summary["exports"]["default"]["parameters"]
    sheet = (recommended / "shaders" / "hlsl" / "BINDINGS.md").read_text()
    fitted = [n for n, st in statuses.items() if st == "fitted"]
    assert all(n.split("[")[0] in sheet for n in fitted), (fitted, sheet[:400])
    marked = [ln for ln in sheet.splitlines() if ln.startswith("|") and f"`{fitted[0][:5]}" in ln]
    assert marked and all("not fitted" not in ln for ln in marked), marked
    assert (recommended / "viewer" / "index.html").is_file() and (
        recommended / "report.md"
    ).is_file()
    row = point_row(rows, "default", rec["label"])
    point = Constants.from_dict(constants_of(row))  # the same constants as the point's row
    for n, p in saved["parameters"].items():
        if p["fitted"] is not None:
            assert p["fitted"] == pytest.approx(get_value(point, p["name"]), rel=1e-6), n
    # the recommendation exported again from its constants.json: the same shader and textures
    again = tmp_path / "again"
    assert main(["export", str(recommended / "constants.json"), "--out", str(again)]) == 0
    for rel in (f"core/{rec['variant']}.frag", "textures/fresnel_lut.exr"):
        assert (again / "shaders" / rel).read_bytes() == (
            recommended / "shaders" / rel
        ).read_bytes()
    assert (tmp_path / "pareto.png").stat().st_size > 10_000
    assert "Recommended" in (tmp_path / "report.md").read_text()
    # the reference beside the original shader (its own constants, fitted) and the recommendation
    assert summary["images"]["default"] == "images_default.png"
    assert (tmp_path / "images_default.png").stat().st_size > 10_000
    assert "images_default.png" in (tmp_path / "report.md").read_text()
    # its panels kept as data (the figure can be drawn again from them alone)
    from study.report.panels import read_panels

    images, errs, mask, title = read_panels(tmp_path / "images_default.png")
    assert list(images)[0] == "reference" and mask.any() and title == "default"
    assert errs == summary["panels"]["default"]
    before = {r["key"]: r["seconds"] for r in rows}
    # a wider plan (one more scale) resumes too: only the new point runs
    wider = [a.replace("tradeoff.scales=[0.5,1.0]", "tradeoff.scales=[0.5,1.0,2.0]") for a in args]
    assert main(wider) == 0
    after = {r["key"]: r["seconds"] for r in read_table(tmp_path / "tradeoff.parquet")}
    assert len(after) == 5 and {k: after[k] for k in before} == before


def test_motion_findings_hand_checked():
    """A cheap schedule whose temporal error exceeds its own constants' with the raymarch
    converged in every frame pair bands; within the FLIP tolerance it is the still
    recommendation, and motion moves the recommendation to the cheapest point that moves like
    the water."""
    from study.studies.tradeoff_motion import motion_findings, paired

    floor = [1.0e-3, 1.1e-3, 0.9e-3]

    def pt(label, kind, fetches, flip, trmse, pair_ms, converged=None):
        return {"label": label, "variant": "water_refraction", "kind": kind,
                "fetches_mean": fetches, "flip": flip, "flip_frames_mean": flip,
                "flip_frames_spread": 0.001, "trmse": trmse, "trmse_excess": None,
                "change_ratio": 1.0, "noise": None, "frames": 4, "pair_ms": pair_ms,
                "converged_pair_ms": converged,
                "converged_trmse": 0.0316 if converged else None}  # fmt: skip

    pts = [
        pt("cheap", "grid", 5.0, 0.100, 0.040, [m + 5e-4 for m in floor], floor),
        pt(
            "mid",
            "scale",
            10.0,
            0.100,
            0.0316,
            [m + 1e-6 * (-1) ** i for i, m in enumerate(floor)],
            floor,
        ),  # fmt: skip
        pt("floor", "converged", 40.0, 0.099, 0.0316, floor),
    ]
    f = motion_findings(pts, {"label": "cheap"}, tolerance=0.02, z=2.0)
    assert f["bands"] == ["cheap"] and f["recommended"]["label"] == "mid" and f["changes"]
    assert f["why"].startswith("motion changes the recommendation: cheap")
    d, se = paired(pts[0]["pair_ms"], floor)
    assert d == pytest.approx(5e-4) and se == pytest.approx(0.0, abs=1e-12)
    same = motion_findings(pts, {"label": "mid"}, tolerance=0.02, z=2.0)
    assert not same["changes"] and same["why"] == "motion does not change the recommendation"
    # a paired difference within its noise does not band; the converged point is not compared
    assert [(b["label"], b["bands"]) for b in f["banding"]] == [("cheap", True), ("mid", False)]
    # nor does one the pairs detect but below the tolerance (cheap: +22 % temporal RMSE)
    assert f["banding"][0]["rel"] == pytest.approx((1.5e-3 / 1.0e-3) ** 0.5 - 1)
    loose = motion_findings(pts, {"label": "cheap"}, tolerance=0.25, z=2.0)
    assert loose["bands"] == []


def test_a_user_shaders_job_hash_covers_includes_defines_and_the_vertex_shader(tmp_path):
    # what the tradeoff keys a user's point by: editing an include file, a define or the
    # vertex shader measures it again; an unchanged experiment reads the same key
    from study import load_experiment
    from study.studies.tradeoff_user import user_jobs

    shaders = REPO / "tests" / "shaders"
    (tmp_path / "inc").mkdir()
    common = tmp_path / "inc" / "water_common.glsl"
    common.write_text((shaders / "include" / "water_common.glsl").read_text())
    (tmp_path / "w.frag").write_text((shaders / "schlick_fog_120.frag").read_text())
    vert = tmp_path / "w.vert"
    vert.write_text((shaders / "urho_water.vert").read_text())
    exp_file = tmp_path / "e.toml"
    exp_file.write_text(
        '[fit]\nshader = "w.frag"\ninclude_paths = ["inc"]\ndefines = ["WATER_FOG=1"]\n'
    )

    def key(*overrides):
        (job,) = user_jobs([load_experiment(exp_file, list(overrides))], ["scene"])
        return job["shader_sha256"]

    base = key()
    assert key() == base
    assert key('fit.defines=["WATER_FOG=0"]') != base
    assert key('fit.defines=["WATER_FOG=1", "UNUSED"]') != base
    common.write_text(common.read_text().replace("F0 = 0.02", "F0 = 0.03"))
    edited = key()
    assert edited != base
    with_vertex = key(f'fit.vertex="{vert}"')
    assert with_vertex != edited
    assert key(f'fit.vertex="{vert}"', "fit.vertex_grid=[8, 8]") != with_vertex
    vert.write_text(vert.read_text() + "\n// an edit\n")
    assert key(f'fit.vertex="{vert}"') != with_vertex


def _interrupt_after_the_first_row(args: list, table) -> dict:
    """Run ``study`` with ``args`` in a process of its own and send it SIGINT once ``table`` holds
    a row: it exits 130 saying it was interrupted, and the table it leaves holds only finished
    points. Returns those rows by key. The sweep installs its own SIGINT handler, so this holds
    where a background shell (nohup, make under CI) starts the process with SIGINT ignored, as
    well as for a terminal's Ctrl-C."""
    from study.sweep import read_table

    proc = subprocess.Popen(
        [sys.executable, "-m", "study.cli", *args],
        cwd=table.parent,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and proc.poll() is None:
        if table.exists() and len(read_table(table)) >= 1:
            break
        time.sleep(0.2)
    assert proc.poll() is None, (
        "the sweep ended before it could be interrupted: " + proc.stdout.read()[-2000:]
    )
    proc.send_signal(signal.SIGINT)
    log = proc.communicate(timeout=300)[0]
    assert proc.returncode == 130, log[-3000:]
    assert "interrupted" in log and "Traceback" not in log, log[-3000:]
    done = {r["key"]: r for r in read_table(table)}
    assert len(done) >= 1 and all(r["status"] == "ok" for r in done.values())
    return done


def test_joint_findings_hold_the_best_within_the_originals_fetches_and_the_budget():
    """Over several scenes: the original shader at its schedule (FLIP and fetches averaged over
    the scenes), the lowest mean FLIP within its mean fetches, and a budget's pick."""
    from study.studies.tradeoff_analysis import analyse

    rows = []
    for scene, shift in (("A", 0.0), ("B", 0.02)):
        rows += [
            _row(scene, "water_refraction", "scale", 1.0, 10, 3, 40, 0.16 + shift, 17.0),
            _row(scene, "water_refraction_beer", "scale", 0.5, 5, 1.5, 20, 0.12 + shift, 16.0),
            _row(scene, "water_refraction_beer", "scale", 2.0, 20, 6, 80, 0.10 + shift, 25.0),
        ]
    rows.append(_row("A", "water_refraction_box", "scale", 0.5, 5, 1.5, 20, 0.05, 12.0))
    summary, _ = analyse(rows, ["A", "B"], 0.02)
    j = summary["joint"]
    assert j["seed"]["label"] == "water_refraction (10, 3, 40)"
    assert j["seed"]["flip"] == pytest.approx(0.17) and j["seed"]["fetches_mean"] == 17.0
    # the box shader is measured on one scene only: no joint point; the 25-fetch point is dearer
    assert j["best_within_seed_budget"]["label"] == "water_refraction_beer (5, 1.5, 20)"
    assert j["best_within_seed_budget"]["flip"] == pytest.approx(0.13)
    assert j["recommended"]["label"] == "water_refraction_beer (20, 6, 80)"
    budget, _ = analyse(rows, ["A", "B"], 0.02, {"fetches_mean": 16.5})
    assert budget["joint"]["recommended"]["label"] == "water_refraction_beer (5, 1.5, 20)"
