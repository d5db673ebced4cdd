"""The calibration report: figures (matplotlib, Agg) and ``report.md`` with its tables.

Images are linear RGB (H, W, 3); figures show them sRGB-encoded and clipped to [0, 1].
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from shaders_port import CONSTANT_SPECS, study_scalar

from .._io import to_srgb, write_text_atomic
from ..export.textures import expects_lines
from ..scene.reference import spp_text
from .identifiability import identifiability_section
from .numbers import fmt


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def comparison_figure(
    path: Path, images: dict, errors: dict, mask: np.ndarray, title: str = ""
) -> Path:
    """Row 1: the images (e.g. reference | default | fitted); row 2: |image - reference| averaged
    over RGB on the water pixels, one shared colour scale, each map under its image."""
    plt = pyplot()
    names = list(images)
    ref = images[names[0]]
    n = len(names)
    fig, axes = plt.subplots(2, n, figsize=(3.2 * n, 6.4), squeeze=False)
    vmax = (
        max(float(np.abs(images[k] - ref).mean(-1)[mask].max()) for k in names[1:])
        if n > 1
        else 1.0
    )
    vmax = max(vmax, 1e-6)
    for j, k in enumerate(names):
        axes[0, j].imshow(to_srgb(images[k]))
        name = textwrap.fill(k, 34)
        label = (
            name
            if k not in errors
            else f"{name}\nRMSE {errors[k]['rmse']:.4f}  FLIP {errors[k]['flip']:.4f}"
        )
        axes[0, j].set_title(label, fontsize=9)
        if j == 0:
            axes[1, j].imshow(mask, cmap="gray")
            axes[1, j].set_title("water pixels scored", fontsize=9)
        else:
            err = np.where(mask, np.abs(images[k] - ref).mean(-1), np.nan)
            im = axes[1, j].imshow(err, cmap="magma", vmin=0, vmax=vmax)
            # the panel above names the image: a short title that fits the narrower map
            axes[1, j].set_title(f"|above - {names[0]}|", fontsize=9)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    if n > 1:
        fig.colorbar(im, ax=axes[1, :].tolist(), shrink=0.8, label="mean abs. error (linear RGB)")
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def diagnostics_figure(path: Path, maps: dict, mask: np.ndarray, title: str = "") -> Path:
    """One panel per diagnostic map, water pixels only."""
    plt = pyplot()
    keys = list(maps)
    fig, axes = plt.subplots(1, len(keys), figsize=(3.2 * len(keys), 3.4), squeeze=False)
    for ax, k in zip(axes[0], keys):
        v = np.where(mask, maps[k], np.nan)
        if k == "denominator":
            v = np.log10(np.maximum(v, 1e-9))
            k = "log10 |denominator|"
        im = ax.imshow(v, cmap="viridis")
        ax.set_title(k, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        fig.colorbar(im, ax=ax, shrink=0.75)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def loss_figure(path: Path, curves: dict, title: str = "") -> Path:
    """Loss (0.5 * sum r^2) against iteration, one line per run, log scale."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for name, ys in curves.items():
        if len(ys):
            ax.semilogy(np.arange(len(ys)), ys, label=name)
    ax.set_xlabel("iteration")
    ax.set_ylabel("loss 0.5 ||r||^2")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def constants_table(parameters: dict) -> list[str]:
    """Each constant by its GLSL name (the study's descriptive name beside it, where the record
    gives one that differs; the stage that reads it, for a user's shader after its own vertex
    shader): its default (the fit's start), exported value, status and why."""
    named = any(p.get("name", n) != n for n, p in parameters.items())
    staged = any("stage" in p for p in parameters.values())  # a pair with its vertex shader
    cols = ["constant (GLSL)", "study name"] if named else ["constant (GLSL)"]
    cols += ["stage"] if staged else []
    cols += ["default", "exported", "status", "why"]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for name, p in parameters.items():
        shown = p["fitted"] if p["fitted"] is not None else p["default"]
        study = [p.get("name", name)] if named else []
        stage = [p.get("stage", "")] if staged else []
        lines.append(
            "| "
            + " | ".join([f"`{name}`", *study, *stage, fmt(p["default"]), fmt(shown)])
            + f" | {p.get('status', '')} | {p.get('reason', '')} |"
        )
    return lines


