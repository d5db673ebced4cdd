"""The adaptive search: the paired noise estimate, dominance with a margin, the walk's rounds,
the marginal table, and a tiny adaptive `study tradeoff` end to end."""

import json
import math

import numpy as np
import pytest

from helpers import REPO
from shaders_port import space as _space
from study.studies import search


def test_paired_se_is_the_standard_error_of_the_block_differences():
    rng = np.random.default_rng(0)
    a = rng.normal(0.3, 0.05, 400)
    b = a - 0.01 + rng.normal(0, 0.02, 400)  # correlated with a: the pairing removes the shared
    se = search.paired_se(a.tolist(), b.tolist())
    assert se == pytest.approx(np.std(a - b, ddof=1) / 20, rel=1e-9)
    assert se < np.std(a, ddof=1) / 20  # far below an unpaired estimate
    a[:397] = np.nan  # fewer than 4 common blocks: no estimate
    assert search.paired_se(a.tolist(), b.tolist()) == math.inf


def _pt(name, fetches, flip, blocks):
    return {"variant": name, "fetches_mean": fetches, "flip": flip, "flip_blocks": blocks}


def test_dominance_needs_a_lower_cost_and_a_gap_beyond_the_noise():
    rng = np.random.default_rng(1)
    base = rng.normal(0.3, 0.05, 256)
    noisy = base + rng.normal(0, 0.03, 256)
    far = _pt("far", 10, float(base.mean()) - 0.05, (base - 0.05).tolist())
    near = _pt("near", 10, float(noisy.mean()), noisy.tolist())
    x = _pt("x", 12, float(base.mean()), base.tolist())
    assert search.clearly_dominates(far, x, 2.0)  # cheaper and 0.05 better, noise-free
    gap = x["flip"] - near["flip"]
    se = search.paired_se(x["flip_blocks"], near["flip_blocks"])
    assert search.clearly_dominates(near, x, 2.0) == (gap > 2 * se)
    dear = _pt("dear", 20, far["flip"], far["flip_blocks"])
    assert not search.clearly_dominates(dear, x, 2.0)  # better but costlier
    # a tie costlier than "far" is kept (no gap beyond the noise); "x" is dropped
    assert [p["variant"] for p in search.survivors([x, far, dear], 2.0)] == ["far", "dear"]


def test_the_first_round_holds_the_original_every_source_and_the_neighbours():
    names = [_space.name_of(c) for c in search.first_round(None)]
    assert names[0] == "water_refraction"
    for n in ("water_reflection", "water_baseline", "water_baseline_flat",
              "water_baseline_noplanar", "water_refraction_noreflection",
              "water_refraction_beer", "water_refraction_walls"):  # fmt: skip
        assert n in names
    assert len(names) == len(set(names))
    pinned = search.first_round({"refraction": "raycast", "textures": "float"})
    assert all(c["refraction"] == "raycast" and c["textures"] == "float" for c in pinned)
    front = [_space.choices_of("water_refraction_beer")]
    seen = search.first_round(None)
    nxt = search.next_round(front, seen, None)
    assert _space.choices_of("water_refraction_beer_walls") in nxt
    assert not any(c in seen for c in nxt)


def test_the_walk_expands_the_best_shaders_first():
    # the max_shaders cut keeps the neighbours of the lowest-FLIP survivors
    worse = {"choices": _space.choices_of("water_baseline_flat"), "flip": 0.30}
    better = {"choices": _space.choices_of("water_refraction_beer"), "flip": 0.15}
    front = search.best_first([worse, better])
    assert front == [better, worse]
    nxt = search.next_round([r["choices"] for r in front], search.first_round(None), None)
    first = _space.name_of(nxt[0])
    assert "beer" in first, first  # a neighbour of the better one


