"""The docs' page of what the best shaders' remaining error is made of, and the figure of the
highlights beside the reference.

The page is generated from committed results in ``docs/results/error-budget/``:

* ``<fit>.json``: ``benchmarks/bench_error_budget.py <run> --json`` on a ``study calibrate``
  output folder (``experiments/default.toml`` with ``--set fit.shader=...``; the folder's name
  is ``<fit>``); ``<scene>/<fit>.json`` the same on another experiment (``--experiment
  experiments/<scene>.toml``);
* ``images_default.exr`` / ``.json``: the reference beside the fitted shaders, the panels as
  data (``study.report.panels``; ``scripts/build_docs.py`` draws ``images_default.png``), from
  the same run folders: ``python scripts/docs_error_budget.py panels RUN [RUN ...]``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FOLDER = REPO / "docs" / "results" / "error-budget"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    return [
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
        *("| " + " | ".join(r) + " |" for r in rows),
    ]


def _fit_section(d: dict) -> list[str]:
    out = [
        f"## `{d['shader']}`" + ("" if d["experiment"] == "default" else f" on {d['experiment']}"),
        "",
        f"Its terms against the reference's (the reference {d['reference_spp']} spp, each of the "
        f"reference's terms path traced again at {d['spp']} spp, {d['terms_render_s']} s):",
        "",
    ]
    rows = [[o["label"], f"{o['flip']:.4f}", f"{o['rmse']:.4f}"] for o in d["oracles"]]
    out += _table(["terms taken from the reference", "FLIP", "RMSE"], rows)
    out += ["", "Where its error is:", ""]
    rows = [
        [c["class"], f"{c['pixels']:.1%}", f"{c['flip']:.4f}", f"{c['flip_share']:.1%}"]
        for c in d["classes"]
    ]
    out += _table(["pixel class", "water pixels", "FLIP there", "share of the mean FLIP"], rows)
    out += ["", "Its sky and refraction with other highlights:", ""]
    rows = [
        [h["label"], f"{h['flip']:.4f}", f"{h['rmse']:.4f}", h["note"]] for h in d["highlights"]
    ]
    out += _table(["highlight", "FLIP", "RMSE", ""], rows)
    return out + [""] + glint_split(d["highlights"])


def glint_split(highlights: list[dict]) -> list[str]:
    """A paragraph: the FLIP between the sun's disc off the shader's normal at one sample a
    pixel and the reference's glitter, term by term, from rows (c), (e), (f) and the oracle
    (none where the result has no rows (e) and (f))."""
    flip = {}
    for h in highlights:
        if h["label"][:3] in ("(c)", "(e)", "(f)"):
            flip[h["label"][:3], h["label"].rsplit(", ", 1)[1].split()[0]] = h["flip"]
        elif "(oracle)" in h["label"]:
            flip["oracle"] = h["flip"]
    fine = {n[1] for n in flip if n != "oracle" and n[1] != "1x1"}
    need = [("(c)", "1x1"), "oracle"] + [(t, k) for t in ("(c)", "(e)", "(f)") for k in fine]
    if len(fine) != 1 or any(n not in flip for n in need):
        return []
    (k,) = fine
    c1, ck, ek, fk, o = (
        flip[n] for n in (("(c)", "1x1"), ("(c)", k), ("(e)", k), ("(f)", k), "oracle")
    )
    return [
        f"From the sun's disc off the shader's normal at one sample a pixel (FLIP {c1:.4f}) to "
        f"the reference's glitter ({o:.4f}): {c1 - o:.4f} in all, of which the pixel's footprint "
        f"({k} samples) {c1 - ck:.4f}, the normal (the surface's exact normal in place of the "
        f"shader's) {ck - ek:.4f}, the heights' parallax (that normal where the eye ray meets "
        f"the surface, not under the pixel's point on the water plane) {ek - fk:.4f}, and the "
        f"rest {fk - o:.4f}.",
        "",
    ]


def error_budget_page(folder: Path = FOLDER) -> str:
    """``report.md`` of ``docs/results/error-budget`` from its ``<fit>.json`` files."""
    fits = sorted(folder.glob("*.json")) + sorted(folder.glob("*/*.json"))
    fits = [p for p in fits if not p.name.startswith("images_")]
    if not fits:
        raise FileNotFoundError(f"{folder}: no bench_error_budget.py result (<fit>.json)")
    lines = [
        "# What the remaining error is made of",
        "",
        "*Written by `scripts/build_docs.py` (`scripts/docs_error_budget.py`) from the committed "
        "results of `benchmarks/bench_error_budget.py` (its docstring says what each table "
        "measures). FLIP and RMSE on the scored water pixels of the default scene (of the "
        "scene a section names) against the cached reference.*",
        "",
    ]
    results = [json.loads(p.read_text()) for p in fits]
    # the default scene's fits first, the worst first
    for d in sorted(
        results, key=lambda d: (d["experiment"] != "default", -d["oracles"][0]["flip"])
    ):
        lines += _fit_section(d)
    if (folder / "images_default.exr").is_file():
        lines += [
            "![the reference beside the fitted shaders and their absolute errors]"
            "(images_default.png)",
            "",
        ]
    return "\n".join(lines)


def write_panels_from_runs(runs: list[Path], folder: Path = FOLDER) -> Path:
    """``images_default.exr`` / ``.json``: the first run's reference, then each run's fitted
    image titled by its shader, scored on the calibration's water pixels (the mask of
    ``ShaderModel.from_experiment`` on the default experiment for the first run's shader, as
    the bench scores; the raycast shaders share it)."""
    sys.path.insert(0, str(REPO))
    from study import init_backend, load_experiment
    from study._io import read_exr
    from study._metrics import errors
    from study.calibration.frames import load_scene_data
    from study.fit.model import ShaderModel
    from study.report.panels import write_panels

    runs = [Path(r) for r in runs]
    exp = load_experiment(REPO / "experiments" / "default.toml")
    ref, inputs, _ = load_scene_data(exp, init_backend(exp["variant"]))
    w, h = exp["resolution"]
    images, errs, mask = {"reference": ref.image}, {}, None
    for run in runs:
        d = json.loads((run / "constants.json").read_text())
        if d.get("experiment") != exp["name"] or tuple(d.get("resolution", (w, h))) != (w, h):
            raise SystemExit(f"{run}: not a calibration of {exp['name']} at {w}x{h}")
        if mask is None:  # the water quad's pixels: the same for every shader drawn on it
            mask = ShaderModel.from_experiment(
                exp, inputs, ref.image, shader=d["shader"], resolution=(w, h)
            ).mask
        images[d["shader"]] = read_exr(run / "fitted.exr")[0]
    for title, img in list(images.items())[1:]:
        errs[title] = errors(ref.image, img, mask)
    return write_panels(folder / "images_default.png", images, errs, mask, title="default")[0]


if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] != "panels":
        raise SystemExit("usage: python scripts/docs_error_budget.py panels RUN [RUN ...]")
    print(write_panels_from_runs(sys.argv[2:]))
