"""The tradeoff report: ``pareto.png`` (error against each cost measure, every point drawn, the
Pareto front, the original shader's schedule and the recommendation marked, one colour per
variant, a row of panels per scene, a user's own shader a labelled diamond, a budget a dashed
line) and ``report.md`` (the fronts as tables, the recommendation, where a user's shader stands,
what each scene needs, each halving of the original's schedule)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from shaders_port import space as _space

from .._io import write_text_atomic
from .calibration import fmt, gl_ran, pyplot
from .lod import lod_lines
from .tradeoff_motion import motion_lines

COSTS = {
    "fetches_mean": "texture fetches / water pixel (mean)",
    "gl_norm_ms_1080p": "llvmpipe ms / frame, 1920x1080 (normalised)",
    "port_ms_512": "Dr.Jit port ms / frame, 512x512 (the run's backend)",
}
MARKERS = {"grid": "o", "scale": "s", "converged": "*", "fixed": "D"}
# the side-by-side's panel of the original shader at its own constants: the baseline of every
# "x times the original's error" the report gives
ORIGINAL_PANEL = "original shader, its own constants"


def pareto_figure(path: Path, recs: list, summary: dict) -> Path:
    """Draw :func:`pareto_chart` into ``path`` (PNG, 110 dpi)."""
    plt = pyplot()
    fig = pareto_chart(recs, summary)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def pareto_chart(recs: list, summary: dict):
    """The chart of the module doc as a matplotlib figure: a row of panels per scene, a column
    per cost measure of :data:`COSTS` (log x, plain-number ticks), FLIP on y. ``recs``: the
    successful points (``experiment``, ``variant``, ``kind``, ``scale``, ``label``, ``flip`` and
    the cost measures); the fronts are ``summary["scenes"][scene]["fronts_by_cost"]`` (labels,
    cheapest first); ``summary["budget"]`` (cost -> limit), when set, a dashed vertical line on
    its panel. The converged raymarch (star) is drawn but is not a candidate. One legend, beside
    the first row's last panel, lists what is drawn and nothing else; every drawn artist
    carries its legend entry as its ``gid``."""
    plt = pyplot()
    scenes = list(summary["scenes"])
    variants = list(dict.fromkeys(r["variant"] for r in recs))
    colours = {v: plt.cm.tab20(i % 20) for i, v in enumerate(variants)}
    fig, axes = plt.subplots(
        len(scenes), len(COSTS), figsize=(5.2 * len(COSTS), 4.2 * len(scenes)), squeeze=False
    )
    legend: dict[str, object] = {}  # entry -> its proxy handle, in the order first drawn
    for i, scene in enumerate(scenes):
        pts = [r for r in recs if r["experiment"] == scene]
        for j, (cost, label) in enumerate(COSTS.items()):
            ax = axes[i, j]
            _draw_panel(ax, pts, summary, scene, cost, colours, legend)
            xs = [r[cost] for r in pts if r.get(cost) is not None]
            limit = (summary.get("budget") or {}).get(cost)
            if limit is not None:
                entry = f"budget: {COST_NAMES.get(cost, cost)} <= {fmt(limit, 4)}"
                ax.axvline(limit, color="tab:red", ls="--", lw=1.2, gid=entry)
                legend.setdefault(entry, plt.Line2D([], [], color="tab:red", ls="--", lw=1.2))
                xs.append(limit)
            ax.set_xscale("log")
            _plain_log_ticks(ax, xs)
            ax.set_xlabel(label, fontsize=9)
            ax.set_ylabel("FLIP on water pixels" if j == 0 else "")
            ax.set_title(scene if j == 0 else "", fontsize=10, loc="left")
            ax.grid(alpha=0.3, which="both")
    if legend:
        # outside the panels, to the right of the first row: it covers no point
        axes[0, -1].legend(list(legend.values()), list(legend), fontsize=7, loc="upper left",
                           bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)  # fmt: skip
    fig.tight_layout()
    return fig


def _draw_panel(ax, pts: list, summary: dict, scene: str, cost: str, colours, legend) -> None:
    """One scene's points against one cost: every point, the front, the original schedule's
    points ringed, the recommendation, the user's shader; each drawn artist's legend entry is
    added to ``legend`` (entry -> proxy handle) and set as its ``gid``."""
    plt = pyplot()
    cands = [r for r in pts if r["kind"] != "converged"]
    for r in pts:
        if r.get(cost) is None:
            continue
        # a converged point (a star in its variant's colour) stands for the floor in the legend
        conv = r["kind"] == "converged"
        entry = FLOOR if conv else r["variant"]
        ax.scatter(r[cost], r["flip"], color=colours[r["variant"]],
                   marker=MARKERS.get(r["kind"], "o"), s=60 if conv else 22, alpha=0.8,
                   edgecolors="none", gid=entry)  # fmt: skip
        legend.setdefault(
            entry,
            plt.Line2D(
                [],
                [],
                ls="",
                marker="*" if conv else "o",
                ms=9 if conv else 6,
                color="gray" if conv else colours[r["variant"]],
            ),
        )
    ranked = summary.get("cost", "fetches_mean")  # frame times are noisy: no front on them
    on = summary["scenes"][scene]["fronts_by_cost"][cost] if cost == ranked else []
    front = sorted(
        (r for r in cands if r["label"] in on and r.get(cost) is not None), key=lambda r: r[cost]
    )
    if front:
        ax.step([r[cost] for r in front], [r["flip"] for r in front], where="post", color="k",
                lw=1.0, gid="Pareto front")  # fmt: skip
        legend.setdefault("Pareto front", plt.Line2D([], [], color="k", lw=1.0))
    for r in cands:
        if r["kind"] == "scale" and r["scale"] == 1.0 and r.get(cost) is not None:
            ax.scatter(r[cost], r["flip"], s=120, facecolors="none",
                       edgecolors=colours[r["variant"]], linewidths=1.5, gid=SEED)  # fmt: skip
            legend.setdefault(SEED, plt.Line2D([], [], ls="", marker="o", ms=10, mfc="none",
                                               mec="k", mew=1.5))  # fmt: skip
    rec = summary["scenes"][scene]["recommended"]
    for r in cands:
        if rec is not None and r["label"] == rec["label"] and r.get(cost) is not None:
            ax.scatter(r[cost], r["flip"], marker="x", s=120, color="red", gid="recommended")
            legend.setdefault("recommended", plt.Line2D([], [], ls="", marker="x", ms=10,
                                                        color="red", mew=1.5))  # fmt: skip
    yours = {p["label"] for p in summary["scenes"][scene].get("user") or []}  # the analysis's
    for r in cands:
        if r["label"] in yours and r.get(cost) is not None:
            name = r["variant"].split(":", 1)[1]
            entry = f"your shader ({name})"
            ax.scatter(r[cost], r["flip"], marker="D", s=90, facecolors="none", edgecolors="k",
                       linewidths=1.5, gid=entry)  # fmt: skip
            ax.annotate(name, (r[cost], r["flip"]), textcoords="offset points",
                        xytext=(6, 6), fontsize=8)  # fmt: skip
            legend.setdefault(entry, plt.Line2D([], [], ls="", marker="D", ms=8, mfc="none",
                                                mec="k", mew=1.5))  # fmt: skip


FLOOR = "converged raymarch (floor)"
SEED = "original schedule (10, 3, 40)"


def is_user_variant(variant: str) -> bool:
    """A user's own shader on the chart (variant ``user:<file>``)."""
    return variant.startswith("user:")


