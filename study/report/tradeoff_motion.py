"""The motion part of the tradeoff report (``study.studies.tradeoff_motion``): ``motion.png``
(per animated scene, the mean FLIP over the frames and the temporal RMSE against texture fetches
per water pixel, one colour per shader, both recommendations marked) and the section of
``report.md`` (every point on every frame, the schedules that band, whether motion changes the
recommendation)."""

from __future__ import annotations

from pathlib import Path

from .calibration import fmt, pyplot

COST = "fetches_mean"


def motion_figure(path: Path, summary: dict) -> Path | None:
    """``motion.png`` from the summary's ``scenes[name]["motion"]``; None when no scene has
    one."""
    scenes = [(n, f["motion"]) for n, f in summary["scenes"].items() if f.get("motion")]
    if not scenes:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(len(scenes), 2, figsize=(14, 4.6 * len(scenes)), squeeze=False)
    for i, (name, m) in enumerate(scenes):
        pts = [p for p in m["points"] if p.get(COST) is not None]
        variants = list(dict.fromkeys(p["variant"] for p in pts))
        colours = {v: plt.cm.tab20(k % 20) for k, v in enumerate(variants)}
        for j, (key, label) in enumerate(
            (("flip_frames_mean", "FLIP on water pixels, mean over the frames"),
             ("trmse", "temporal RMSE (frame-to-frame change)"))
        ):  # fmt: skip
            ax = axes[i, j]
            for p in pts:
                ax.scatter(p[COST], p[key], color=colours[p["variant"]], s=22,
                           marker="*" if p["kind"] == "converged" else "o",
                           label=p["variant"])  # fmt: skip
            for lab, marker, colour, text in (
                (m["still"], "x", "red", "recommended on frame 0"),
                ((m["recommended"] or {}).get("label"), "+", "green", "recommended in motion"),
            ):
                for p in pts:
                    if p["label"] == lab and p["kind"] != "converged":
                        ax.scatter(p[COST], p[key], marker=marker, s=140, color=colour,
                                   label=text)  # fmt: skip
            ax.set_xscale("log")
            ax.set_xlabel("texture fetches / water pixel (mean)", fontsize=9)
            ax.set_ylabel(label, fontsize=9)
            ax.set_title(f"{name} ({m['frames']} frames)" if j == 0 else "", loc="left",
                         fontsize=10)  # fmt: skip
            ax.grid(alpha=0.3, which="both")
        handles, labels = axes[i, 0].get_legend_handles_labels()
        seen = dict(zip(labels, handles))
        axes[i, 1].legend(seen.values(), seen.keys(), fontsize=7, loc="upper left",
                          bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def motion_lines(m: dict | None) -> list[str]:
    """The section of one animated scene (``summary["scenes"][name]["motion"]``)."""
    if not m:
        return []
    lines = [
        "",
        f"### In motion ({m['frames']} frames)",
        "",
        "Every point measured in full, its constants as fitted on frame 0, rendered on every "
        "frame against that frame's reference: FLIP per frame (mean and spread over the "
        "frames) and the temporal error on the pixels that are water in every frame (the RMS of "
        "the shader's frame-to-frame change minus the reference's; beyond the reference's own "
        "noise; the change ratio: the shader's change over the water's).",
        "",
        "| shader (schedule) | fetches | FLIP frame 0 | FLIP mean (spread) | temporal RMSE | "
        "beyond noise | change ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in m["points"]:
        lines.append(
            f"| {p['label']}{' (converged)' if p['kind'] == 'converged' else ''} | "
            f"{fmt(p.get(COST), 3)} | {fmt(p['flip'])} | {fmt(p['flip_frames_mean'])} "
            f"({fmt(p['flip_frames_spread'], 2)}) | {fmt(p['trmse'])} | "
            f"{fmt(p.get('trmse_excess'))} | {fmt(p.get('change_ratio'), 3)} |"
        )
    if m["banding"]:
        lines += [
            "",
            "Each schedule against its own constants with the raymarch converged (the same "
            "shader without step artefacts), paired over the frame pairs: the difference of "
            "the mean squared temporal error +- its standard error, and of the temporal RMSE "
            "(relative); *bands* when it is larger by more than the search's noise margin and "
            "by more than the tolerance:",
            "",
            "| shader (schedule) | fetches | temporal RMSE | converged | difference (MS) | "
            "relative | bands |",
            "|---|---|---|---|---|---|---|",
        ]
        for b in m["banding"]:
            se = "-" if b["se_ms"] is None else f"{b['se_ms']:.1e}"
            lines.append(
                f"| {b['label']} | {fmt(b.get(COST), 3)} | {fmt(b['trmse'])} | "
                f"{fmt(b['floor_trmse'])} | {b['d_ms']:+.2e} +- {se} | {100 * b['rel']:+.2f} % | "
                f"{'**yes**' if b['bands'] else 'no'} |"
            )
    rec = m["recommended"]
    lines += [""]
    if rec:
        lines.append(
            f"**Recommended in motion**: {rec['label']} (the cheapest point within the "
            f"tolerance of the best mean FLIP over the frames and of the best temporal RMSE): "
            f"mean FLIP {fmt(rec['flip_frames_mean'])}, temporal RMSE {fmt(rec['trmse'])} at "
            f"{fmt(rec.get(COST), 3)} fetches. On frame 0 alone: {m['still'] or '-'}. "
            f"{m['why'][0].upper() + m['why'][1:]}."
        )
    lines.append(
        "Schedules that band in motion: " + (", ".join(m["bands"]) if m["bands"] else "none") + "."
    )
    lines += ["", "![in motion: error over the frames and temporal error](motion.png)"]
    return lines