def basin_lines(parameters: dict) -> list[str]:
    """What the basin scan (``study.fit.basins``) found for each scanned constant."""
    lines = []
    for name, p in parameters.items():
        b = p.get("basins")
        if not b:
            continue
        span = f"{fmt(min(b['grid']))}-{fmt(max(b['grid']))}"
        r = b.get("restart")
        if r:
            lines.append(
                f"`{name}`: the first fit stopped at {fmt(r['from'])}, with a basin at "
                f"{fmt(r['to'])} lower "
                "by more than the reference's noise explains (the loss is piecewise); "
                "refitted from there: "
                f"loss {fmt(r['loss_before'])} -> {fmt(r['loss_after'])}, "
                + ("kept." if r["kept"] else "not lower, so the first solution is exported.")
            )
        unconfirmed = {o["value"]: o for o in b.get("unconfirmed", [])}
        lower = [o for o in b["basins"] if o["value"] in b.get("lower", [])]
        close = [o for o in b["basins"] if o["indistinguishable"]]
        for o in lower:
            if o["value"] in unconfirmed:
                lines.append(
                    f"`{name}`: a basin of the loss at {fmt(o['value'])} is "
                    "lower than the fit's by "
                    f"{fmt(-o['delta_loss'])} (+- {fmt(o['noise_sd'])} from the "
                    "reference's noise) in "
                    "this texture, but higher by "
                    f"{fmt(unconfirmed[o['value']]['texture_delta'])} in the "
                    "decorrelated loss of the "
                    "texture's independent halves (unbiased for the noise-free "
                    "texture): the texture's "
                    "noise or its denoiser makes it lower, so it was not refitted."
                )
                continue
            lines.append(
                f"`{name}`: a basin of the loss at {fmt(o['value'])} is lower than the fit's by "
                f"{fmt(-o['delta_loss'])}, more than the reference's noise explains "
                f"(+- {fmt(o['noise_sd'])}): the solver stopped short of it "
                "(the loss is piecewise). " + _start_there(name, p, o["value"])
            )
        for o in close:
            lines.append(
                f"`{name}`: another basin of the loss at {fmt(o['value'])} (loss difference "
                f"{fmt(o['delta_loss'])} +- {fmt(o['noise_sd'])} from the reference's noise): the "
                "reference's noise cannot tell it from the fit's, so the exported value is one of "
                "these, not known to its standard error."
            )
        rest = len(b["basins"]) - len(close) - len(lower)
        minima = f"{rest} other local minim{'um' if rest == 1 else 'a'} of the loss in {span}"
        if not b["basins"]:
            what = f"no other basin of the loss in {span}."
        elif any(o["noise_sd"] is None for o in b["basins"]):
            what = f"{minima} (no noise estimate of the reference to compare them with)."
        else:
            what = (
                f"{minima}, each higher than the fit's by more than the reference's noise "
                "explains: the fit is in the lowest basin found, nothing to try there."
            )
        if rest or not b["basins"]:
            lines.append(f"`{name}`: {what} (The other constants held at the solution.)")
    return lines + [""] if lines else []


def _start_there(name: str, p: dict, value: float) -> str:
    """What to run to fit from a lower basin at ``value`` of the constant ``name``."""
    study = p.get("name") or study_scalar(name)  # records before names: the study's own
    if study.split("[")[0] in CONSTANT_SPECS:  # the study's shader: the [constants] table
        return (
            f"To fit from there, run the same command with `--set constants.{study}={value:.4g}`"
            " (the fit then starts in that basin)."
        )
    return (
        f"To fit from there, set the initializer of `{name}` in your shader to {value:.4g} and "
        "run the same command (the fit starts from the shader's own values)."
    )


def write_report(out: Path, summary: dict, figures: dict) -> Path:
    """``out/report.md`` from the calibration summary (the content of constants.json)."""
    path = out / "report.md"
    write_text_atomic(path, report_text(summary, figures, out=out))
    return path