def _plain_log_ticks(ax, xs: list) -> None:
    """Plain-number labels (``5``, ``10``, ``20``) on a log x axis, major ticks only, as many per
    decade as the span leaves room for (1-2-3-5, 1-2-5, 1-3 or 1), minor ticks unlabelled."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    xs = [x for x in xs if x is not None and x > 0]
    if not xs:
        return
    decades = np.log10(max(xs)) - np.log10(min(xs))
    if decades <= 1.0:
        subs = (1.0, 2.0, 3.0, 5.0)
    else:
        subs = (1.0, 2.0, 5.0) if decades <= 1.5 else (1.0, 3.0) if decades <= 3 else (1.0,)
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=subs))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())


def _sched(rec) -> str:
    return rec["label"] if rec else "-"


def write_tradeoff_report(out: Path, summary: dict) -> Path:
    """``out/report.md`` from the tradeoff summary (the content of summary.json)."""
    path = out / "report.md"
    write_text_atomic(path, tradeoff_report_text(summary))
    return path


def tradeoff_report_text(summary: dict) -> str:
    """The Markdown of ``report.md`` from the tradeoff summary (the content of summary.json)."""
    tol = summary["tolerance"]
    lines = [
        "# Speed against accuracy",
        "",
        f"{summary['n_points']} points, {summary['n_failed']} failed. Error: FLIP "
        "on the water pixels "
        "at full resolution against the reference; every point's continuous constants refitted for "
        "its schedule. Cost: mean texture fetches per water pixel "
        "(machine-independent, used for the "
        "recommendation), llvmpipe frame time at 1920x1080 normalised by a fixed "
        "reference shader timed "
        "in the same job (reference median "
        f"{fmt(summary.get('gl_reference_ms_1080p'), 3)} ms), the "
        "port's frame time. Recommendation: the cheapest point within "
        f"{100 * tol:g} % of the best FLIP.",
        "",
        "Frame times are shown, never ranked: each is one timing on llvmpipe, a CPU rasteriser "
        "shared with whatever else the machine runs, and it moves from run to run by more than "
        "neighbouring points differ (a shader with fewer fetches can time slower). The "
        "recommendation and the chart's front use the fetches, which do not move; the "
        "frame-time panels show the points without a front.",
        "",
        *_schedule_note(summary),
    ]
    lines += _search_lines(summary)
    lines += ["![error against cost, Pareto fronts](pareto.png)", ""]
    for scene, f in summary["scenes"].items():
        lines += _scene_lines(scene, f, summary)
    lines += lod_lines(summary)
    lines += _closing_lines(summary)
    return "\n".join(lines) + "\n"


SCHEDULE_NOTE = (
    "A configuration is a shader and its step schedule, written `shader (a, b, c)`: the "
    "schedule is (steps at grazing angles, steps at steep angles, loop cap), the shader's "
    "`STEPS_GRAZING`, `STEPS_STEEP` and `LOOP_CAP`: the refraction raymarch takes a steps per "
    "world unit of ray when the refracted ray is grazing and b when it points straight down "
    "(interpolated between by its slope), and stops after c steps. A shader named without a "
    "schedule has no raymarch."
)
REFL_NOTE = (
    "`refl (d, e, f)` after it is the reflection march's schedule, in the order (steps at steep "
    "angles, steps at grazing angles, loop cap): `REFL_STEPS_STEEP`, `REFL_STEPS_GRAZING`, "
    "`REFL_LOOP_CAP`."
)
SCHEDULE_HEAD = "shader (schedule)"


def _schedule_note(summary: dict) -> list[str]:
    """What the numbers after a shader's name are, said once."""
    refl = any(" refl (" in r["label"] for f in summary["scenes"].values() for r in f["front"])
    return [SCHEDULE_NOTE + (" " + REFL_NOTE if refl else ""), ""]


