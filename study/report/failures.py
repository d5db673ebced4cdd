"""Figures and report of the failure catalogue (``study failures``).

Images are linear RGB (H, W, 3), shown sRGB-encoded and clipped to [0, 1]; the class map is
one colour per primary class (the first class that holds, in catalogue order); the FLIP map is
the per-pixel LDR-FLIP of the port against the reference on the scored water pixels.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .._io import to_srgb, write_text_atomic
from .calibration import pyplot

# one colour per class, in catalogue order (tab10 without its grey), 'none' light grey
_COLOURS = ["#d62728", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#1f77b4", "#17becf", "#bcbd22"]


def failures_figure(
    path: Path,
    reference: np.ndarray,
    port: np.ndarray,
    label: np.ndarray,
    flip: np.ndarray,
    scored: np.ndarray,
    class_keys: list,
    title: str = "",
) -> Path:
    """Reference | port | class map | FLIP map. ``label``: (H, W) int from
    ``studies.failures.primary_class`` (-1 off the water, 0 none, i + 1 class ``class_keys[i]``
    of the full catalogue order); ``class_keys``: the catalogue's keys."""
    plt = pyplot()
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    fig, axes = plt.subplots(1, 4, figsize=(13.5, 3.9))
    axes[0].imshow(to_srgb(reference))
    axes[0].set_title("reference", fontsize=9)
    axes[1].imshow(to_srgb(port))
    axes[1].set_title("port", fontsize=9)
    colours = ["#e6e6e6"] + _COLOURS[: len(class_keys)]
    lab = np.where(label < 0, np.nan, label.astype(float))
    axes[2].imshow(
        lab,
        cmap=ListedColormap(colours),
        vmin=-0.5,
        vmax=len(colours) - 0.5,
        interpolation="nearest",
    )
    axes[2].set_title("failure class (first that holds)", fontsize=9)
    present = sorted(set(int(v) for v in np.unique(label) if v >= 0))
    handles = [
        Patch(color=colours[v], label="none" if v == 0 else class_keys[v - 1]) for v in present
    ]
    axes[2].legend(handles=handles, fontsize=6, loc="lower left", framealpha=0.85)
    im = axes[3].imshow(np.where(scored, flip, np.nan), cmap="magma", vmin=0, vmax=1)
    axes[3].set_title(f"FLIP (mean {float(flip[scored].mean()):.3f} on scored water)", fontsize=9)
    fig.colorbar(im, ax=axes[3], shrink=0.8)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        fig.suptitle(title, fontsize=10)
    fig.savefig(path, dpi=80, bbox_inches="tight")
    plt.close(fig)
    return path


def _pct(x) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f} %"


def _num(x) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.3f}"


def table_markdown(rows: list[dict]) -> str:
    """Markdown table of ``studies.failures.failure_table`` rows."""
    lines = [
        "| class | water pixels | share of FLIP error | mean FLIP inside | mean FLIP outside |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| `{r['class']}` | {_pct(r['pixel_share'])} ({r['pixels']}) | "
            f"{_pct(r['flip_share'])} | {_num(r['flip_inside'])} | {_num(r['flip_outside'])} |"
        )
    return "\n".join(lines)


def scenes_of(tidy: list[dict]) -> list[dict]:
    """The report's scenes from the rows of ``failures.parquet`` (one per experiment and class,
    each carrying its scene's figures), in the table's order: dicts with ``experiment``,
    ``shader``, ``figure`` (relative path), ``rows``, ``flip``, ``spp``, ``noise``,
    ``water_pixels``."""
    scenes: dict[str, dict] = {}
    for t in tidy:
        s = scenes.setdefault(
            t["experiment"],
            {
                "experiment": t["experiment"],
                "shader": t["shader"],
                "figure": t["figure"],
                "rows": [],
                "flip": t["scene_flip"],
                "spp": t.get("reference_spp"),
                "noise": t.get("reference_noise"),
                "water_pixels": t["water_pixels"],
            },
        )
        s["rows"].append(t)
    return list(scenes.values())


def write_failures_report(out: Path, scenes: list[dict], classes: list, command: str) -> Path:
    """``out/report.md`` of :func:`failures_report_text`."""
    path = out / "report.md"
    write_text_atomic(path, failures_report_text(scenes, classes, command))
    return path


def failures_report_text(scenes: list[dict], classes: list, command: str) -> str:
    """The report's Markdown: the class definitions, then per scene its figure and table.
    ``scenes``: :func:`scenes_of`; ``classes``: the catalogue's ``FailureClass`` entries."""
    lines = [
        "# Where the shader fails: the failure catalogue",
        "",
        f"Reproduce: `{command}`",
        "",
        "Classes (a pixel may be in several; the map shows the first that holds, in this order; "
        "thresholds and their reasons: `study/studies/failures.py`):",
        "",
        "| class | meaning | test |",
        "|---|---|---|",
    ]
    lines += [f"| `{c.key}` | {c.title} | {c.rule} |" for c in classes]
    lines.append("")
    for s in scenes:
        lines += [
            f"## {s['experiment']} ({s['shader']})",
            "",
            f"{s['water_pixels']} scored water pixels, mean FLIP {s['flip']:.4f} (reference: "
            f"{s.get('spp')} spp, noise {s.get('noise') or float('nan'):.3g} RMS linear RGB; the "
            "noise raises FLIP in every class alike).",
            "",
            f"![failure classes of {s['experiment']}]({s['figure']})",
            "",
            table_markdown(s["rows"]),
            "",
        ]
    return "\n".join(lines)