# the tradeoff-family results committed with the project (absent from an installed package)
COMMITTED_RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
TRADEOFF_RESULTS = ("tradeoff", "scenes", "views/tradeoff")


def best_known(experiment: str, results: Path = COMMITTED_RESULTS) -> dict | None:
    """The best shader a committed tradeoff knows for the scene ``experiment``: its best point
    within the original's fetches (``best_within_seed_budget``, else the recommendation), with
    the folder it comes from; None where no committed tradeoff holds the scene."""
    import json

    for folder in TRADEOFF_RESULTS:
        summary = results / folder / "summary.json"
        if not summary.is_file():
            continue
        scene = (json.loads(summary.read_text()).get("scenes") or {}).get(experiment)
        best = scene and (scene.get("best_within_seed_budget") or scene.get("recommended"))
        if best and best.get("flip") is not None:
            return {**best, "folder": f"docs/results/{folder}"}
    return None


def verdict_lines(summary: dict, out: Path | None = None) -> list[str]:
    """The report's opening: where the fit stands (against the reference's noise, the shader at
    its start constants and the best shader a committed tradeoff knows for the scene) and the
    commands to run next."""
    e, noise = summary["error"], summary["reference"].get("noise")
    rmse, flip = e["rmse"], e["flip"]
    gain = 1 - flip["fitted"] / flip["default"] if flip["default"] else 0.0
    lines = [
        f"**Verdict.** FLIP {flip['default']:.4f} at the start constants -> "
        f"{flip['fitted']:.4f} fitted ({100 * gain:.0f} % less error; RMSE "
        f"{rmse['default']:.4f} -> {rmse['fitted']:.4f})."
    ]
    if noise:
        ratio = rmse["fitted"] / noise
        lines[0] += (
            f" The fitted RMSE is {ratio:.1f}x the reference's measured noise ({noise:.4f}): "
            + (
                "the error left is the shader's, not the reference's noise."
                if ratio >= 1.5
                else "close to what this reference can tell; render it with more samples "
                "(`reference.spp`) to judge the fit further."
            )
        )
    best = best_known(summary["experiment"])
    if best is None:
        lines[0] += (
            f" No committed tradeoff covers the scene `{summary['experiment']}`: "
            "`study tradeoff` finds the best shader for it."
        )
    else:
        ahead = best["flip"] < flip["fitted"]
        lines[0] += (
            f" The best shader the committed tradeoff knows for `{summary['experiment']}` "
            f"within the original's fetches is `{best['label']}`, FLIP {best['flip']:.4f} "
            f"({best['folder']}): "
            + (
                f"{100 * (1 - best['flip'] / flip['fitted']):.0f} % less error than this fit."
                if ahead
                else "this fit is as good or better."
            )
        )
    where = str(out) if out is not None else "OUT"
    experiment = f"experiments/{summary['experiment']}.toml"
    lines += [
        "",
        "**Next.**",
        "",
        f"* Chart this scene's shaders, cost against error, and export the recommended one: "
        f"`study tradeoff {experiment} --out {where}-tradeoff` (the experiment file you "
        "calibrated).",
        f"* Export these constants to GLSL ES 3.00, HLSL, Metal and SPIR-V: "
        f"`study export {where}/constants.json --out {where}-export`.",
        f"* See the fitted water live beside the reference: open `{where}/viewer/index.html` "
        f"in a browser (`study viewer {where} {experiment}` writes it again).",
        "",
    ]
    return lines