def _search_lines(summary: dict) -> list[str]:
    """How the points were chosen (adaptive or exhaustive) and the budget, when a run says."""
    lines = []
    budget = summary.get("budget")
    if budget:
        limits = ", ".join(f"{COST_NAMES.get(c, c)} <= {fmt(v, 4)}" for c, v in budget.items())
        lines += [f"**Budget**: {limits}; the recommendation is the lowest FLIP within it.", ""]
    s = summary.get("search")
    if not s:
        return lines
    fixed = ", ".join(f"{a} = {c}" for a, c in s.get("fix", {}).items()) or "none"
    if s["mode"] == "adaptive":
        rounds = ", ".join(f"{k} {v}" for k, v in s.get("rounds", {}).items())
        # runs before the descent have no "descents"
        descents = ", ".join(f"{k} {v}" for k, v in s.get("descents", {}).items()) or "none"
        descents = f"; descent moves: {descents}" if "descents" in s else ""
        if s.get("joint_screened"):
            descents += f"; {s['joint_screened']} points screened by the joint rung"
        lines += [
            f"Search: adaptive. A quick screen fitted {s['screened']} points ("
            f"{s['shaders_screened']} shaders, some at several schedules; walk rounds per "
            f"scene: {rounds}{descents}); the {s['points_in_full']} points "
            f"nearest the screen's front were then measured in full, every constant refitted at "
            f"full resolution ({fmt(s['seconds'], 3)} s in all). Axes held: {fixed}.",
            "",
        ]
    else:
        lines += [
            f"Search: exhaustive, {s['points_in_full']} points in full, {fmt(s['seconds'], 3)} "
            f"s; axes held: {fixed}.",
            "",
        ]
    return lines


