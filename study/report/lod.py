"""The level-of-detail part of the tradeoff report: ``lod.png`` (per scene, the full rung's
single points and their front beside the front of band policies, FLIP against mean texture
fetches per water pixel, the single point and the policy chosen against it marked, and the
policy drawn as one shader) and the report's "Level of detail" lines. Both read
``summary["scenes"][scene]["lod"]`` (``study.studies.lod.scene_policies``, with the drawn
policy's ``export``)."""

from __future__ import annotations

from pathlib import Path

from .calibration import pyplot
from .numbers import fmt


def lod_figure(path: Path, summary: dict) -> Path | None:
    """Draw the chart of the module doc into ``path`` (PNG, 110 dpi); None when no scene has a
    level-of-detail finding (a chart of an earlier run at ``path`` is removed)."""
    scenes = [(n, s["lod"]) for n, s in summary["scenes"].items() if s.get("lod")]
    if not scenes:
        Path(path).unlink(missing_ok=True)
        return None
    plt = pyplot()
    from matplotlib import ticker  # local: matplotlib is loaded by pyplot() only when drawing

    fig, axes = plt.subplots(1, len(scenes), figsize=(5.6 * len(scenes), 4.4), squeeze=False)
    for ax, (name, lod) in zip(axes[0], scenes):
        singles = lod["single_front"]
        ax.step([p["fetches"] for p in singles], [p["flip"] for p in singles], where="post",
                color="0.4", label="single points' front")  # fmt: skip
        ax.plot([p["fetches"] for p in lod["front"]], [p["flip"] for p in lod["front"]], ".",
                color="tab:blue", ms=4, label="band policies' front")  # fmt: skip
        s, p = lod["single"], lod["policy"]
        ax.plot([s["fetches"]], [s["flip"]], "D", color="0.1",
                label=f"single point (cheapest within the tolerance): {s['label']}")  # fmt: skip
        if p:
            ax.plot([p["fetches"]], [p["flip"]], "*", color="tab:red", ms=12,
                    label=f"policy, {len(p['bands'])} bands by {p['measure']}")  # fmt: skip
        e = lod.get("export") or {}
        if "flip" in e:
            ax.plot([e["fetches"]], [e["flip"]], "*", mfc="none", color="tab:red", ms=14,
                    label="the policy drawn as one shader (margins paid)")  # fmt: skip
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(ticker.NullFormatter())
        lo, hi = ax.get_xlim()
        ax.set_xticks([t for t in (1, 2, 3, 5, 10, 20, 30, 50, 100, 200) if lo <= t <= hi])
        ax.set_xlabel("texture fetches / water pixel (mean)")
        ax.set_ylabel(f"FLIP at {lod['resolution'][0]}x{lod['resolution'][1]}")
        ax.set_title(name)
        ax.legend(fontsize=7, loc="best")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


#: how the table of :func:`lod_table` is made, in words (the report and the docs' page)
METHOD = (
    "The water split into bands by what a pixel needs (its distance to the camera, or its "
    "footprint on the water), each band given one point measured in full (at the "
    "experiment's resolution, with the point's fitted constants; the adaptive search sends the "
    "bands of the policy its screen's maps choose to the full rung too); bounds at deciles of "
    "the measure, up to 5 bands. FLIP and fetches from the points' per-pixel maps. The "
    "*single point* is the one a user would take by the recommendation's rule: the cheapest "
    "within the tolerance (2 %) of the lowest FLIP. Beside it, the cheapest policy of two bands "
    "or more whose FLIP is above the single point's by no more than one paired standard "
    "error; *ratio*, the policy's mean fetches per water pixel over the single point's. "
    "*Held out*: the same choice made on half the water's 4 x 4-pixel blocks (a "
    "checkerboard) and scored on the other half: the policy's FLIP above the single point's "
    "there, with its paired standard error, and the ratio of fetches there. *Drawn*: the "
    "policy as one shader, rendered and scored (below). Bands pay where both the held-out and "
    "the drawn policy are within one standard error at a ratio of 0.8 or less. *Against the "
    "lowest*: the same policy against the lowest-FLIP point, whose fetches a cheaper single "
    "point within the tolerance undercuts too. Each band keeps its point's constants fitted "
    "on the whole view."
)

#: how the drawn policy's table (:func:`export_table`) is made, in words
EXPORT_METHOD = (
    "The chosen policy as one GLSL file (`policy/policy.frag`, with the engine targets and "
    "their binding sheets; for an engine that switches shaders itself, each band's own file "
    "in `policy/bands/` and their table, `policy/BANDS.md`), drawn by the port at the "
    "experiment's resolution with the narrowest of four blend margins that shows no seam: "
    "its FLIP above the single point's (paired standard error), its fetches (a pixel in a "
    "margin pays for both bands) over the single point's; *seam*, FLIP in a strip 8 pixels "
    "wide each side of every boundary between bands, over the bands' own FLIP there (each "
    "pixel's FLIP in its band's own image; above 1.1 a seam shows); *GL check*, the file and "
    "its HLSL run on OpenGL (llvmpipe) against the port's mix of its bands, with every "
    "export's thresholds."
)


