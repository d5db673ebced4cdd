"""The report of an animated calibration (``study.commands.animated``): the animation a person
watches, the temporal error maps and ``report.md`` with the per-frame and temporal tables.

Images are linear RGB (H, W, 3) float; the animation shows them sRGB-encoded and clipped to
[0, 1] (no tone mapping, as FLIP's LDR variant scores them), the error panel the LDR-FLIP map
of each frame (magma, 0 to 1) on the pixels that are water in every frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._io import to_srgb, write_text_atomic
from .._metrics import flip_map
from ..export.textures import expects_lines
from .calibration import constants_table, fit_steps_line, fmt, pyplot, waves_lines
from .identifiability import identifiability_table

PANELS = ("reference", "fitted (all frames)", "FLIP error")


def animation_frames(references: list, fitted: list, mask: np.ndarray) -> list[np.ndarray]:
    """One (H + 16, 3 W, 3) uint8 sRGB frame per animation frame: reference | fitted | the FLIP
    map of fitted against reference (magma, 0 outside ``mask``), each panel captioned."""
    from PIL import Image, ImageDraw

    cmap = pyplot().get_cmap("magma")
    out = []
    for k, (r, f) in enumerate(zip(references, fitted)):
        err = np.where(mask, flip_map(r, f), 0.0)
        panels = [to_srgb(r), to_srgb(f), cmap(np.clip(err, 0.0, 1.0))[..., :3]]
        h, w = r.shape[:2]
        body = np.concatenate([(p * 255 + 0.5).astype(np.uint8) for p in panels], axis=1)
        canvas = Image.new("RGB", (3 * w, h + 16), (0, 0, 0))
        canvas.paste(Image.fromarray(body), (0, 16))
        draw = ImageDraw.Draw(canvas)
        for j, label in enumerate(PANELS):
            text = f"{label}, frame {k}" if j == 0 else label
            draw.text((j * w + 4, 2), text, fill=(255, 255, 255))
        out.append(np.asarray(canvas))
    return out


SHOWN_S = 0.125  # seconds each frame is shown, at least: 8 frames at 30 fps would flash by


def shown_seconds(time_step: float) -> float:
    """Seconds each frame is shown: the animation's own ``time_step``, slowed to ``SHOWN_S``."""
    return max(float(time_step), SHOWN_S)


def write_animation(folder: Path, frames: list[np.ndarray], time_step: float) -> dict:
    """``animation.webp`` (quality 90) and ``animation.gif`` of ``frames`` (uint8 RGB), looping,
    each frame shown :func:`shown_seconds`; returns figure name -> file name."""
    from PIL import Image

    images = [Image.fromarray(f) for f in frames]
    ms = int(round(1000 * shown_seconds(time_step)))
    names = {"animation_webp": "animation.webp", "animation_gif": "animation.gif"}
    common = {"save_all": True, "append_images": images[1:], "duration": ms, "loop": 0}
    images[0].save(folder / names["animation_webp"], quality=90, method=6, **common)
    images[0].save(folder / names["animation_gif"], optimize=False, **common)
    return names


