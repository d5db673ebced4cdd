"""The generated parts of the documentation, from the result files committed beside them.

Every table of results in ``docs/`` is written by this script, never by hand:

* ``docs/results/<study>/report.md`` of the tradeoff-family studies (``tradeoff``, ``scenes``:
  the tradeoff on deep_steps, grazing and calm, ``views/tradeoff``: over four views of the
  default pool, ``variants``,
  ``variants/shipped``, ``baselines``, ``animation/tradeoff``: the tradeoff in motion,
  ``user-shader/tradeoff``: a user's own shader charted): from the study's ``summary.json``
  where it is committed, else from its ``tradeoff.parquet`` (fronts, recommendations and
  findings recomputed by ``study.studies.tradeoff_analysis.analyse``; the run-time sections --
  exported shaders, side-by-side images -- exist only in a run's own summary);
* ``docs/results/failures/report.md``: from its ``failures.parquet`` (one row per scene and
  failure class) and ``summary.json`` (the command that ran it);
* ``docs/results/stability/<phase>/stability.md``: from the phase's ``summary.json``;
* ``docs/results/search/report.md``: adaptive against exhaustive search, from the
  ``bench.json`` that ``benchmarks/bench_search.py --json`` writes;
* ``docs/results/gpu/report.md``: the calibration's stages on the CPU and on a GPU, from the
  ``bench.json`` that ``benchmarks/bench_gpu.py --json`` writes (tables: ``docs_gpu.py``);
* ``docs/results/normal-equations/report.md``: the fit with its normal equations formed on the
  device, from ``benchmarks/bench_normal_equations.py``'s ``bench.json``
  (``docs_normal_equations.py``);
* ``docs/results/animation/report.md``: the animated calibration's report, from the
  ``constants.json`` that ``study calibrate experiments/animated.toml`` writes, and
  ``schedules.md``, the same calibration at three step schedules (``schedules.json``);
* ``docs/results/error-budget/report.md``: what the best shaders' remaining error is made of,
  from ``benchmarks/bench_error_budget.py``'s results (``docs_error_budget.py``);
* ``docs/results/engine-shaders/report.md``: the engine-style shader pairs of
  ``experiments/`` calibrated, from each one's ``constants.json`` (``study calibrate
  experiments/<name>.toml``);
* ``docs/results/lod/report.md``: the level-of-detail policies on seven scenes, from their
  tradeoff summaries (``docs_lod.py``);
* ``docs/experiment-keys.md``: the experiment file's key table, from the schema;
* ``docs/file-formats.md``: the files a user gives and the files the tool writes, its tables
  from the schema, the file readers and the committed result files (``docs_file_formats.py``);
* ``docs/engine-inputs.md``: every input a user's shader can read, from the code's tables
  (``docs_engine_inputs.py``);
* the quoted passages of the hand-written pages (``<!-- quote:NAME -->``: the front figure's
  caption, make run's figures, the recommendation), from the result files
  (``docs_figures.py``, which also marks a tradeoff-family report whose run is stale).

and every figure it can draw from those files (:func:`figures`): the Pareto chart of a
tradeoff-family study whose ``tradeoff.parquet`` is committed, a study's ``lod.png`` (and each
``docs/results/lod/<scene>/lod.png``) and ``motion.png``, the
stability figures, and each side-by-side of renders whose panels a run saved as data
(``images_<scene>.exr`` and ``.json``). ``docs/results/figures.json`` records, per figure, the
SHA-256 of each file it was drawn from, and lists every other figure under ``docs/results``
with why it is not redrawn here (renders no committed file holds, or points not committed).

Re-running a study into ``docs/results/<study>`` and then this script refreshes the pages::

    .venv/bin/python scripts/build_docs.py           # write the pages, draw the figures
    .venv/bin/python scripts/build_docs.py --check   # exit 1 if a committed page differs, a
                                                     # figure is missing or a result file is not
                                                     # the one its figure was drawn from

``tests/test_docs.py`` runs the check, so a number in the docs cannot go stale by hand.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"
RESULTS = DOCS / "results"
TRADEOFF_FAMILY = (
    "tradeoff",
    "scenes",
    "views/tradeoff",
    "variants",
    "variants/shipped",
    "baselines",
    "animation/tradeoff",
    "user-shader/tradeoff",
)
STABILITY_PHASES = ("stability/multistart", "stability/noise")
ENGINE_PAIRS = ("webgl_mirror_water", "dudv_depth_water", "fog_cube_water", "zup_water")
DEFAULT_TOLERANCE = 0.02

KEYS_HEADER = """# Experiment keys