def report_text(summary: dict, figures: dict, out: Path | None = None) -> str:
    """The Markdown of :func:`write_report` (``figures``: figure name -> file, those drawn;
    ``out``: the run's folder, for the commands it suggests)."""
    e = summary["error"]
    head = _header_lines(summary)
    lines = head[:2] + verdict_lines(summary, out) + head[2:] + waves_lines(summary.get("waves"))
    lines += _decorrelated_lines(summary.get("fit", {}))
    lines += [
        "| metric (water pixels) | default constants | fitted constants |",
        "|---|---|---|",
        f"| RMSE, linear RGB | {fmt(e['rmse']['default'])} | {fmt(e['rmse']['fitted'])} |",
        f"| FLIP (LDR, mean) | {fmt(e['flip']['default'])} | {fmt(e['flip']['fitted'])} |",
        "",
    ] + resolution_lines(summary)
    if "comparison" in figures:
        lines += [f"![reference | default | fitted, with error maps]({figures['comparison']})", ""]
    lines += ["## Constants", ""] + constants_table(summary["parameters"]) + [""]
    lines += basin_lines(summary["parameters"])
    lines += expects_lines(summary.get("textures"))
    lines += identifiability_section(summary)
    lines += _sweep_lines(summary.get("step_sweep"))
    if "loss" in figures:
        lines += ["## Convergence", "", f"![loss per iteration]({figures['loss']})", ""]
    if "diagnostics" in figures:
        lines += _diagnostics_lines(summary.get("diagnostics", {}), figures["diagnostics"])
    t = summary["timings"]
    lines += ["## Timings (seconds)", "", "| stage | s |", "|---|---|"]
    lines += [f"| {k} | {fmt(v, 3)} |" for k, v in t.items()] + [""]
    words = summary["export"]
    lines += _export_lines(summary.get("gl_check"), words["files"])
    lines += engine_targets_section(summary.get("engine_targets") or {}, words["constants"])
    return "\n".join(lines)


def waves_lines(waves: dict | None) -> list[str]:
    """What the report says of a reference whose waves are the shader's (``waves.source =
    "shader"``, the ``waves`` record of ``study.scene.shader_waves``); nothing otherwise."""
    if not waves:
        return []
    name, frame = waves["normal"]
    scale = waves["height_scale"]
    scaled = "" if scale == 1.0 else f", its height scaled by {scale:g} (`waves.height_scale`)"
    return [
        "## The reference's waves: the shader's own",
        "",
        f"The reference's water is the surface whose normals `{waves['shader']}` computes in "
        f"`{name}` ({frame} frame) at its start values, integrated in least squares over a "
        f"{waves['grid'][0]}x{waves['grid'][1]} grid of the water{scaled}; its RMS slope is "
        f"{waves['slope_rms']:.3g}. The shader's normals differ from that surface's by "
        f"{waves['curl_mean_deg']:.2f} degrees on average ({waves['curl_p99_deg']:.2f} at the "
        "99th percentile): the part of its normal field no surface has (its curl), which no "
        "reference can match.",
        "",
    ]


LOSS_WORDS = {
    "linear": 'the squared error in linear RGB (`fit.loss = "linear"`)',
    "log": 'the squared error of log(RGB + 0.02) (`fit.loss = "log"`)',
    "flip": "the mean FLIP at the fit's resolution, from the squared error's solution "
    '(`fit.loss = "flip"`)',
    "transport": "a quarter the squared error, three quarters the values matched within 8 x 8 "
    'tiles (`fit.loss = "transport"`)',
}


def loss_words(loss: str) -> str:
    """What the loss ``loss`` (``fit.loss``) is, in the report's words."""
    return LOSS_WORDS.get(loss, f"`fit.loss = {loss!r}`")


def _header_lines(summary: dict) -> list[str]:
    ref, res = summary["reference"], summary["fit_resolution"]
    return [
        f"# Calibration: {summary['experiment']} ({summary['shader']})",
        "",
        f"Reference: {spp_text(ref)}, measured noise {fmt(ref['noise'], 3)} "
        "(RMS standard error on "
        f"water pixels, linear RGB). Fit at {res[0]}x{res[1]}{footprint_words(summary)} "
        f"with `{summary['solver']}`, minimising {loss_words(summary.get('loss', 'linear'))}: "
        f"{fit_steps_line(summary)}",
        "",
    ]


