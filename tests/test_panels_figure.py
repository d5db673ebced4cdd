"""The side-by-side figure's titles: each stays within its own column."""

from __future__ import annotations

import numpy as np
import pytest

from study.report.calibration import comparison_figure, pyplot

NAMES = [
    "reference",
    "original shader, its own constants",
    "original shader, fitted: water_refraction (10, 3, 40)",
    "best within the original's fetches: water_refraction_beer_disc_walls (10, 3, 40)",
    "recommended: water_refraction_beer_disc_walls (5, 1.5, 20)",
]


def _overlaps(boxes) -> list[tuple[int, int]]:
    return [(i, i + 1) for i, (a, b) in enumerate(zip(boxes, boxes[1:])) if a.x1 > b.x0]


@pytest.mark.parametrize("n", [3, 5])
def test_no_two_titles_of_a_row_overlap(tmp_path, monkeypatch, n):
    plt = pyplot()
    figs = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig: figs.append(fig))
    rng = np.random.default_rng(0)
    images = {k: rng.random((32, 40, 3), dtype=np.float32) for k in NAMES[:n]}
    errors = {k: {"flip": 0.1, "rmse": 0.05} for k in NAMES[1:n]}
    path = comparison_figure(tmp_path / "f.png", images, errors, np.ones((32, 40), bool), "t")
    assert path.stat().st_size > 0
    (fig,) = figs
    renderer = fig.canvas.get_renderer()
    top, bottom = fig.axes[:n], fig.axes[n : 2 * n]  # the grid's rows; then the colour bar
    assert not _overlaps([ax.title.get_window_extent(renderer) for ax in top])
    assert not _overlaps([ax.title.get_window_extent(renderer) for ax in bottom])
    assert [ax.get_title() for ax in bottom][1:] == ["|above - reference|"] * (n - 1)
    close(fig)
