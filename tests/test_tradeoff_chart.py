"""The tradeoff chart and report text from small hand-made points: the legend lists exactly what
is drawn and sits beside the panels, a budget is drawn, log-axis tick labels are plain numbers
that do not overlap, and the report labels its schedule tuples and prints no row of dashes."""

from __future__ import annotations

import itertools

import pytest

from study.report.calibration import pyplot
from study.report.tradeoff import COSTS, FLOOR, SEED, pareto_chart, tradeoff_report_text


def _rec(variant, kind, scale, sched, fetches, flip):
    return {
        "experiment": "default",
        "variant": variant,
        "kind": kind,
        "scale": scale,
        "label": f"{variant} {sched}",
        "flip": flip,
        "rmse": flip / 2,
        "fetches_mean": fetches,
        "fetches_p99": fetches * 1.5,
        "gl_norm_ms_1080p": fetches * 12.0,
        "port_ms_512": fetches * 3.0,
    }


def _points(converged: bool, seed: bool) -> list:
    recs = [
        _rec("water_refraction", "grid", None, "(5, 1.5, 20)", 9.0, 0.20),
        _rec("water_baseline_flat", "fixed", None, "", 3.2, 0.30),
        _rec("water_refraction_beer", "grid", None, "(20, 6, 80)", 31.0, 0.15),
    ]
    if seed:
        recs.append(_rec("water_refraction", "scale", 1.0, "(10, 3, 40)", 17.0, 0.17))
    if converged:
        recs.append(_rec("water_refraction", "converged", 8.0, "(80, 24, 320)", 120.0, 0.14))
    return recs


def _summary(recs, budget=None) -> dict:
    cands = [r for r in recs if r["kind"] != "converged"]
    front = sorted(cands, key=lambda r: r["fetches_mean"])
    front = [r for i, r in enumerate(front) if all(q["flip"] > r["flip"] for q in front[:i])]
    labels = [r["label"] for r in front]
    seed = next((r for r in cands if r["kind"] == "scale"), None)
    floors = {r["variant"]: r["flip"] for r in recs if r["kind"] == "converged"}
    return {
        "tolerance": 0.02,
        "n_points": len(recs),
        "n_failed": 0,
        "budget": budget or {},
        "failures": [],
        "scenes": {
            "default": {
                "fronts_by_cost": {c: labels for c in COSTS},
                "front": front,
                "recommended": front[1],
                "seed": seed,
                "simplest_variant_within_tolerance": "water_refraction",
                "best_flip_by_variant": {r["variant"]: r["flip"] for r in cands},
                "error_floor_by_variant": {
                    v: floors.get(v) for v in dict.fromkeys(r["variant"] for r in cands)
                },
                "smallest_crossing_loop_cap": {"water_refraction": 20},
                "halvings": [],
            }
        },
    }


def _drawn(fig) -> set:
    """The legend entries of what is drawn: the ``gid`` of every artist in the panels."""
    out = set()
    for ax in fig.axes:
        for a in itertools.chain(ax.collections, ax.lines):
            if a.get_gid():
                out.add(a.get_gid())
    return out


def _legend(fig):
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert len(legends) == 1, "one legend for the chart"
    return legends[0]


@pytest.mark.parametrize("converged,seed,budget", [(False, False, None), (True, True, 17.0)])
def test_legend_lists_exactly_what_is_drawn(converged, seed, budget):
    recs = _points(converged, seed)
    summary = _summary(recs, {"fetches_mean": budget} if budget else None)
    plt = pyplot()
    fig = pareto_chart(recs, summary)
    try:
        texts = [t.get_text() for t in _legend(fig).get_texts()]
        assert len(texts) == len(set(texts))
        assert set(texts) == _drawn(fig)
        assert (FLOOR in texts) == converged and (SEED in texts) == seed
        assert any(t.startswith("budget:") for t in texts) == (budget is not None)
        if budget:
            fetches = fig.axes[0]
            lines = [ln for ln in fetches.lines if str(ln.get_gid()).startswith("budget:")]
            assert len(lines) == 1 and lines[0].get_xdata()[0] == budget
            # only the fetches panel has a budget
            assert not any(str(ln.get_gid()).startswith("budget:") for ln in fig.axes[1].lines)
        assert {"Pareto front", "recommended", "water_refraction"} <= set(texts)
        # beside the panels: the legend's box overlaps no panel's
        fig.canvas.draw()
        box = _legend(fig).get_window_extent()
        assert box.x0 >= max(ax.get_window_extent().x1 for ax in fig.axes)
    finally:
        plt.close(fig)


