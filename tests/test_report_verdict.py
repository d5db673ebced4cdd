"""The calibration report opens with its verdict (against the reference's noise, the shader at
its start constants and the best shader a committed tradeoff knows for the scene) and the
commands to run next."""

from __future__ import annotations

import copy
import json
from pathlib import Path

from helpers import REPO

from study.report.calibration import best_known, report_text

RESULTS = REPO / "docs" / "results"


def _make_run() -> dict:
    return json.loads((RESULTS / "default" / "constants.json").read_text())


def _opening(text: str) -> str:
    """The report's lines before its reference line."""
    return text.split("\nReference: ")[0]


def test_the_first_lines_judge_the_fit_and_name_the_next_commands():
    summary = _make_run()
    text = report_text(summary, {}, out=Path("out/x"))
    lines = text.split("\n")
    assert lines[0].startswith("# Calibration") and lines[2].startswith("**Verdict.**")
    head = _opening(text)
    e, noise = summary["error"], summary["reference"]["noise"]
    assert f"{e['flip']['default']:.4f} at the start constants" in head
    assert f"{e['rmse']['fitted'] / noise:.1f}x the reference's measured noise" in head
    tradeoff = json.loads((RESULTS / "tradeoff" / "summary.json").read_text())
    best = tradeoff["scenes"]["default"]["best_within_seed_budget"]
    assert f"`{best['label']}`, FLIP {best['flip']:.4f}" in head
    assert "`study tradeoff experiments/default.toml --out out/x-tradeoff`" in head
    assert "`study export out/x/constants.json --out out/x-export`" in head
    assert "`out/x/viewer/index.html`" in head


def test_a_scene_no_tradeoff_knows_and_a_fit_at_the_noise_floor(tmp_path):
    summary = copy.deepcopy(_make_run())
    summary["experiment"] = "my_pool"
    summary["reference"]["noise"] = summary["error"]["rmse"]["fitted"]
    assert best_known("my_pool") is None
    head = _opening(report_text(summary, {}))
    assert "No committed tradeoff covers the scene `my_pool`" in head
    assert "1.0x the reference's measured noise" in head and "more samples" in head


def test_the_best_known_shader_comes_from_the_committed_tradeoffs(tmp_path):
    (tmp_path / "scenes").mkdir()
    point = {"label": "water_refraction_beer (5, 1.5, 20)", "flip": 0.5}
    (tmp_path / "scenes" / "summary.json").write_text(
        json.dumps({"scenes": {"pool": {"recommended": point}}})
    )
    assert best_known("pool", tmp_path) == {**point, "folder": "docs/results/scenes"}
    assert best_known("other", tmp_path) is None