def resolution_lines(summary: dict) -> list[str]:
    """Where the table's scores were taken, the fitted constants' score at the fit's resolution
    (``fit_error``: the image the fit saw), and the game's resolution when it is another;
    nothing for a result without ``fit_error`` (written before it was recorded)."""
    fe, res = summary.get("fit_error"), summary.get("resolution")
    if not fe or not res:
        return []
    fw, fh = summary["fit_resolution"]
    s = summary.get("supersample", 1)
    samples = f", {s}x{s} samples a pixel" if s > 1 else ""
    text = (
        f"Scored at the experiment's {res[0]}x{res[1]}, the reference's pixels. At the fit's "
        f"{fw}x{fh} (the image the fit saw{samples}, against the reference box-downsampled) the "
        f"fitted constants score FLIP {fmt(fe['flip'])}, RMSE {fmt(fe['rmse'])}."
    )
    target = summary.get("target_resolution")
    if target and list(target) != list(res):
        text += (
            f" The game's {target[0]}x{target[1]} is not scored here: "
            "`benchmarks/bench_resolution_transfer.py` path traces a reference at a game's "
            "resolution and scores fits there."
        )
    return [text, ""]


def footprint_words(summary: dict) -> str:
    """How a fit pixel was shaded, in the report's words: empty for one sample at its centre;
    else its samples and the game's resolution whose pixels they stand for."""
    s, target = summary.get("supersample", 1), summary.get("target_resolution")
    if s <= 1:
        return ""
    at = f" of {target[0]}x{target[1]}" if target else ""
    return f" ({s}x{s} samples a pixel, the pixel footprint{at}: `fit.target_resolution`)"


def fit_steps_line(summary: dict) -> str:
    """The solver's steps in one sentence: their total, and, when constants were frozen at the
    solution and the rest refitted, the steps of each round; the last round's stopping reason
    (its own steps, which a total over rounds would contradict)."""
    fit = summary.get("fit", {})
    per = fit.get("iterations_per_round") or []
    msg = summary["message"]
    said = summary["converged"] and msg.startswith("converged")  # the message says it already
    if len(per) > 1:
        rounds = " + ".join(str(n) for n in per)
        head = (
            f"{summary['iterations']} solver steps in {len(per)} rounds ({rounds}: a constant "
            "not identified at the solution is frozen and the rest refitted)"
        )
        if said:
            return f"{head}; the last round {msg}."
        state = "converged" if summary["converged"] else "NOT converged"
        return f"{head}, {state}; the last round stopped: {msg}."
    if said:
        return f"{summary['iterations']} solver steps, {msg}."
    state = "converged" if summary["converged"] else "NOT converged"
    return f"{summary['iterations']} solver steps, {state}: {msg}."


def _decorrelated_lines(fit: dict) -> list[str]:
    """The decorrelated refinement's paragraph (``fit.input_noise = "decorrelate"``), if any."""
    dec = fit.get("input_noise")
    if not dec:
        return []
    moved = ", ".join(f"{n} {fmt(a)} -> {fmt(b)}" for n, (a, b) in dec["shift"].items() if a != b)
    return [
        f'Texture noise (`fit.input_noise = "decorrelate"`): the least-squares constants refined '
        f"on the decorrelated loss over the refraction texture's two independent halves, "
        f"{fmt(dec['loss_start'])} -> {fmt(dec['loss'])} in {dec['steps']} damped Newton steps: "
        + (
            f"{dec['message']}; {moved or 'nothing moved'}."
            if dec["accepted"]
            else f"refused ({dec['message']}), the least-squares constants kept."
        ),
        "",
    ]


def _sweep_lines(sw: dict | None) -> list[str]:
    """The step schedule's sweep: a 1-D or 2-D table of the loss over the integer grid."""
    if not sw:
        return []
    lines = [
        "## Step schedule (sweep)",
        "",
        "Step counts change which step crosses the floor, so their effect is piecewise "
        "constant: they are chosen from a grid of the loss at the fitted continuous "
        f"constants, not by a gradient. Best: {sw['best']}.",
        "",
    ]
    if len(sw["names"]) == 2:
        a, b = sw["names"]
        lines += [
            f"| {a} \\ {b} | " + " | ".join(fmt(v) for v in sw["grid"][b]) + " |",
            "|---|" + "---|" * len(sw["grid"][b]),
        ]
        for va, row in zip(sw["grid"][a], sw["loss"]):
            lines.append(f"| {fmt(va)} | " + " | ".join(fmt(v) for v in row) + " |")
    else:
        (a,) = sw["names"]
        lines += [f"| {a} | loss |", "|---|---|"]
        lines += [f"| {fmt(v)} | {fmt(l)} |" for v, l in zip(sw["grid"][a], sw["loss"])]
    return lines + [""]