def test_marginals_name_the_axis_changed():
    blocks = [0.2] * 16
    base = {"choices": _space.choices_of("water_refraction_beer"), "flip": 0.2,
            "fetches_mean": 17.0, "flip_blocks": blocks}  # fmt: skip
    pts = []
    cases = (
        ("water_refraction_beer_walls", 0.18),
        ("water_refraction", 0.21),
        ("water_baseline", 0.25),
        ("water_refraction_noreflection_beer", 0.3),
    )
    for name, flip in cases:
        pts.append({"variant": name, "choices": _space.choices_of(name), "flip": flip,
                    "fetches_mean": 15.0, "flip_blocks": [flip] * 16})  # fmt: skip
    rows = {r["variant"]: r for r in search.marginals(base, pts)}
    assert rows["water_refraction_beer_walls"]["axis"] == "walls"
    assert rows["water_refraction_beer_walls"]["d_flip"] == pytest.approx(-0.02)
    assert rows["water_refraction"]["axis"] == "attenuation"
    assert rows["water_baseline"]["axis"] == "refraction"
    assert rows["water_refraction_noreflection_beer"]["axis"] == "reflection"
    assert rows["water_refraction"]["d_fetches"] == pytest.approx(-2.0)


def test_adaptive_tradeoff_tiny(tmp_path):
    """Two shaders at 32x32 through the CLI: screened, one schedule each screened, the
    survivors measured in full, the marginal table and the budget in the report."""
    from study.cli import main
    from study.sweep import read_table

    from helpers.experiments import SMALL_OVERRIDES

    small = SMALL_OVERRIDES + [
        'tradeoff.variants=["water_refraction", "water_baseline_flat"]',
        "tradeoff.steps_grazing=[5.0]",
        "tradeoff.steps_steep=[3.0]",
        "tradeoff.loop_cap=[20]",
        "tradeoff.scales=[1.0]",
        "tradeoff.gl_repeats=3",
        "fit.max_steps=5",
        "tradeoff.lod=true",
    ]
    args = ["tradeoff", str(REPO / "experiments" / "default.toml"), "--out", str(tmp_path)]
    args += ["--workers", "1", "--budget", "fetches=12"]
    assert main(args + [a for s in small for a in ("--set", s)]) == 0
    screen = read_table(tmp_path / "screen.parquet")
    assert {r["job.variant"] for r in screen} >= {"water_refraction", "water_baseline_flat"}
    # screened at fit.resolution (32x32) / tradeoff.screen_factor (1): 8 x 8 blocks of 4 x 4
    assert all(r["status"] == "ok" and len(r["flip_blocks"]) == 64 for r in screen)
    # and their per-pixel FLIP and fetch maps, float16 at the screen's resolution
    assert all(len(r["flip_map"]) == len(r["fetch_map"]) == 2 * 32 * 32 for r in screen)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["search"]["mode"] == "adaptive" and summary["budget"] == {"fetches_mean": 12.0}
    rec = summary["scenes"]["default"]["recommended"]
    assert rec["fetches_mean"] <= 12.0  # within the budget: the loopless baseline
    full = read_table(tmp_path / "tradeoff.parquet")
    assert any(r["job.variant"] == "water_refraction" for r in full)  # the original, always
    report = (tmp_path / "report.md").read_text()
    assert "Search: adaptive" in report and "**Budget**" in report
    # the level-of-detail policies from the full points' maps: the single points' front
    # among them
    mapped = [r for r in full if r.get("flip_map") is not None]
    assert mapped and all(len(r["flip_map"]) == 2 * 32 * 32 for r in mapped)
    lod = summary["scenes"]["default"]["lod"]
    assert lod["resolution"] == [32, 32] and lod["points"] == len(mapped)
    assert lod["front"][-1]["flip"] <= lod["best"]["flip"] + 1e-12
    # here the raycast near and the loopless baseline far: drawn as one shader, whose two files
    # need different inputs (the baseline's screen buffers), seams measured, GL-checked
    drawn = lod["export"]
    assert lod["policy"]["bands"] == ["water_refraction (5, 3, 20)", "water_baseline_flat"]
    best = lod["against_best"]
    assert best["fetch_ratio"] == pytest.approx(lod["policy"]["fetches"] / lod["best"]["fetches"])
    assert drawn["gl_check"]["passed"], drawn["gl_check"]
    assert drawn["seams"] and drawn["seam_ratio"] is not None
    folder = tmp_path / drawn["folder"]
    assert folder.joinpath("policy.frag").read_text().count("_main();") == 2
    # and for an engine that switches shaders itself: each band's own file, checked alone
    assert all(b["gl_check"]["passed"] for b in drawn["bands"]), drawn["bands"]
    assert "void main" in folder.joinpath("bands", "b1.frag").read_text()
    assert "| 1 |" in folder.joinpath("BANDS.md").read_text()
    assert "## Level of detail" in report and (tmp_path / "lod.png").stat().st_size > 5_000
    assert summary["exports"]["default"]["gl_check"]["passed"]