def test_log_ticks_are_plain_numbers_that_do_not_overlap():
    recs = _points(True, True)
    plt = pyplot()
    fig = pareto_chart(recs, _summary(recs, {"fetches_mean": 17.0}))
    try:
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        for ax in fig.axes:
            lo, hi = ax.get_xlim()
            labels = [
                t
                for t in ax.get_xticklabels(which="both")
                if t.get_text() and lo <= t.get_position()[0] <= hi
            ]
            assert len(labels) >= 2, [t.get_text() for t in labels]
            for t in labels:
                assert "^" not in t.get_text() and "times" not in t.get_text(), t.get_text()
                float(t.get_text().replace("\u2212", "-"))  # a plain number
            boxes = sorted((t.get_window_extent(renderer) for t in labels), key=lambda b: b.x0)
            for a, b in zip(boxes, boxes[1:]):
                assert a.x1 <= b.x0, [t.get_text() for t in labels]
    finally:
        plt.close(fig)


def test_report_labels_the_schedule_and_prints_no_dashes():
    recs = _points(False, True)
    text = tradeoff_report_text(_summary(recs))
    assert "(steps at grazing angles, steps at steep angles, loop cap)" in text
    assert "error floor" not in text  # no converged point: no floor line at all
    assert "| shader (schedule) |" in text
    assert " -, " not in text and not text.count(" - |") > 3
    floored = tradeoff_report_text(_summary(_points(True, True)))
    line = next(ln for ln in floored.splitlines() if "error floor" in ln)
    assert "water_refraction 0.14" in line and "-" not in line.split(":", 1)[1]


def test_the_recommended_point_lies_on_the_front_drawn_and_frame_times_draw_none():
    """The committed default tradeoff's chart: the front is drawn against the fetches only (frame
    times on llvmpipe move from run to run), and the recommendation is one of its vertices."""
    import json

    from helpers import REPO

    from study.studies.tradeoff_analysis import analyse
    from study.sweep import read_table

    folder = REPO / "docs" / "results" / "tradeoff"
    summary = json.loads((folder / "summary.json").read_text())
    _, recs = analyse(read_table(folder / "tradeoff.parquet"), list(summary["scenes"]),
                      summary["tolerance"])  # fmt: skip
    fig = pareto_chart(recs, summary)
    rec = summary["scenes"]["default"]["recommended"]
    fronts = {}
    for ax, cost in zip(fig.axes, COSTS):
        lines = [ln for ln in ax.lines if ln.get_gid() == "Pareto front"]
        fronts[cost] = lines
        marks = [c for c in ax.collections if c.get_gid() == "recommended"]
        assert len(marks) == 1, cost
        x, y = marks[0].get_offsets()[0]
        assert (x, y) == pytest.approx((rec[cost], rec["flip"])), cost
        for ln in lines:  # the mark is a vertex of the front drawn on its panel
            assert any((px, py) == pytest.approx((x, y)) for px, py in zip(*ln.get_data())), cost
    assert len(fronts[summary["cost"]]) == 1
    assert all(not fronts[c] for c in COSTS if c != summary["cost"])
    pyplot().close(fig)
    text = tradeoff_report_text(summary)
    assert "Frame times are shown, never ranked" in text and "ranked by BIC" in text
    assert f"A quick screen fitted {summary['search']['screened']} points" in text