def temporal_figure(path: Path, maps: dict, mask: np.ndarray, title: str = "") -> Path:
    """Three panels, one shared colour scale: the reference's frame-to-frame change, the
    shader's, and the RMS of their difference (where the shader flickers unlike the water)."""
    plt = pyplot()
    keys = [
        ("reference", "reference: RMS of R[k+1] - R[k]"),
        ("shader", "shader: RMS of S[k+1] - S[k]"),
        ("flicker", "RMS of (S[k+1] - S[k]) - (R[k+1] - R[k])"),
    ]
    # the 99.5th percentile: a few glint pixels would otherwise set the scale for all
    vmax = max(max(float(np.percentile(maps[k][mask], 99.5)) for k, _ in keys), 1e-6)
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 3.9))
    for ax, (k, label) in zip(axes, keys):
        im = ax.imshow(np.where(mask, maps[k], np.nan), cmap="magma", vmin=0, vmax=vmax)
        ax.set_title(label, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(im, ax=axes.tolist(), shrink=0.8, label="linear RGB (clipped at p99.5)")
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def animation_figures(out: Path, refs: list, ev: dict, time_step: float) -> dict:
    """The animation (reference | all-frames fit | FLIP error) and ``temporal.png`` of the
    all-frames fit in ``out``; returns figure name -> file name."""
    frames = animation_frames([r.image for r in refs], ev["images"]["all_frames"], ev["mask"])
    figs = write_animation(out, frames, time_step)
    figs["temporal"] = "temporal.png"
    temporal_figure(
        out / figs["temporal"],
        ev["scores"]["all_frames"]["maps"],
        ev["mask"],
        title="frame-to-frame change on the water, constants fitted on all frames",
    )
    return figs


ROWS = (
    ("start", "start constants"),
    ("single_frame", "fitted on frame 0 alone"),
    ("all_frames", "fitted on all frames"),
)


def per_frame_table(scores: dict) -> list[str]:
    """FLIP of every frame under each constants block, then the mean and the spread."""
    n = len(scores["start"]["flip"])
    lines = [
        "| constants | " + " | ".join(f"frame {k}" for k in range(n)) + " | mean | spread |",
        "|---|" + "---|" * (n + 2),
    ]
    for key, label in ROWS:
        s = scores[key]
        cells = " | ".join(fmt(v) for v in s["flip"])
        lines.append(f"| {label} | {cells} | {fmt(s['flip_mean'])} | {fmt(s['flip_spread'])} |")
    return lines


def temporal_table(scores: dict) -> list[str]:
    """The temporal error of each constants block (``study._metrics.temporal_errors``)."""
    lines = [
        "| constants | temporal RMSE | beyond the noise | shader change | reference change | "
        "... without its noise | change ratio | ... to the noise-free change | mean RMSE |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for key, label in ROWS:
        t, s = scores[key]["temporal"], scores[key]
        lines.append(
            f"| {label} | {fmt(t['trmse'])} | {fmt(t.get('trmse_excess'))} | "
            f"{fmt(t['shader_change'])} | {fmt(t['reference_change'])} | "
            f"{fmt(t.get('reference_change_excess'))} | {fmt(t['change_ratio'], 3)} | "
            f"{fmt(t.get('change_ratio_excess'), 3)} | {fmt(s['rmse_mean'])} |"
        )
    return lines


def noise_sentence(t: dict) -> str:
    """What the reference's Monte Carlo noise contributes to its frame-to-frame change."""
    out = ""
    if t.get("noise") is not None:
        out += (
            f" The reference's own noise in R[k+1] - R[k], measured from its passes over "
            f"{t['noise_pairs']} frame pair(s), is {fmt(t['noise'])} RMS (the frames share their "
            "sampler seeds, so part of it cancels); 'beyond the noise' is "
            "sqrt(temporal RMSE^2 - noise^2), the reference's change without its noise "
            "sqrt(change^2 - noise^2)."
        )
    if t.get("noise_floor") is not None:
        out += f" With independent frames it would be {fmt(t['noise_floor'])}."
    return out


def write_animation_report(out: Path, summary: dict) -> Path:
    """``out/report.md`` of an animated calibration (the content of constants.json)."""
    path = Path(out) / "report.md"
    write_text_atomic(path, animation_report_text(summary))
    return path


def animation_report_text(summary: dict, gif: bool = True) -> str:
    """The Markdown of :func:`write_animation_report` (also the docs' generated page, which
    leaves out the link to the GIF: ``gif = False``)."""
    a = summary["animation"]
    sc, figs = a["scores"], a["figures"]
    n = a["frames"]
    lines = [
        f"# Animated calibration: {summary['experiment']} ({summary['shader']}), {n} frames",
        "",
        f"{n} frames {a['time_step']:.4g} s apart; the four normal-map layers move at "
        f"{a['velocities']} texture units per second, the reference's surface with them. One "
        f"constants block fitted on all frames (joint fit, each frame weighted equally), solver "
        f"`{summary['solver']}`: {fit_steps_line(summary)} Frame 0 fitted alone the same way, "
        "for comparison. Errors on the water pixels at full resolution.",
        "",
        f"![reference | fitted | FLIP error, {n} frames]({figs['animation_webp']})",
        "",
        f"Each frame shown {shown_seconds(a['time_step']):.3g} s"
        + (" (slowed down)" if shown_seconds(a["time_step"]) > a["time_step"] else "")
        + (f"; also as [GIF]({figs['animation_gif']})" if gif and "animation_gif" in figs else "")
        + ".",
        "",
    ]
    lines += waves_lines(summary.get("waves")) + ["## FLIP per frame", ""]
    lines += per_frame_table(sc) + [""]
    lines += [
        "## Temporal error",
        "",
        f"On the {a['mask_pixels']} pixels that are water in every frame, linear RGB: temporal "
        "RMSE is the RMS of (S[k+1] - S[k]) - (R[k+1] - R[k]) over the frame pairs (0: the shader "
        "changes as the reference does); the change ratio is the shader's RMS frame-to-frame "
        "change over the reference's (below 1: too still; above 1: flickers more than the water)."
        + noise_sentence(sc["all_frames"]["temporal"]),
        "",
    ]
    lines += temporal_table(sc) + ["", f"![temporal error maps]({figs['temporal']})", ""]
    lines += ["## Constants (fitted on all frames)", ""]
    lines += constants_table(summary["parameters"]) + [""]
    losses = a.get("losses")
    if losses:
        lines += [
            "The fit's loss (0.5 |r|^2 at the fit resolution) of each block, over all frames and "
            "on frames 1 and later (the frames frame 0's fit did not see):",
            "",
            "| constants | all frames | frames 1.. |",
            "|---|---|---|",
        ]
        for key, label in ROWS:
            lo = losses[key]
            lines.append(
                f"| {label} | {fmt(lo['all_frames'])} | {fmt(float(sum(lo['per_frame'][1:])))} |"
            )
        lines += [""]
    lines += ["| constant | frame 0 alone | all frames |", "|---|---|---|"]
    single = a["single_frame"]["parameters"]
    for name, p in summary["parameters"].items():
        lines.append(
            f"| {name} | {fmt(single.get(name, {}).get('fitted'))} | {fmt(p.get('fitted'))} |"
        )
    lines += ["", "## Identifiability (all frames)", ""]
    lines += identifiability_table(summary["identifiability"], summary["parameters"]) + [""]
    lines += _export_lines(summary, a)
    lines += expects_lines(summary.get("textures"))
    sh = a["shared"]
    lines += [
        "## Timings (seconds)",
        "",
        "Built once for all frames: "
        + (", ".join(sh["built_once"]) or "nothing (all cached)")
        + ".",
        "",
        "| stage | s |",
        "|---|---|",
    ]
    t = summary["timings"]
    lines += [f"| {k} | {fmt(v, 3)} |" for k, v in t.items() if not k.startswith("frame")]
    for what in ("reference_s", "inputs_s"):
        per = [fmt(t[f"frame{k}.{what}"], 3) for k in range(n) if f"frame{k}.{what}" in t]
        lines.append(f"| {what} per frame | {', '.join(per)} |")
    refs = a.get("references") or []
    if refs:
        noise = np.mean([r["noise"] for r in refs])
        lines += ["", f"References: {refs[0]['spp']} spp a frame, mean noise {fmt(noise, 3)}."]
    return "\n".join(lines) + "\n"


def _export_lines(summary: dict, a: dict) -> list[str]:
    gl = summary.get("gl_check") or {}
    frames = gl.get("frames", [])
    worst = max((f["mean_abs"] for f in frames if f.get("mean_abs") is not None), default=None)
    return [
        "## Exported shaders",
        "",
        "`shaders/` holds the shaders with the all-frames constants; the vertex shader takes the "
        "layer offsets as its `wave1..wave4` uniforms, and `shaders/animation.json` gives their "
        "value per frame (wave_i(t) = offsets[i] + t velocities[i]). GL check (llvmpipe against "
        f"the port) on each of the {len(frames)} frames with its own uniforms: worst mean |diff| "
        f"{fmt(worst, 3)}, {'passed' if gl.get('passed') else '**MISMATCH: do not ship**'}.",
        "",
    ]