def test_the_cut_keeps_the_points_closest_to_the_front():
    flat = [0.0] * 64  # noise-free blocks: the margin is the FLIP gap over a tiny floor

    def pt(name, fetches, flip):
        return _pt(name, fetches, flip, [flip + v for v in flat])

    a, b, c, d = pt("a", 5, 0.30), pt("b", 10, 0.20), pt("c", 10, 0.21), pt("d", 20, 0.25)
    assert search.margin(a, [a, b, c, d]) == math.inf  # nothing is cheaper
    assert search.margin(b, [a, b, c, d]) > 0 > search.margin(d, [a, b, c, d])
    kept = search.closest_to_front([a, b, c, d], 2)
    assert [p["variant"] for p in kept] == ["a", "b"]  # in their order, the front's two
    assert search.closest_to_front([a, b], 5) == [a, b]


def test_the_schedule_cut_leaves_no_place_to_a_shader_without_a_raymarch():
    flat = [0.0] * 64

    def pt(name, fetches, flip, kind):
        return {**_pt(name, fetches, flip, [flip + v for v in flat]), "kind": kind}

    # the cheap screen-space shaders are on the front with nothing cheaper (infinite margin),
    # the raymarch shaders are what rung 2 has schedules for
    cheap = [pt(f"baseline{k}", 3 + k, 0.30 - 0.01 * k, "fixed") for k in range(3)]
    box = pt("box", 17.128, 0.1022, "scale")
    disc = pt("disc", 17.131, 0.0948, "scale")  # a hair dearer, much better
    worse = pt("worse", 22.0, 0.2, "scale")  # dominated
    points = cheap + [box, disc, worse]
    # over every point the cheapest screen-space shader (nothing cheaper) takes one of the two
    assert "baseline0" in [p["variant"] for p in search.closest_to_front(points, 2)]
    assert [p["variant"] for p in search.to_schedule(points, 2.0, 2)] == ["box", "disc"]


def test_the_descent_goes_on_from_the_cheapest_shader_near_the_lowest():
    """After the walk's cut, the descent goes on from the configuration the recommendation's
    rule picks among the screened ones (the cheapest within the tolerance of the lowest FLIP):
    its one-axis neighbours not yet screened (a best shader more choices from the original than
    the cut reaches is found this way, where it costs least)."""
    low = {"choices": _space.choices_of("water_reflection_beer_disc_walls"), "flip": 0.100,
           "fetches_mean": 24.0}  # fmt: skip
    near = {"choices": _space.choices_of("water_refraction_beer_disc_walls"), "flip": 0.101,
            "fetches_mean": 17.0}  # fmt: skip
    far = {"choices": _space.choices_of("water_refraction"), "flip": 0.16, "fetches_mean": 17.0}
    assert search.descent_origin([low, near, far], 0.02) is near
    assert search.descent_origin([low, near, far], 0.001) is low
    seen = [low["choices"], near["choices"], far["choices"]]
    todo = search.descent_round([low, near, far], seen, None, 0.02)
    names = {_space.name_of(c) for c in todo}
    assert "water_refraction_beer_disc_walls_parallax" in names
    assert not names & {"water_reflection_beer_disc_walls", "water_refraction"}
    fixed = search.descent_round([low, near, far], seen, {"parallax": "off"}, 0.02)
    assert fixed and all(c["parallax"] == "off" for c in fixed)


def test_joint_screen_averages_the_experiments_and_pools_their_blocks():
    def rec(v, sched, flip, fetches, blocks):
        return {"variant": v, "choices": {}, "kind": "scale", "scale": 1.0,
                "schedule": sched, "flip": flip, "rmse": flip / 2, "fetches_mean": fetches,
                "flip_blocks": blocks}  # fmt: skip

    s1, s2 = {"steps_grazing": 10.0}, {"steps_grazing": 5.0}
    view0 = [rec("a", s1, 0.10, 20.0, [0.1, 0.1]), rec("a", s2, 0.12, 16.0, [0.12, 0.12])]
    view1 = [rec("a", s1, 0.20, 22.0, [0.2, float("nan")]), rec("b", s1, 0.3, 9.0, [0.3, 0.3])]
    joint = search.joint_screen([view0, view1])
    # only (a, s1) is on both views: FLIP and fetches averaged, blocks in the views' order
    assert [(r["variant"], r["schedule"]) for r in joint] == [("a", s1)]
    (j,) = joint
    assert j["flip"] == pytest.approx(0.15) and j["fetches_mean"] == pytest.approx(21.0)
    assert j["rmse"] == pytest.approx(0.075)
    assert j["flip_blocks"][:3] == [0.1, 0.1, 0.2] and math.isnan(j["flip_blocks"][3])
    assert j["per_experiment"] == [view0[0], view1[0]]


