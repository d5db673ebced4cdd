"""Figures and ``stability.md`` of ``study stability`` (inputs: the study's JSON-able summary,
``study.studies.stability``). Times in seconds of wall clock on the machine that ran the jobs."""

from __future__ import annotations

from pathlib import Path

from .._io import write_text_atomic
from .calibration import fmt, pyplot


def solver_figure(path: Path, ms: dict) -> Path:
    """Success rate against median time to stop, one point per reported solver."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.8, 4.0))
    for label in ms["reported"]:
        s = ms["solvers"][label]
        t = s["time_to_stop_median"]
        if t is None:
            continue
        ax.scatter([t], [s["success_rate"]], s=40)
        ax.annotate(
            label, (t, s["success_rate"]), fontsize=8, xytext=(4, 4), textcoords="offset points"
        )
    ax.set_xscale("log")
    ax.set_xlabel("median time to stop (s)")
    ax.set_ylabel("success rate (final loss within 0.1 % of the best)")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("solvers from Latin-hypercube starts")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def spread_figure(path: Path, ms: dict) -> Path:
    """Relative spread (std / |median| over the runs, median over scenes) per constant and
    solver."""
    import numpy as np

    plt = pyplot()
    labels = ms["reported"]
    names = sorted({n for l in labels for n in ms["solvers"][l]["rel_spread"]})
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(names) + 2), 4.0))
    w = 0.8 / max(len(labels), 1)
    x = np.arange(len(names))
    for i, l in enumerate(labels):
        v = [ms["solvers"][l]["rel_spread"].get(n, np.nan) for n in names]
        ax.bar(x + i * w, np.maximum(v, 1e-6), w, label=l)
    ax.set_xticks(x + 0.4 - w / 2)
    ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("relative spread of the fitted value")
    ax.legend(fontsize=7)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def noise_figure(path: Path, noise: dict) -> Path:
    """Bias against the highest spp, with its standard error, per constant, against spp."""
    plt = pyplot()
    whichs = [w for w in ("reference", "texture") if w in noise]
    fig, axes = plt.subplots(
        1, max(len(whichs), 1), figsize=(5.5 * max(len(whichs), 1), 4.0), squeeze=False
    )
    for ax, which in zip(axes[0], whichs):
        d = noise[which]
        # spp -> stats; keyed by str once the summary has been through JSON
        stats = {int(k): v for k, v in d["stats"].items()}
        names = sorted({n for s in stats.values() for n in s})
        for n in names:
            xs, ys, es = [], [], []
            for spp in d["levels"]:
                st = stats[spp].get(n)
                if st is None or "bias" not in st:
                    continue
                scale = abs(stats[d["levels"][-1]][n]["mean"]) or 1.0
                xs.append(spp)
                ys.append(st["bias"] / scale)
                es.append((st.get("bias_se") or 0.0) / scale)
            ax.errorbar(xs, ys, yerr=es, marker="o", capsize=3, label=n)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xscale("log", base=2)
        ax.set_xlabel(f"{which} spp")
        ax.set_ylabel(f"relative bias vs {d['levels'][-1]} spp")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def solver_table(ms: dict) -> list[str]:
    lines = [
        "| solver | runs | success rate | time to target median / p90 (s) | time to "
        "stop median / p90 (s) "
        "| median iterations | failures |",
        "|---|---|---|---|---|---|---|",
    ]
    for label in ms["reported"]:
        s = ms["solvers"][label]
        fails = (
            ", ".join(f"{k} {v}" for k, v in sorted(s["classes"].items()) if k != "success") or "-"
        )
        lines.append(
            f"| {label} | {s['runs']} | {fmt(s['success_rate'], 3)} | "
            f"{fmt(s['time_to_target_median'], 3)}"
            f" / {fmt(s['time_to_target_p90'], 3)} | {fmt(s['time_to_stop_median'], 3)} / "
            f"{fmt(s['time_to_stop_p90'], 3)} | {fmt(s['iterations_median'], 3)} | {fails} |"
        )
    return lines


def spread_table(ms: dict) -> list[str]:
    labels = ms["reported"]
    names = sorted({n for l in labels for n in ms["solvers"][l]["rel_spread"]})
    lines = ["| constant | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for n in names:
        lines.append(
            f"| `{n}` | "
            + " | ".join(fmt(ms["solvers"][l]["rel_spread"].get(n), 2) for l in labels)
            + " |"
        )
    return lines


def write_stability_report(out: Path, summary: dict) -> Path:
    """``out/stability.md`` of :func:`stability_report_text`."""
    path = Path(out) / "stability.md"
    write_text_atomic(path, stability_report_text(summary))
    return path


def stability_report_text(summary: dict) -> str:
    """The Markdown of ``stability.md`` from the study's ``summary.json``: one section per phase
    run, and the command that reproduces it."""
    lines = ["# Stability where methods fail", ""]
    if summary.get("command"):
        lines += [f"Reproduce: `{summary['command']}`", ""]
    lines += _multistart_lines(summary.get("multistart"))
    lines += _loss_lines(summary.get("loss"))
    lines += _noise_lines(summary.get("noise"))
    return "\n".join(lines)


def _multistart_lines(ms: dict | None) -> list[str]:
    if not ms:
        return []
    lines = []
    lines += [
        "## Solvers from many starts",
        "",
        f"{ms['starts']} Latin-hypercube starts per scene and solver; success: final loss within "
        f"0.1 % of the best loss of all runs on the scene; step cap {ms['max_steps']} "
        f"(Nelder-Mead {ms['nm_steps']}); Adam at learning rates {ms['adam_lrs']}, reported at the "
        f"best ({ms['best_adam']}).",
        "",
    ]
    for row in ms.get("left_out", []):
        lines += [f"Left out: {row['solver']} on {row['scene']} ({row['why']}).", ""]
    lines += solver_table(ms) + [
        "",
        "![success rate against median time](solvers.png)",
        "",
        "Relative spread of each fitted constant (std / |median| over the runs, "
        "median over scenes):",
        "",
    ]
    lines += spread_table(ms) + ["", "![spread](spread.png)", ""]
    if any(k.startswith("adam") for k in ms["solvers"]):
        lines += [
            "Adam's learning-rate sweep:",
            "",
            "| learning rate | success rate | median time to stop (s) |",
            "|---|---|---|",
        ]
        for k, s in ms["solvers"].items():
            if k.startswith("adam"):
                lines.append(
                    f"| {k} | {fmt(s['success_rate'], 3)} | {fmt(s['time_to_stop_median'], 3)} |"
                )
        lines.append("")
    return lines


def _loss_lines(ls: dict | None) -> list[str]:
    if not ls:
        return []
    lines = []
    lines += [
        "## Which residual",
        "",
        "FLIP (water pixels, full resolution) of each scene calibrated with the "
        "linear-RGB residual and the log residual (`study.fit.losses`).",
        "",
        "| scene | FLIP linear | FLIP log | RMSE linear | RMSE log |",
        "|---|---|---|---|---|",
    ]
    for scene, d in ls["per_scene"].items():
        a, b = d.get("linear", {}), d.get("log", {})
        lines.append(
            f"| {scene} | {fmt(a.get('flip'))} | {fmt(b.get('flip'))} | {fmt(a.get('rmse'))} | "
            f"{fmt(b.get('rmse'))} |"
        )
    lines += [
        "",
        f"Mean FLIP: linear {fmt(ls['mean_flip']['linear'])}, log {fmt(ls['mean_flip']['log'])}; "
        f"scenes won: {ls['wins']}; lower mean FLIP: **{ls['winner']}**.",
        "",
    ]
    return lines


def _noise_lines(nz: dict | None) -> list[str]:
    if not nz:
        return []
    lines = []
    lines += [
        "## Noise of the references and textures",
        "",
        f"{nz['seeds']} seeds per level at {nz['resolution']}x{nz['resolution']}; "
        "the other spp held at "
        f"{nz['fixed_spp']}. Bias against the highest level +- its standard error (seeds).",
        "",
    ]
    for which in ("reference", "texture"):
        d = nz.get(which)
        if not d:
            continue
        names = sorted({n for s in d["stats"].values() for n in s})
        lines += [
            f"### {which} spp (cheapest agreeing with {d['levels'][-1]} within one standard error: "
            f"**{d['cheapest_agreeing']}**)",
            "",
            "| spp | " + " | ".join(f"`{n}`" for n in names) + " | all agree |",
            "|---|" + "---|" * len(names) + "---|",
        ]
        # levels key the tables as numbers in a run and as strings once read from summary.json
        stats = {str(k): v for k, v in d["stats"].items()}
        agrees = {str(k): v for k, v in d["agrees"].items()}
        for spp in d["levels"]:
            cells = []
            for n in names:
                st = stats[str(spp)].get(n, {})
                cells.append(
                    f"{fmt(st.get('mean'))} ({fmt(st.get('bias'), 2)} +- "
                    f"{fmt(st.get('bias_se'), 2)})"
                )
            lines.append(
                f"| {spp} | " + " | ".join(cells) + f" | {'yes' if agrees[str(spp)] else 'no'} |"
            )
        lines.append("")
    lines += ["![bias against spp](noise.png)", ""]
    return lines