def lod_table(rows: list[tuple[str, dict]]) -> list[str]:
    """The Markdown table of level-of-detail findings: a row per (scene cell, ``lod`` of
    ``study.studies.lod.scene_policies``)."""
    lines = [
        "| scene | lowest FLIP | single point (cheapest within the tolerance) | its FLIP "
        "| its fetches "
        "| policy (bands, nearest first) | its FLIP | its fetches | ratio "
        "| held out: FLIP above | ratio | drawn: FLIP above | ratio "
        "| against the lowest: FLIP above, ratio | pays |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for scene, lod in rows:
        b, s, p = lod["best"], lod["single"], lod["policy"]
        if p is None:
            cells = ["none within the margin", "", "", ""]
        else:
            unit = "world units" if p["measure"] == "distance" else "square world units"
            bands = "; ".join(
                f"{label} ({100 * share:.0f} %" + (f", to {x:.3g}" if x is not None else "") + ")"
                for label, share, x in zip(p["bands"], p["shares"], [*p["bounds"], None])
            )
            flip = f"{fmt(p['flip'], 4)} ± {fmt(p['se'], 2)}"
            cells = [f"by {p['measure']} ({unit}): {bands}", flip, fmt(p["fetches"], 3),
                     fmt(lod["fetch_ratio"], 3)]  # fmt: skip
        h = lod.get("held_out")
        cells += ([f"{fmt(h['d_flip'], 2)} ± {fmt(h['se'], 2)}", fmt(h["fetch_ratio"], 3)]
                  if h else ["", ""])  # fmt: skip
        e = lod.get("export") or {}
        cells += ([f"{fmt(e['d_flip'], 2)} ± {fmt(e['se'], 2)}", fmt(e["fetch_ratio"], 3)]
                  if "d_flip" in e else [e.get("error", ""), ""])  # fmt: skip
        a = lod.get("against_best")
        cells.append(f"{fmt(a['d_flip'], 2)} ± {fmt(a['se'], 2)}, {fmt(a['fetch_ratio'], 3)}"
                     if a else "")  # fmt: skip
        lines.append(
            f"| {scene} | {fmt(b['flip'], 4)} ({b['label']}) | {s['label']} | "
            f"{fmt(s['flip'], 4)} | {fmt(s['fetches'], 3)} | "
            + " | ".join([*cells, "yes" if pays(lod) else "no"])
            + " |"
        )
    return lines


def pays(lod: dict) -> bool:
    """Whether bands pay on a scene: the held-out choice reaches (``lod["reaches"]``) and so
    does the drawn policy where it was drawn (its ``export``)."""
    e = lod.get("export")
    return bool(lod["reaches"] and (e is None or e.get("reaches")))


def export_table(rows: list[tuple[str, dict]], files=None) -> list[str]:
    """The Markdown table of the drawn policies: a row per (scene cell, ``lod``) with an
    ``export`` (``study.studies.lod_export.export_policy``'s record). ``files``: the last
    cell of a row from its ``export`` (default: the folder it was written to)."""
    files = files or (lambda e: f"`{e.get('folder', '')}/`")
    lines = [
        "| scene | bands (margin) | FLIP drawn | above the single point | fetches drawn | ratio "
        "| seam (worst boundary) | GL check (GLSL's mean, 99.9th pct) | files |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for scene, lod in rows:
        e = lod.get("export")
        if not e or "flip" not in e:
            continue
        gl = e["gl_check"]
        verdict = ", ".join(
            f"{what} " + ("passed" if c["passed"] else f"FAILED: {c['reason']}")
            for what, c in (("GLSL", gl), ("HLSL", e.get("hlsl_check")))
            if c is not None
        )
        seam = fmt(e["seam_ratio"], 3) if e["seam_ratio"] is not None else "no boundary"
        cells = [
            scene,
            f"{len(e['bands'])} by {e['measure']} (±{fmt(e['margin'], 2)} in the log)",
            fmt(e["flip"], 4),
            f"{fmt(e['d_flip'], 2)} ± {fmt(e['se'], 2)}",
            fmt(e["fetches"], 3),
            fmt(e["fetch_ratio"], 3),
            seam,
            f"{verdict} ({fmt(gl['mean_abs'], 2)}, {fmt(gl['p999'], 2)})",
            files(e),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def lod_lines(summary: dict) -> list[str]:
    """The report's "Level of detail" section (no lines when no scene has a finding)."""
    scenes = [(n, s["lod"]) for n, s in summary["scenes"].items() if s.get("lod")]
    if not scenes:
        return []
    return [
        "## Level of detail",
        "",
        METHOD,
        "",
        *lod_table(scenes),
        "",
        "![Band policies against single points](lod.png)",
        "",
        *(
            ["### The policy drawn", "", EXPORT_METHOD, "", *export_table(scenes), ""]
            if any((lod.get("export") or {}).get("flip") is not None for _, lod in scenes)
            else []
        ),
    ]
