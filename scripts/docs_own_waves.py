"""The docs' page of the engine waters calibrated against a reference with their own waves
(``waves.source = "shader"``), beside the same shaders against the study's waves, and the figure
of where their glints land.

The page is generated from committed ``constants.json`` files:

* ``docs/results/engine-shaders/<name>/``: ``study calibrate experiments/<name>.toml`` (the
  study's waves);
* ``docs/results/own-waves/<name>/``: the same with ``--set waves.source=shader``;
* ``docs/results/own-waves/<name>-x1.3/``: the same with ``--set waves.height_scale=1.3`` (a
  known factor on the reference's waves, for the shader's normal-strength constant to recover);
* ``docs/results/own-waves/<name>-animated-<source>/``: an animated calibration, both sources.

The figure (``glints.png``) and its scores (``glints.json``) come from two run folders'
``reference.exr`` and ``fitted.exr`` (``study calibrate experiments/dudv_depth_water.toml``,
without and with ``--set waves.source=shader``):
``python scripts/docs_own_waves.py STUDY_RUN OWN_RUN docs/results/own-waves/glints.png``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OWN_WAVES = ("webgl_mirror_water", "dudv_depth_water", "fog_cube_water", "zup_water")
# (experiment, its normal-strength constant) whose fit at waves.height_scale 1.3 is committed
RECOVERY = (("my_water", "BUMP"), ("zup_water", "bumpscale"))
# each shader's constant that scales its normals' slopes
NORMAL_CONSTANT = {"webgl_mirror_water": "normalScale", "zup_water": "bumpscale"}
ANIMATED = "zup_water"
GLINTS = "dudv_depth_water"  # the shader of the glints' figure


def _json(path: Path) -> dict:
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: re-run the calibration into {path.parent}")
    return json.loads(path.read_text())


def own_waves_page(results: Path) -> str:
    """The Markdown of ``results/own-waves/report.md`` (see the module doc)."""
    own = results / "own-waves"
    lines = [
        "# Engine waters against their own waves",
        "",
        "*Written by `scripts/build_docs.py` (`scripts/docs_own_waves.py`) from the committed "
        "`constants.json` of `study calibrate experiments/<name>.toml` with the study's waves "
        "(`docs/results/engine-shaders/<name>`) and with `--set waves.source=shader` "
        "(`docs/results/own-waves/<name>`). What the key does: [your shader's own "
        "waves](../../user-shader.md#the-reference-with-your-shaders-own-waves).*",
        "",
        "The reference of each shader's own waves is the surface whose normals the shader "
        "computes at its start values, integrated in least squares; the curl is the angle "
        "between the shader's normals and that surface's (what no surface has). Against its "
        "own waves a shader's fit may still lower its normal strength (last column): what it "
        "shades with its normals (a distorted mirror, a refraction buffer without the water's "
        "caustics) does not make the reference's glitter and caustics, and flatter normals "
        "lower the error by blurring, the more so the steeper the surface (an RMS slope near 1 "
        "is a storm).",
        "",
        "| experiment | FLIP fitted, study's waves | FLIP fitted, own waves | RMSE fitted, "
        "study's -> own | curl, mean (99th pct.) | RMS slope of its surface | normal constant: "
        "start, fitted study's -> own |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in OWN_WAVES:
        s, o = (
            _json(results / "engine-shaders" / name / "constants.json"),
            _json(own / name / "constants.json"),
        )
        w, const = o["waves"], NORMAL_CONSTANT.get(name)
        strength = "-"
        if const:
            ps, po = s["parameters"][const], o["parameters"][const]
            strength = f"`{const}`: {ps['default']:.3g}, {ps['fitted']:.3g} -> {po['fitted']:.3g}"
        lines.append(
            f"| `{name}` | {s['error']['flip']['fitted']:.4f} | {o['error']['flip']['fitted']:.4f}"
            f" | {s['error']['rmse']['fitted']:.4f} -> {o['error']['rmse']['fitted']:.4f} | "
            f"{w['curl_mean_deg']:.2f} ({w['curl_p99_deg']:.2f}) degrees | {w['slope_rms']:.3f} | "
            f"{strength} |"
        )
    lines += ["", "## A known truth: the reference's waves 1.3 times as steep", ""]
    lines += [
        "`--set waves.height_scale=1.3` scales the reference's surface (heights and slopes) by "
        "1.3; a shader whose normal-strength constant scales its normals' slopes should fit it "
        "1.3 times as large. Each constant below is fitted with the shader's other constants, "
        "against path-traced references.",
        "",
        "| experiment | constant | fitted, own waves | fitted, own waves x 1.3 | ratio | "
        "ratio / 1.3 | relative standard errors |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, const in RECOVERY:
        a, b = _json(own / name / "constants.json"), _json(own / f"{name}-x1.3" / "constants.json")
        pa, pb = a["parameters"][const], b["parameters"][const]
        se = [p.get("rel_std_error") for p in (pa, pb)]
        ses = ", ".join("-" if v is None else f"{100 * v:.1f} %" for v in se)
        ratio = pb["fitted"] / pa["fitted"]
        lines.append(
            f"| `{name}` | `{const}` | {pa['fitted']:.4g} ({pa['status']}) | {pb['fitted']:.4g} "
            f"({pb['status']}) | {ratio:.4f} | {100 * (ratio / 1.3 - 1):+.1f} % | {ses} |"
        )
    lines += [
        "",
        "A ratio off by more than its standard errors says the fit does not find the constant "
        "that makes the shader's normals the reference's, and then the fit is the weak link, "
        "not the reference: fitted to a noise-free image of its own, `my_water.frag` also stops "
        "short of its true `BUMP` (its loss falls only slowly over a stretch below the truth, "
        "where the solver's stopping rule ends the fit), where a shader whose lookups are all "
        "bilinear is recovered exactly (`tests/test_shader_waves.py`).",
    ]
    lines += _animated_lines(own)
    if (own / "glints.json").is_file():
        g = _json(own / "glints.json")
        lines += [
            "",
            "## Where the glints land",
            "",
            f"`{GLINTS}` fitted against each reference (the middle rows of the image, where the "
            "sun's glints are). A glint is a pixel brighter than the "
            f"{g['percentile']:g}th percentile of its image's water; one is matched when the "
            f"other image has one within {g['radius_px']} pixels.",
            "",
            "| reference's waves | shader's glints on one of the reference's | reference's "
            "glints the shader has |",
            "|---|---|---|",
        ]
        for label, sc in g["scores"].items():
            p, r = 100 * sc["precision"], 100 * sc["recall"]
            lines.append(f"| {label} | {p:.1f} % | {r:.1f} % |")
        lines += [
            "",
            "![reference, fitted shader and their difference, with the study's waves (top) and "
            "the shader's own (bottom)](glints.png)",
        ]
    return "\n".join(lines) + "\n"


def _animated_lines(own: Path) -> list[str]:
    runs = {s: own / f"{ANIMATED}-animated-{s}" / "constants.json" for s in ("study", "shader")}
    if not all(p.is_file() for p in runs.values()):
        return []
    lines = [
        "",
        "## In motion",
        "",
        f"`{ANIMATED}` animated (one constants block fitted on every frame): the shader's clock "
        "and the reference's frames move together when the reference has the shader's waves.",
        "",
        "The temporal RMSE compares frame-to-frame changes: the reference's change is mostly its "
        "floor's caustics and refraction moving under the waves, which a shader that reads the "
        "scene's colour without the water never draws; the change ratio (the shader's change "
        "over the reference's) says how much of it the fitted shader has.",
        "",
        "| reference's waves | frames | mean FLIP | temporal RMSE | above the reference's noise "
        "| change ratio |",
        "|---|---|---|---|---|---|",
    ]
    names = {"study": "the study's", "shader": "the shader's own"}
    for source, path in runs.items():
        d = _json(path)
        a = d["animation"]
        sc = a["scores"]["all_frames"]
        t = sc["temporal"]
        lines.append(
            f"| {names[source]} | {a['frames']} | {sc['flip_mean']:.4f} | {t['trmse']:.5f} | "
            f"{t['trmse_excess']:.5f} | {t['change_ratio']:.3f} |"
        )
    return lines


GLINT_PERCENTILE = 99.0  # a glint: a pixel brighter than this percentile of its image
GLINT_RADIUS = 2  # pixels: a glint is matched when the other image has one this close


def glint_match(ref, img, mask) -> dict:
    """How well the glints of ``img`` land on those of ``ref`` ((H, W, 3) linear RGB) on the
    pixels ``mask``: each image's glints are its pixels above :data:`GLINT_PERCENTILE` of its
    luminance there; ``precision``: the fraction of ``img``'s glints with one of ``ref``'s
    within :data:`GLINT_RADIUS` pixels; ``recall``: the fraction of ``ref``'s with one of
    ``img``'s."""
    import numpy as np
    from scipy.ndimage import binary_dilation

    def glints(x):
        lum = x @ np.array([0.2126, 0.7152, 0.0722])
        return mask & (lum > np.percentile(lum[mask], GLINT_PERCENTILE))

    a, b = glints(ref), glints(img)
    near = np.ones((2 * GLINT_RADIUS + 1,) * 2, bool)
    return {
        "precision": float((b & binary_dilation(a, near)).sum() / max(b.sum(), 1)),
        "recall": float((a & binary_dilation(b, near)).sum() / max(a.sum(), 1)),
        "glints": [int(a.sum()), int(b.sum())],
    }