def _diagnostics_lines(d: dict, figure: str) -> list[str]:
    crossing = (
        f"Rays not crossing the floor within the loop cap: {fmt(d['not_crossed_fraction'])} "
        "of water pixels; "
        if "not_crossed_fraction" in d  # the seed's raycast (a user's shader may have none)
        else ""
    )
    return [
        "## Shader diagnostics (fitted constants)",
        "",
        f"{crossing}non-finite pixels: {d.get('nonfinite_pixels', '-')}; mean loop "
        f"iterations {fmt(d.get('iterations', {}).get('mean'))}, mean texture fetches "
        f"{fmt(d.get('fetches', {}).get('mean'))} per pixel.",
        "",
        f"![diagnostics]({figure})",
        "",
    ]


def gl_ran(gl: dict, default: str) -> str:
    """Which text the GL check ran on which context, in words (a user's shader's record has
    ``text`` and ``context``, ``why_translation`` when its translation ran); ``default`` for a
    record without them."""
    if not gl.get("text"):
        return default
    why = f" (not as written: {gl['why_translation']})" if gl.get("why_translation") else ""
    return f"the GL check ran {gl['text']} on {gl['context']}{why},"


def _export_lines(gl: dict | None, what: str) -> list[str]:
    """What was exported (``what``: the export's ``files`` in words, ``Shader.export_words``)
    and how the GL check of the exported core shader went."""
    check = "."
    if gl and gl.get("ran", True) is False:
        failed = "**FAILED**: " if gl.get("passed") is False else ""
        check = f"; {failed}not run on OpenGL ({gl['why']})."
    elif gl:
        check = (
            f"; {gl_ran(gl, 'the exported core shader on llvmpipe')} vs the Dr.Jit shader with "
            f"the fitted constants: mean |diff| {fmt(gl['mean_abs'], 3)}, 99.9th percentile "
            f"{fmt(gl['p999'], 3)}"
            + (
                "."
                if gl.get("passed")
                else " -- **MISMATCH: do not ship these shaders; see constants.json gl_check**."
            )
            + (f" ({gl['note']}.)" if gl.get("note") else "")
            + (
                f" Your file {own['note']}."
                if (own := gl.get("own_precision") or {}).get("note")
                else ""
            )  # fmt: skip
        )
    return ["## Exported shaders", "", what + check, ""]


def engine_targets_section(targets: dict, how: str) -> list[str]:
    """The report's "Engine targets" lines: each target written and what checked it; ``how``:
    how the targets carry the fitted constants, in words (``Shader.export_words``)."""
    if not targets:
        return []
    lines = [
        "## Engine targets",
        "",
        f"Translated from the core shader by glslang and SPIRV-Cross, {how}; the binding sheet "
        "of each is `shaders/<target>/BINDINGS.md` (see docs/engine.md).",
        "",
        "| target | files | checked by |",
        "|---|---|---|",
    ]
    for target, t in targets.items():
        if "left_out" in t:  # the pair has no translation to it
            lines.append(f"| {target} | - | left out: {t['left_out']} |")
            continue
        shaders = [f for f in t["files"] if not f.endswith((".json", ".md"))]
        check = t["check"]
        run = t.get("llvmpipe")
        if isinstance(run, dict) and run.get("ran", True) is False:
            check += f"; not run on llvmpipe ({run['why']})"
        elif isinstance(run, dict):
            how = run.get("context") or "llvmpipe through SPIR-V and GLSL 330"
            check += (
                f"; run on {how} vs the Dr.Jit shader: mean abs. difference "
                f"{fmt(run['mean_abs'], 3)}, 99.9th percentile {fmt(run['p999'], 3)} "
                + ("(passed)" if run["passed"] else "(**MISMATCH**)")
            )
        elif run:
            check += f"; {run}"
        lines.append(f"| {target} | {', '.join(f'`{f}`' for f in shaders)} | {check} |")
    return lines + [""]