An experiment file (TOML) describes one scene, how its reference is rendered and what is fitted.
Any key can be overridden on the command line with `--set key=value` (dotted name, TOML value).
Unknown keys, wrong types, out-of-range values and impossible combinations are refused with a
message naming the key. World units, `+y` up, the water plane at `y = 0`, linear RGB.

This table is generated by `scripts/build_docs.py` from the schema (`study/config/schema_scene.py`
and `schema_study.py`); `experiments/README.md` describes the shipped experiment files.

"""


def _tradeoff_summary(folder: Path) -> dict:
    """The study's summary: its committed ``summary.json``, else recomputed from its table."""
    from study.studies.tradeoff_analysis import analyse
    from study.sweep import read_table

    summary_file = folder / "summary.json"
    if summary_file.is_file():
        return json.loads(summary_file.read_text())
    rows = read_table(folder / "tradeoff.parquet")
    if not rows:
        raise FileNotFoundError(f"{folder}: neither summary.json nor a non-empty tradeoff.parquet")
    names = list(dict.fromkeys(r["job.experiment"] for r in rows if r.get("job.experiment")))
    summary, _ = analyse(rows, names, DEFAULT_TOLERANCE)
    return summary


def generated() -> dict[Path, str]:
    """Every generated page: path -> its Markdown."""
    from study.report.animation import animation_report_text
    from study.report.generalise import generalise_report_text
    from study.report.stability import stability_report_text
    from study.report.tradeoff import tradeoff_report_text
    from study.config.experiment import schema_markdown

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from docs_engine_inputs import engine_inputs_page
    from docs_file_formats import file_formats_page
    from docs_gpu import gpu_bench_page
    from docs_error_budget import error_budget_page
    from docs_own_waves import own_waves_page
    from docs_lod import lod_page
    from docs_normal_equations import normal_equations_page
    from docs_resolution_transfer import resolution_transfer_page
    from docs_figures import quoted_pages, stale_results

    stale_folders = stale_results()
    pages = {DOCS / "experiment-keys.md": KEYS_HEADER + schema_markdown()}
    pages[DOCS / "file-formats.md"] = file_formats_page()
    pages[DOCS / "engine-inputs.md"] = engine_inputs_page()
    for study in TRADEOFF_FAMILY:
        folder = RESULTS / study
        text = tradeoff_report_text(_tradeoff_summary(folder))
        if study in stale_folders:  # its reference is not the current one: say so on top
            title, rest = text.split("\n", 1)
            text = (
                f'{title}\n\n!!! warning "Not the current reference"\n    '
                f"{stale_folders[study]}. Its figures compare its shaders with each other only; "
                f"re-run the study (its command is in the page that links here) to compare them "
                f"with the other pages.\n{rest}"
            )
        pages[folder / "report.md"] = text
    pages[RESULTS / "failures" / "report.md"] = _failures_page(RESULTS / "failures")
    pages[RESULTS / "search" / "report.md"] = _search_page(_json(RESULTS / "search" / "bench.json"))
    pages[RESULTS / "search" / "scenes.md"] = _search_page(
        _json(RESULTS / "search" / "bench_scenes.json"), "four scenes in one study"
    )
    pages[RESULTS / "gpu" / "report.md"] = gpu_bench_page(_json(RESULTS / "gpu" / "bench.json"))
    pages[RESULTS / "normal-equations" / "report.md"] = normal_equations_page(
        _json(RESULTS / "normal-equations" / "bench.json")
    )
    pages[RESULTS / "animation" / "report.md"] = animation_report_text(
        _json(RESULTS / "animation" / "constants.json"), gif=False
    )
    pages[RESULTS / "animation" / "schedules.md"] = _schedules_page(
        _json(RESULTS / "animation" / "schedules.json")
    )
    for phase in STABILITY_PHASES:
        folder = RESULTS / phase
        pages[folder / "stability.md"] = stability_report_text(_json(folder / "summary.json"))
    pages.update(_default_run_pages(RESULTS / "default"))
    pages[RESULTS / "loss-linear" / "report.md"] = _calibration_page(
        RESULTS / "loss-linear",
        "`study calibrate experiments/default.toml --set 'fit.loss=\"linear\"' --out "
        "out/loss-linear`",
        Path("out/loss-linear"),
    )
    pages[RESULTS / "loss-transport" / "report.md"] = _calibration_page(
        RESULTS / "loss-transport",
        "`study calibrate experiments/default.toml --set 'fit.loss=\"transport\"' --out "
        "out/loss-transport`",
        Path("out/loss-transport"),
    )
    pages[RESULTS / "resolution-transfer" / "report.md"] = resolution_transfer_page(
        RESULTS / "resolution-transfer"
    )
    pages[RESULTS / "engine-shaders" / "report.md"] = _engine_pairs_page(RESULTS / "engine-shaders")
    pages[RESULTS / "own-waves" / "report.md"] = own_waves_page(RESULTS)
    pages[RESULTS / "lod" / "report.md"] = lod_page(RESULTS)
    pages[RESULTS / "error-budget" / "report.md"] = error_budget_page(RESULTS / "error-budget")
    pages[RESULTS / "views" / "generalise.md"] = generalise_report_text(
        _json(RESULTS / "views" / "generalise.json")
    )
    pages.update(quoted_pages())  # the hand-written pages' quoted passages
    return pages


