"""The calibration report: ``report.md`` with its tables, beside the PNG figures."""
from __future__ import annotations

from pathlib import Path


def _fmt(x, digits: int = 4) -> str:
    if x is None:
        return "-"
    if isinstance(x, (list, tuple)):
        return "(" + ", ".join(_fmt(v, digits) for v in x) + ")"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    return f"{x:.{digits}g}"


def constants_table(parameters: dict) -> list[str]:
    lines = ["| constant | default | exported | status | why |", "|---|---|---|---|---|"]
    for name, p in parameters.items():
        shown = p["fitted"] if p["fitted"] is not None else p["default"]
        lines.append(f"| `{name}` | {_fmt(p['default'])} | {_fmt(shown)} | {p.get('status', '')} | "
                     f"{p.get('reason', '')} |")
    return lines


def identifiability_table(ident: dict) -> list[str]:
    lines = ["| parameter | rel. sensitivity at start | at solution | rel. std. error at solution | decision |",
             "|---|---|---|---|---|"]
    start, sol = ident.get("start", {}), ident.get("solution", {})
    for name in start.get("names", []):
        i = start["names"].index(name)
        j = sol["names"].index(name) if name in sol.get("names", []) else None
        s1 = _fmt(sol["sensitivity"][j]) if j is not None else "-"
        se = _fmt(sol["rel_std_error"][j]) if j is not None and sol.get("rel_std_error") else "-"
        lines.append(f"| `{name}` | {_fmt(start['sensitivity'][i])} | {s1} | {se} | {start['decision'][i]} |")
    lines.append("")
    for label, d in (("start", start), ("solution", sol)):
        if d.get("singular_values"):
            sv = ", ".join(_fmt(v, 3) for v in d["singular_values"])
            lines.append(f"Singular values of the scaled Jacobian at the {label}: {sv} "
                         f"(condition number {_fmt(d.get('condition'), 3)}).")
    return lines


def write_report(out: Path, summary: dict, figures: dict) -> Path:
    """``out/report.md`` from the calibration summary (the content of constants.json)."""
    e = summary["error"]
    ref = summary["reference"]
    lines = [f"# Calibration: {summary['experiment']} ({summary['shader']})", ""]
    lines += [f"Reference: {ref['spp']} spp, measured noise {_fmt(ref['noise'], 3)} (RMS standard error on "
              f"water pixels, linear RGB). Fit at {summary['fit_resolution'][0]}x{summary['fit_resolution'][1]} "
              f"with `{summary['solver']}`: {summary['iterations']} iterations, "
              f"{'converged' if summary['converged'] else 'NOT converged'} ({summary['message']}).", ""]
    lines += ["| metric (water pixels) | default constants | fitted constants |", "|---|---|---|",
              f"| RMSE, linear RGB | {_fmt(e['rmse']['default'])} | {_fmt(e['rmse']['fitted'])} |",
              f"| FLIP (LDR, mean) | {_fmt(e['flip']['default'])} | {_fmt(e['flip']['fitted'])} |", ""]
    if "comparison" in figures:
        lines += [f"![reference | default | fitted, with error maps]({figures['comparison']})", ""]
    lines += ["## Constants", ""] + constants_table(summary["parameters"]) + [""]
    lines += ["## Identifiability", "",
              "Sensitivity: norm of the Jacobian column with respect to log(value) (a relative change), "
              "divided by the largest column norm. Standard error from the Gauss-Newton covariance "
              "s^2 (J^T J)^-1 at the solution, s^2 = ||r||^2 / (m - k), as a relative error of the value.", ""]
    lines += identifiability_table(summary["identifiability"]) + [""]
    if "loss" in figures:
        lines += ["## Convergence", "", f"![loss per iteration]({figures['loss']})", ""]
    if "diagnostics" in figures:
        d = summary.get("diagnostics", {})
        lines += ["## Shader diagnostics (fitted constants)", "",
                  f"Rays not crossing the floor within the loop cap: {_fmt(d.get('not_crossed_fraction'))} "
                  f"of water pixels; non-finite pixels: {d.get('nonfinite_pixels', '-')}; mean loop "
                  f"iterations {_fmt(d.get('iterations', {}).get('mean'))}, mean texture fetches "
                  f"{_fmt(d.get('fetches', {}).get('mean'))} per pixel.", "",
                  f"![diagnostics]({figures['diagnostics']})", ""]
    t = summary["timings"]
    lines += ["## Timings (seconds)", "", "| stage | s |", "|---|---|"]
    lines += [f"| {k} | {_fmt(v, 3)} |" for k, v in t.items()] + [""]
    lines += ["## Exported shaders", "", "`shaders/compat/` (GLSL 1.20, drop-in) and `shaders/core/` "
              "(GLSL 330 core); every file compiled with glslangValidator"
              + (f"; the exported core shader on llvmpipe vs the port with the fitted constants: "
                 f"mean |diff| {_fmt(summary['gl_check']['mean_abs'], 3)}, 99.9th percentile "
                 f"{_fmt(summary['gl_check']['p999'], 3)}." if summary.get("gl_check") else "."), ""]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path
