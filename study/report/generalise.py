"""Reports of the joint (multi-scene) fit and of leave-one-scene-out validation (Markdown).

Inputs are the JSON-able summaries written by ``study.commands.joint.run_calibrate_joint`` /
``run_generalise`` (constants.json / generalise.json); errors are on water pixels at each
experiment's full resolution (RMSE in linear RGB, mean FLIP).
"""

from __future__ import annotations

from pathlib import Path

from .._io import write_text_atomic
from .calibration import constants_table, fit_steps_line, fmt
from .identifiability import identifiability_table


def joint_lines(summary: dict) -> list[str]:
    lines = [
        f"# Joint calibration over {len(summary['scenes'])} scenes ({summary['shader']})",
        "",
        "One constants block fitted on every scene at once; residuals stacked, each scene weighted "
        "equally (its residual times sqrt(mean size / its size)). Solver "
        f"`{summary['solver']}`: {fit_steps_line(summary)}",
        "",
        "| scene | weight | RMSE start | RMSE joint | FLIP start | FLIP joint |",
        "|---|---|---|---|---|---|",
    ]
    for name in summary["scenes"]:
        e = summary["error"][name]
        lines.append(
            f"| {name} | {fmt(summary['weights'][name], 3)} | {fmt(e['default']['rmse'])} | "
            f"{fmt(e['fitted']['rmse'])} | {fmt(e['default']['flip'])} | "
            f"{fmt(e['fitted']['flip'])} |"
        )
    lines += ["", "## Constants", ""] + constants_table(summary["parameters"]) + [""]
    lines += (
        ["## Identifiability (joint Jacobian)", ""]
        + identifiability_table(summary["identifiability"], summary["parameters"])
        + [""]
    )
    gl = summary.get("gl_check")
    if gl:
        lines += [
            f"Exported shaders in `shaders/`; GL check on the first scene: mean |diff| "
            f"{fmt(gl.get('mean_abs'), 3)}, {'passed' if gl.get('passed') else '**MISMATCH**'}.",
            "",
        ]
    return lines


def write_joint_report(out: Path, summary: dict) -> Path:
    path = Path(out) / "report.md"
    write_text_atomic(path, "\n".join(joint_lines(summary)))
    return path


def loso_table(rows: list[dict]) -> list[str]:
    """FLIP (and RMSE) of each left-out scene under the seed's, the others', the first scene's
    and its own constants."""
    first = rows[0]["scene"] if rows else ""
    lines = [
        f"| left-out scene | FLIP original | FLIP others' fit | FLIP {first}'s fit | FLIP own "
        f"fit | RMSE original | RMSE others' fit | RMSE {first}'s fit | RMSE own fit |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        o, f = r.get("others") or {}, r.get("first") or {}
        lines.append(
            f"| {r['scene']} | {fmt(r['seed']['flip'])} | {fmt(o.get('flip'))} | "
            f"{fmt(f.get('flip'))} | {fmt(r['own']['flip'])} | {fmt(r['seed']['rmse'])} | "
            f"{fmt(o.get('rmse'))} | {fmt(f.get('rmse'))} | {fmt(r['own']['rmse'])} |"
        )
    return lines


def universality_table(uni: dict, scenes: list[str]) -> list[str]:
    """Per constant: the joint value, each scene's own value +- standard error, max |z|, verdict."""
    lines = [
        "| constant | joint | " + " | ".join(scenes) + " | max abs z | verdict |",
        "|---|---|" + "---|" * len(scenes) + "---|---|",
    ]
    for n, u in uni.items():
        cells = []
        for s in scenes:
            d = u["scenes"].get(s, {})
            if d.get("se") is not None:
                cells.append(f"{fmt(d['value'])} +- {fmt(d['se'], 2)}")
            else:
                cells.append(f"{d.get('status', '-')}")
        lines.append(
            f"| `{n}` | {fmt(u['joint'])} | "
            + " | ".join(cells)
            + f" | {fmt(u['max_abs_z'], 3)} | {u['verdict']} |"
        )
    return lines


def write_generalise_report(out: Path, summary: dict) -> Path:
    """``out/generalise.md`` (:func:`generalise_report_text`)."""
    path = Path(out) / "generalise.md"
    write_text_atomic(path, generalise_report_text(summary))
    return path


def generalise_report_text(summary: dict) -> str:
    """The Markdown of ``generalise.md`` from ``generalise.json``'s content (also the docs'
    generated page)."""
    lines = [
        "# Constants that generalise",
        "",
        "Leave-one-scene-out: each scene scored (water pixels, full resolution) under the original "
        "shader's constants, the constants fitted jointly on the *other* scenes, those fitted on "
        "the first scene alone (what a block fitted on one view or scene loses on the others), "
        "and its own fit.",
        "",
    ]
    lines += loso_table(summary["leave_one_out"]) + [""]
    lines += [
        "## Universal or scene-specific",
        "",
        "Each scene's own fitted value +- its standard error (Gauss-Newton, a lower bound under "
        "correlated model error) against the joint value; universal when every scene fitted it and "
        "lies within 2 standard errors of the joint value (|z| <= 2), "
        "scene-specific when some scene "
        "lies further. A constant frozen or bound in a scene shows its status there.",
        "",
    ]
    lines += universality_table(summary["universality"], summary["scenes"]) + [""]
    lines += ["", "---", ""] + joint_lines(summary["joint"])
    return "\n".join(lines)