def _figures(run: dict) -> str:
    """A target check's "mean, 99.9th percentile" (or "-" where it did not run)."""
    from study.report.calibration import fmt

    return f"{fmt(run['mean_abs'], 3)}, {fmt(run['p999'], 3)}" if "mean_abs" in run else "-"


def _engine_pairs_page(folder: Path) -> str:
    """The engine-style pairs' calibrations: one section per ``folder/<name>/constants.json``
    (errors, every constant's status and value, the GL check and the HLSL round trip)."""
    from study.report.calibration import fmt

    lines = [
        "# Engine waters, calibrated",
        "",
        "*Written by `scripts/build_docs.py` from the `constants.json` that `study calibrate "
        "experiments/<name>.toml --out docs/results/engine-shaders/<name>` wrote, committed "
        "beside this page. The shaders: [Four engine waters](../../user-shader.md#four-engine-"
        "waters-shipped).*",
        "",
        "| experiment | RMSE start -> fitted | FLIP start -> fitted | solver steps | GL check "
        "(mean, 99.9th pct.) | the GL check ran | GLSL ES 3.00 export on OpenGL ES | HLSL round "
        "trip |",
        "|---|---|---|---|---|---|---|---|",
    ]
    runs = {n: _json(folder / n / "constants.json") for n in ENGINE_PAIRS}
    for name, d in runs.items():
        e, gl = d["error"], d["gl_check"]
        targets = d.get("engine_targets") or {}
        hl, es = (_figures((targets.get(t) or {}).get("llvmpipe") or {})
                  for t in ("hlsl", "gles300"))  # fmt: skip
        ran = f"{gl.get('text', 'the core-profile translation')}, {gl.get('context', 'core')}"
        lines.append(
            f"| `{name}` | {e['rmse']['default']:.4f} -> {e['rmse']['fitted']:.4f} | "
            f"{e['flip']['default']:.4f} -> {e['flip']['fitted']:.4f} | {d['iterations']} | "
            f"{fmt(gl['mean_abs'], 3)}, {fmt(gl['p999'], 3)} "
            f"({'passed' if gl['passed'] else 'FAILED'}) | {ran} | {es} | {hl} |"
        )
    for name, d in runs.items():
        lines += ["", f"## `{name}`", "", f"`{d['shader']}` after its own vertex shader "
                  f"`{Path(d['vertex_file']).name}`.", "",
                  "| constant | start | exported | status | relative standard error | why |",
                  "|---|---|---|---|---|---|"]  # fmt: skip
        for cname, p in d["parameters"].items():
            se = p.get("rel_std_error")
            lines.append(
                f"| `{cname}` | {fmt(p['default'])} | {fmt(p['fitted'])} | {p['status']} | "
                f"{'-' if se is None else f'{100 * se:.1f} %'} | {p['reason']} |"
            )
    return "\n".join(lines) + "\n"


def _json(path: Path) -> dict:
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: re-run the study into {path.parent}")
    return json.loads(path.read_text())