COST_NAMES = {"fetches_mean": "fetches per water pixel", "gl_norm_ms_1080p": "GL ms 1080p"}


def _marginal_lines(rows: list) -> list[str]:
    """What each axis's choice buys at the recommendation (screen points of its neighbours)."""
    if not rows:
        return []
    lines = [
        "",
        "What each choice buys at the recommendation (its one-axis neighbours at its schedule, "
        "at the screen resolution; FLIP difference +- the paired standard error; negative is "
        "better or cheaper):",
        "",
        "| axis | choice | shader | FLIP difference | fetches difference |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        choice = r["choice"]
        if r["axis"] == "refraction":  # a refraction comes with the reflections its file has
            choice = f"{choice}, reflection {_space.choices_of(r['variant'])['reflection']}"
        lines.append(
            f"| {r['axis']} | {choice} | `{r['variant']}` | {r['d_flip']:+.4f} +- "
            f"{fmt(r['se'], 2)} | {r['d_fetches']:+.1f} |"
        )
    return lines


def _user_lines(places: list, export: dict | None, tolerance: float) -> list[str]:
    """Where the user's own shader stands (``tradeoff_analysis.placement``) and its file."""
    lines = []
    for p in places:
        bw = p["best_within"]
        gain = bw["flip"] / p["flip"] - 1 if bw else 0.0
        if p["on_front"]:
            where = "**on the Pareto front**: no point costs no more and errs less"
        else:
            d = p["dominated_by"][0]
            where = (
                f"dominated by {len(p['dominated_by'])} point(s); the cheapest of them: "
                f"{d['label']}, FLIP {fmt(d['flip'])} at {fmt(d['fetches_mean'], 3)} fetches"
            )
        if bw and gain < 0:
            where += (
                f". The best within its fetches: {bw['label']}, FLIP {fmt(bw['flip'])} "
                f"({100 * gain:+.2f} %"
                + (
                    f", within the {100 * tolerance:g} % tolerance: no clearly better shader "
                    "at its cost)"
                    if gain >= -tolerance
                    else ")"
                )  # fmt: skip
            )
        lines += [
            "",
            f"**Your shader**, `{p['label'].split(':', 1)[1]}` (constants fitted, measured like "
            f"every point): FLIP {fmt(p['flip'])} at {fmt(p['fetches_mean'], 3)} fetches per "
            f"water pixel, FLIP rank {p['rank']} of {p['of']}; {where}.",
        ]
        if export:
            gl = export["gl_check"]
            check = (
                f"mean |diff| {fmt(gl['mean_abs'], 3)}, p99.9 {fmt(gl['p999'], 3)}: "
                + ("passed" if gl["passed"] else "**FAILED**")
                if gl.get("ran")
                else f"not run ({gl.get('why')})"
            )
            ran = gl_ran(gl, "llvmpipe")
            lines.append(f"Its file with the fitted constants: `{export['file']}` ({ran} "
                         f"against the executor: {check}).")  # fmt: skip
    return lines


def _alone_lines(rows: list, front: list) -> list[str]:
    """The table of each source's technique alone (full points at their own schedules)."""
    if not rows:
        return []
    on_front = {r["label"] for r in front}
    lines = [
        "",
        "Each source's technique alone, at its own schedule, constants refitted (the cube map "
        "where a source has no reflection of its own):",
        "",
        "| source | shader | fetches (mean) | GL ms 1080p (norm.) | FLIP | on the front |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['source']} | `{r['variant']}` | {fmt(r['fetches_mean'], 3)} | "
            f"{fmt(r.get('gl_norm_ms_1080p'), 3)} | {fmt(r['flip'])} | "
            f"{'yes' if r['label'] in on_front else 'no'} |"
        )
    return lines


def _parsimony_lines(parsimony: dict) -> list[str]:
    """Each variant at the original's schedule: its fitted constants, FLIP and BIC."""
    pars = {v: d for v, d in parsimony.items() if d.get("bic") is not None}
    lines = []
    if pars:
        b0 = min(d["bic"] for d in pars.values())
        lines += [
            "",
            "Each variant at the original's schedule (constants fitted or at a bound), ranked "
            "by BIC: how well the fit's squared residual is explained for the constants the "
            "variant spends (lower is better, relative to the lowest). BIC judges the "
            "residual the fit minimises, FLIP what a viewer sees, so the two orders can "
            "differ: a variant with more constants can lower the residual and still raise "
            "FLIP.",
            "",
            "| variant | constants | FLIP | BIC - min |",
            "|---|---|---|---|",
        ]
        lines += [
            f"| {v} | {d['n_fitted']} | {fmt(d['flip'])} | {d['bic'] - b0:.0f} |"
            for v, d in sorted(pars.items(), key=lambda kv: kv[1]["bic"])
        ]
    return lines


def _scene_lines(scene: str, f: dict, summary: dict) -> list[str]:
    """One scene's section: its front, recommendation, parsimony, needs and halvings."""
    lines = []
    rec, seed = f["recommended"], f["seed"]
    lines += [f"## {scene}", ""]
    lines += [
        f"| {SCHEDULE_HEAD} | fetches (mean) | fetches (p99) | GL ms 1080p (norm.) | "
        "port ms | FLIP | RMSE |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in f["front"]:
        lines.append(
            f"| {r['label']} | {fmt(r['fetches_mean'], 3)} | {fmt(r.get('fetches_p99'), 3)} | "
            f"{fmt(r.get('gl_norm_ms_1080p'), 3)} | {fmt(r.get('port_ms_512'), 3)} | "
            f"{fmt(r['flip'])} | {fmt(r['rmse'])} |"
        )
    lines.append("")
    if rec:
        lines.append(
            f"**Recommended**: {rec['label']}: FLIP {fmt(rec['flip'])} at "
            f"{fmt(rec['fetches_mean'], 3)} fetches per pixel."
        )
    if seed and rec:
        lines.append(
            f"The original shader's configuration (water_refraction (10, 3, 40), refitted): FLIP "
            f"{fmt(seed['flip'])} at {fmt(seed['fetches_mean'], 3)} fetches "
            f"({fmt(seed['fetches_mean'] / rec['fetches_mean'], 3)}x the recommended cost, "
            f"FLIP {100 * (seed['flip'] / rec['flip'] - 1):+.2f} %)."
        )
    bw = f.get("best_within_seed_budget")
    if seed and bw:
        lines.append(
            "**Best within the original's fetch budget** "
            f"({fmt(seed['fetches_mean'], 3)} fetches): "
            f"{bw['label']}: FLIP {fmt(bw['flip'])} at {fmt(bw['fetches_mean'], 3)} fetches "
            f"(the fitted original: {fmt(seed['flip'])}, "
            f"{100 * (bw['flip'] / seed['flip'] - 1):+.1f} %)."
        )
    own = summary.get("panels", {}).get(scene, {}).get(ORIGINAL_PANEL)
    if own and bw:
        lines.append(
            f"Against the original shader at its own constants (FLIP {fmt(own['flip'])}): "
            f"{fmt(bw['flip'] / own['flip'], 3)}x its error within its fetch budget."
        )
    lines += _user_lines(
        f.get("user") or [], summary.get("user_exports", {}).get(scene), summary["tolerance"]
    )
    lines += motion_lines(f.get("motion"))
    lines += _marginal_lines(f.get("marginals", []))
    lines += _alone_lines(f.get("sources_alone", []), f["front"])
    if summary.get("images", {}).get(scene):
        lines += ["", f"![{scene}: reference and shaders]({summary['images'][scene]})"]
    lines += _parsimony_lines(f.get("parsimony", {}))
    lines += ["", "What the scene needs:", ""]
    best = sorted((v, x) for v, x in f["best_flip_by_variant"].items() if x is not None)
    lines.append(
        f"- simplest variant within tolerance: `{f['simplest_variant_within_tolerance']}`; "
        "best FLIP per variant: " + ", ".join(f"{v} {fmt(x)}" for v, x in best)
    )
    floors = sorted((v, x) for v, x in f["error_floor_by_variant"].items() if x is not None)
    if floors:  # only the variants a converged raymarch was measured for
        lines.append(
            "- error floor (converged raymarch) per variant: "
            + ", ".join(f"{v} {fmt(x)}" for v, x in floors)
        )
    lines.append(
        "- smallest loop cap at which fewer than 1 % of rays miss the floor: "
        + ", ".join(
            f"{v} {x if x is not None else 'none in the grid'}"
            for v, x in sorted(f["smallest_crossing_loop_cap"].items())
        )
    )
    if f["halvings"]:
        lines += [
            "",
            "Each halving of the original's schedule (scaled family):",
            "",
            f"| {SCHEDULE_HEAD} | scale | fetches | GL ms 1080p (norm.) | FLIP | not crossed |",
            "|---|---|---|---|---|---|",
        ]
        for r in f["halvings"]:
            lines.append(
                f"| {r['label']} | {fmt(r['scale'], 3)} | {fmt(r['fetches_mean'], 3)} | "
                f"{fmt(r.get('gl_norm_ms_1080p'), 3)} | {fmt(r['flip'])} | "
                f"{fmt(r.get('not_crossed'), 3)} |"
            )
    lines.append("")
    return lines


def _closing_lines(summary: dict) -> list[str]:
    """The joint front, the exported shaders and the failed points."""
    lines = []
    if "joint" in summary:
        j = summary["joint"]
        lines += [
            "## Joint front (error averaged over the scenes)",
            "",
            f"| {SCHEDULE_HEAD} | fetches (mean) | FLIP (mean) |",
            "|---|---|---|",
        ]
        lines += [
            f"| {r['label']} | {fmt(r['fetches_mean'], 3)} | {fmt(r['flip'])} |" for r in j["front"]
        ]
        lines += ["", f"**Recommended for all scenes**: {_sched(j['recommended'])}."]
        if j.get("best_within_seed_budget") and j.get("seed"):  # runs before it have neither
            b, o = j["best_within_seed_budget"], j["seed"]
            lines += [
                "",
                "**Best for all scenes within the original's fetches** ("
                f"{fmt(o['fetches_mean'], 3)} on average, FLIP {fmt(o['flip'])}): "
                f"{_sched(b)}, FLIP {fmt(b['flip'])} at "
                f"{fmt(b['fetches_mean'], 3)} fetches.",
            ]
        lines.append("")
    if summary.get("exports"):
        lines += ["## Exported shaders", ""]
        for scene, e in summary["exports"].items():
            gl = e["gl_check"]
            lines.append(
                f"- {scene}: `{e['folder']}` ({e['label']}), compiled with glslangValidator; "
                f"llvmpipe vs port mean |diff| {fmt(gl.get('mean_abs'), 3)}, p99.9 "
                f"{fmt(gl.get('p999'), 3)}"
                + ("" if gl["passed"] else " -- **MISMATCH: do not ship**")
            )
        lines.append("")
    if summary["failures"]:
        lines += ["## Failed points", ""]
        lines += [
            f"- {x['experiment']} {x['variant']} {x['schedule']}: {x['error_message']}"
            for x in summary["failures"]
        ]
    return lines