class _Planted(search.Search):
    """A search whose screen is a known truth instead of fits: FLIP per (variant, view), worse
    below 5 steps at grazing angles; fetches from the variant and its schedule."""

    FLIP = {
        "water_refraction_beer_disc_walls": (0.080, 0.140),  # best on view 0 alone
        "water_refraction_box_beer_secant_slopes": (0.140, 0.085),  # best on view 1 alone
        "water_refraction_box_beer_parallax": (0.090, 0.090),  # best on both
    }

    def _run(self, jobs, label):
        self.labels.append(label)
        recs = []
        for j in jobs:
            view = [e.name for e in self.exps].index(j["experiment"])
            g = j["schedule"]["steps_grazing"]
            flip = self.FLIP[j["variant"]][view] + (0.01 if g < 5 else 0.0)
            fetches = 8.0 + 0.8 * g + len(j["variant"]) / 10
            recs.append({
                "experiment": j["experiment"], "variant": j["variant"],
                "choices": _space.choices_of(j["variant"]), "kind": j["kind"],
                "scale": j["scale"], "schedule": j["schedule"], "status": "ok",
                "flip": flip, "rmse": flip, "fetches_mean": fetches,
                "flip_blocks": [flip + 1e-4 * (k % 3) for k in range(64)], "fitted": {},
            })  # fmt: skip
        self.screen += recs
        return recs


def test_the_joint_rung_measures_the_shader_good_on_every_view_at_its_schedules(tmp_path):
    """Each view's own rungs screened the shader best on both views at its original schedule on
    one view only; the joint rung screens it on the other, then its schedules on both, and
    hands the joint front's points to the full rung: the cheapest schedule at its FLIP first."""
    from study.config.experiment import load_experiments
    from study.scene.views import view_experiments

    (exp,) = load_experiments([REPO / "experiments" / "views.toml"], [])
    exps = view_experiments(exp)[:2]
    searcher = _Planted(exps, [None, None], None, tmp_path, print)
    searcher.labels = []
    both = "water_refraction_box_beer_parallax"
    original = search.original_schedule(both)
    seeds = [(0, "water_refraction_beer_disc_walls"), (0, both),
             (1, "water_refraction_box_beer_secant_slopes")]  # fmt: skip
    finalists = []
    for i, v in seeds:
        finalists += searcher._run([searcher._job(i, v, search.original_schedule(v), {})], "")
    joint = searcher.joint(finalists)
    on = {(r["experiment"], r["variant"], search._key(r["schedule"])) for r in searcher.screen}
    assert ("views-view1", both, search._key(original["schedule"])) in on  # filled in
    for i, e in enumerate(exps):
        for s in search.schedules(e, both):
            if s["kind"] != "converged":
                assert (e.name, both, search._key(s["schedule"])) in on, s
    assert searcher.joint_screened == len(searcher.screen) - len(seeds)
    # the joint front's best: the shader good on both views at its cheapest schedule of 5 steps
    # at grazing angles (FLIP 0.090 on both); the shaders good on one view only (mean 0.110,
    # 0.1125) stay only where they cost less
    best = min(joint, key=lambda r: (round(r["flip"], 9), r["fetches_mean"]))
    assert best["variant"] == both and best["schedule"]["steps_grazing"] == 5.0
    assert best["flip"] == pytest.approx(0.09)
    assert all(r["fetches_mean"] < best["fetches_mean"] for r in joint if r["variant"] != both)
    # one experiment: no joint rung
    alone = _Planted(exps[:1], [None], None, tmp_path, print)
    alone.labels = []
    assert alone.joint(finalists) == [] and alone.labels == []