def _schedules_page(res: dict) -> str:
    """The animated experiment's calibration at three step schedules (motion and banding)."""
    lines = [
        "# Step schedules in motion",
        "",
        f"`{res['shader']}` calibrated on `experiments/animated.toml` (8 frames, one constants "
        "block) at each schedule; differences against the original schedule (10, 3, 40), paired "
        "over the frames (FLIP) and the frame pairs (temporal RMSE), +- their standard error.",
        "",
        f"Reproduce: `{res['command']}`",
        "",
        "| schedule | mean FLIP | FLIP difference | temporal RMSE | temporal difference | "
        "shader change | change ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in res["schedules"]:
        df, dt = r.get("flip_vs_original_schedule"), r.get("temporal_vs_original_schedule")
        lines.append(
            f"| ({', '.join(f'{v:g}' for v in r['schedule'])}) | {r['flip_mean']:.4f} | "
            + (f"{df['mean']:+.4f} +- {df['se']:.5f}" if df else "-")
            + f" | {r['temporal_rmse']:.5f} | "
            + (f"{dt['mean']:+.6f} +- {dt['se']:.6f}" if dt else "-")
            + f" | {r['shader_change']:.4f} | {r['change_ratio']:.3f} |"
        )
    return "\n".join(lines) + "\n"


def _search_page(bench: dict, what: str = "") -> str:
    """The benchmark of the adaptive search against the exhaustive grid (``what``: a subtitle)."""
    yes = {True: "yes", False: "**no**"}
    lines = [
        "# Adaptive against exhaustive search" + (f": {what}" if what else ""),
        "",
        f"Reproduce: `{bench['command']}`",
        "",
        f"Shader space with {', '.join(bench['fix']) or 'no axis'} held; schedules: "
        f"{'; '.join(bench['grid'])}. Both searches on the same local cluster, one after the "
        "other, references and inputs cached.",
        "",
        "| search | seconds | screen points | points in full | scene | recommendation | FLIP "
        "| fetches |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in bench["results"]:
        for scene, s in r["scenes"].items():
            lines.append(
                f"| {r['mode']} | {r['seconds']:.0f} | {r['screen_points']} | "
                f"{r['full_points']} | {scene} | {s['recommended']} | {s['flip']:.4f} | "
                f"{s['fetches']:.1f} |"
            )
    lines += [
        "",
        f"Time of the adaptive search: {bench['time_ratio']:.3f} of the exhaustive one's.",
        "",
        "| scene | same shader | schedule within one grid step | FLIP within 1 % |",
        "|---|---|---|---|",
    ]
    for scene, a in bench["agreement"].items():
        lines.append(
            f"| {scene} | {yes[a['same_shader']]} | {yes[a['schedule_within_a_step']]} | "
            f"{yes[a['flip_within_1_percent']]} |"
        )
    return "\n".join(lines) + "\n"


def _failures_page(folder: Path) -> str:
    """The failure catalogue's report from its table and the command that ran it."""
    from study.report.failures import failures_report_text, scenes_of
    from study.studies.failures import CLASSES
    from study.sweep import read_table

    command = _json(folder / "summary.json")["command"]
    rows = read_table(folder / "failures.parquet")
    return failures_report_text(scenes_of(rows), list(CLASSES), command)


LEDGER = RESULTS / "figures.json"
# figures made of renders that no committed file holds (why, per file name)
RENDERS = {
    "failures.png": "renders of each failure class; the failure study does not save them as data",
    "temporal.png": "renders of the animated calibration; `study calibrate` does not save them "
    "as data",
    "animation.webp": "renders of every frame of the animated calibration; `study calibrate` "
    "does not save them as data",
    "example.png": "a screenshot of the three.js example page in headless Chromium; "
    "scripts/threejs_check.py takes it again",
    "wgsl_vs_port.png": "the WGSL export's render on lavapipe beside the port's; "
    "scripts/wgsl_check.py draws it again",
}


def figures() -> dict[Path, tuple[list[Path], object]]:
    """Every figure this script draws: path -> (the result files it is drawn from, a function
    drawing it into a path). Drawn: the Pareto chart of a tradeoff-family study whose
    ``tradeoff.parquet`` is committed, its level-of-detail chart where its summary has one, the
    motion chart of one whose summary has a scene in motion, the stability figures, and every
    side-by-side whose panels are committed as data (``images_<scene>.exr`` and ``.json``,
    ``study.report.panels``)."""
    from study.report.lod import lod_figure
    from study.report.panels import panels_figure
    from study.report.stability import noise_figure, solver_figure, spread_figure
    from study.report.tradeoff_motion import motion_figure

    out = {}
    for study in TRADEOFF_FAMILY:
        folder = RESULTS / study
        table, summary = folder / "tradeoff.parquet", folder / "summary.json"
        sources = [p for p in (table, folder / "user.parquet", summary) if p.is_file()]
        if table.is_file():
            out[folder / "pareto.png"] = (sources, lambda p, f=folder: _pareto(p, f))
        if summary.is_file() and any(f.get("lod") for f in _json(summary)["scenes"].values()):
            out[folder / "lod.png"] = ([summary], lambda p, f=summary: lod_figure(p, _json(f)))
        if summary.is_file() and any(
            f.get("motion") for f in _json(summary)["scenes"].values()
        ):  # fmt: skip
            out[folder / "motion.png"] = (
                [summary],
                lambda p, f=summary: motion_figure(p, _json(f)),
            )
        for data in sorted(folder.glob("images_*.exr")):
            png = data.with_suffix(".png")
            out[png] = ([data, data.with_suffix(".json")], panels_figure)
    for summary in sorted((RESULTS / "lod").glob("*/summary.json")):
        out[summary.parent / "lod.png"] = ([summary], lambda p, f=summary: lod_figure(p, _json(f)))
    for data in sorted((RESULTS / "error-budget").glob("images_*.exr")):
        out[data.with_suffix(".png")] = ([data, data.with_suffix(".json")], panels_figure)
    ms = RESULTS / "stability" / "multistart" / "summary.json"
    out[ms.parent / "solvers.png"] = ([ms], lambda p: solver_figure(p, _json(ms)["multistart"]))
    out[ms.parent / "spread.png"] = ([ms], lambda p: spread_figure(p, _json(ms)["multistart"]))
    noise = RESULTS / "stability" / "noise" / "summary.json"
    out[noise.parent / "noise.png"] = ([noise], lambda p: noise_figure(p, _json(noise)["noise"]))
    return out


def _pareto(path: Path, folder: Path) -> Path:
    """The study's ``pareto.png`` from its points (``tradeoff.parquet``, ``user.parquet``) and
    summary (committed, else recomputed from the points)."""
    from study.report.tradeoff import pareto_figure
    from study.studies.tradeoff_analysis import analyse
    from study.sweep import read_table

    rows = read_table(folder / "tradeoff.parquet")
    if (folder / "user.parquet").is_file():
        rows += read_table(folder / "user.parquet")
    summary = _tradeoff_summary(folder)
    names = list(summary["scenes"])
    _, recs = analyse(rows, names, summary["tolerance"], summary.get("budget") or None)
    return pareto_figure(path, recs, summary)


def sha256(path: Path) -> str:
    """SHA-256 of a file's contents (``study.config.files.digest``)."""
    from study.config.files import digest

    return digest(str(path))


def _rel(path: Path) -> str:
    return path.relative_to(REPO).as_posix()


def ledger(figs: dict | None = None) -> dict:
    """``docs/results/figures.json`` as the files on disk give it: ``drawn`` (figure -> {result
    file: SHA-256 of its bytes}) for every figure of :func:`figures`, and ``not_redrawn``
    (figure -> why) for every other figure under ``docs/results`` (PNG, WebP)."""
    figs = figures() if figs is None else figs
    drawn = {_rel(p): {_rel(s): sha256(s) for s in sources} for p, (sources, _) in figs.items()}
    others = {}
    for p in sorted([*RESULTS.rglob("*.png"), *RESULTS.rglob("*.webp")]):
        if _rel(p) in drawn:
            continue
        if p.name in RENDERS:
            why = RENDERS[p.name]
        elif p.name.startswith("images_"):
            why = (
                "renders of the shaders beside the reference; drawn by a run that did not keep "
                "its panels as data (images_<scene>.exr): re-run the study to redraw it"
            )
        else:
            why = "drawn by the study's run; the points it is drawn from are not committed"
        others[_rel(p)] = why
    return {
        "about": "Written by scripts/build_docs.py: each figure it draws, with the SHA-256 of "
        "the result files it was drawn from, and the figures it cannot redraw, with why.",
        "drawn": drawn,
        "not_redrawn": others,
    }


def ledger_problems(committed: dict | None = None) -> list[str]:
    """What makes the committed ledger wrong: a figure missing, a result file whose hash differs
    from the ledger's, a figure drawn or left out that the ledger does not list as such."""
    now = ledger()
    if committed is None:
        if not LEDGER.is_file():
            return [f"{_rel(LEDGER)} is missing"]
        committed = json.loads(LEDGER.read_text())
    problems = []
    for fig, sources in committed.get("drawn", {}).items():
        if not (REPO / fig).is_file():
            problems.append(f"{fig}: the figure is missing")
        for src, digest in sources.items():
            if not (REPO / src).is_file():
                problems.append(f"{fig}: its result file {src} is missing")
            elif sha256(REPO / src) != digest:
                problems.append(f"{fig}: {src} is not the file it was drawn from (SHA-256)")
        if now["drawn"].get(fig, sources).keys() != sources.keys():
            problems.append(f"{fig}: drawn from other files than the ledger lists")
    for fig in committed.get("not_redrawn", {}):
        if not (REPO / fig).is_file():
            problems.append(f"{fig}: the figure is missing")
    for fig in committed.get("drawn", {}).keys() - now["drawn"].keys():
        problems.append(f"{fig}: listed as drawn, but this script does not draw it")
    for section in ("drawn", "not_redrawn"):
        for fig in now[section].keys() - committed.get(section, {}).keys():
            problems.append(f"{fig}: not listed under {section!r} in {_rel(LEDGER)}")
    return problems


def draw_figures() -> list[Path]:
    """Draw every figure of :func:`figures` and write the ledger; returns the figures."""
    from study._io import write_json

    figs = figures()
    for path, (_, draw) in figs.items():
        draw(path)
    write_json(LEDGER, ledger(figs))
    return list(figs)


def stale(pages: dict[Path, str]) -> list[Path]:
    """The pages whose committed text differs from ``pages``."""
    return [p for p, text in pages.items() if not p.is_file() or p.read_text() != text]


def _default_run_pages(folder: Path) -> dict:
    """``make run``'s calibration as the docs show it: its report (without the run's figures)
    and the short binding sheets of HLSL and GLSL ES, written again from the run's files in
    ``folder`` (``constants.json``, ``shaders/<target>/*.reflect.json``,
    ``shaders/textures/textures.json``) exactly as the run wrote them."""
    from study.export.targets import sheets_of_export
    from study.report.calibration import report_text

    calibration = _json(folder / "constants.json")
    sheets = sheets_of_export(folder / "shaders", calibration)
    head = (
        "*Written by `scripts/build_docs.py` from the files `make run` wrote "
        "(`out/default/`), committed in `docs/results/default/`.*\n\n"
    )
    pages = {folder / "report.md": head + report_text(calibration, {}, out=Path("out/default"))}
    for target in ("hlsl", "gles300"):
        pages[folder / f"BINDINGS-{target}.md"] = head + sheets[f"{target}/BINDINGS.md"]
    return pages


def _calibration_page(folder: Path, command: str, out: Path) -> str:
    """The report of a calibration committed as its ``constants.json`` in ``folder``, written
    again from it (without the run's figures); ``command`` made it into ``out``."""
    from study.report.calibration import report_text

    head = (
        f"*Written by `scripts/build_docs.py` from the `constants.json` that {command} wrote, "
        f"committed in `docs/results/{folder.name}/`.*\n\n"
    )
    return head + report_text(_json(folder / "constants.json"), {}, out=out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="compare, write nothing; exit 1 if a page is stale, a figure is missing or a result "
        "file differs from the one its figure was drawn from",
    )
    ap.add_argument("--no-figures", action="store_true", help="write the pages only")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from study._io import write_text_atomic

    pages = generated()
    bad = stale(pages)
    if args.check:
        for p in bad:
            print(f"stale: {p.relative_to(REPO)} (run scripts/build_docs.py)", file=sys.stderr)
        problems = ledger_problems()
        for line in problems:
            print(f"figures: {line} (run scripts/build_docs.py)", file=sys.stderr)
        return 1 if bad or problems else 0
    for p in bad:
        write_text_atomic(p, pages[p])
        print(f"wrote {p.relative_to(REPO)}")
    if not args.no_figures:
        for p in draw_figures():
            print(f"drew {p.relative_to(REPO)}")
        print(f"wrote {LEDGER.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