def glints_figure(study_run: Path, own_run: Path, out: Path) -> dict:
    """``out`` (PNG): reference | fitted | absolute difference of the two runs (rows), sRGB,
    the middle of the image where the sun's glints are; and ``out`` with ``.json``: the
    :func:`glint_match` of each run on its water pixels (its ``reference.exr``'s finite,
    fitted non-zero pixels)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from study._io import read_exr, to_srgb

    fig, axes = plt.subplots(2, 3, figsize=(9, 3.3))
    scores = {}
    for row, (run, label) in enumerate(((study_run, "study's waves"), (own_run, "own waves"))):
        ref, fit = (read_exr(run / f)[0][..., :3] for f in ("reference.exr", "fitted.exr"))
        mask = np.isfinite(ref).all(-1) & (fit.max(-1) > 0)
        scores[label] = glint_match(ref, fit, mask)
        h, w = ref.shape[:2]
        crop = (slice(h // 4, 3 * h // 5), slice(w // 8, 7 * w // 8))
        diff = np.abs(fit - ref).mean(-1)[crop]
        for col, (img, title) in enumerate(
            ((to_srgb(ref[crop]), "reference"), (to_srgb(fit[crop]), "fitted shader"),
             (diff, "|difference|"))
        ):  # fmt: skip
            ax = axes[row, col]
            ax.imshow(img, cmap="magma" if img.ndim == 2 else None, vmin=0, vmax=0.5)
            ax.set_title(f"{title}, {label}", fontsize=9)
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
    record = {"study_run": study_run.name, "own_run": own_run.name, "scores": scores,
              "percentile": GLINT_PERCENTILE, "radius_px": GLINT_RADIUS}  # fmt: skip
    out.with_suffix(".json").write_text(json.dumps(record, indent=2) + "\n")
    return record


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit("usage: python scripts/docs_own_waves.py STUDY_RUN OWN_RUN OUT.png")
    glints_figure(Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]))
