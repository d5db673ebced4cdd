"""The reports' identifiability section: per constant its sensitivities and standard errors
(Gauss-Newton, over image tiles, from the reference's noise), and the decisions taken."""

from __future__ import annotations

from .numbers import fmt


def identifiability_section(summary: dict) -> list[str]:
    """The section of a calibration's report: what the columns are, then the table."""
    intro = (
        "Sensitivity: norm of the Jacobian column with respect to log(value) (a relative "
        "change), divided by the largest column norm. Standard error from the Gauss-Newton "
        "covariance s^2 (J^T J)^-1 at the solution, s^2 = ||r||^2 / (m - k), as a relative error "
        "of the value: it holds when the residuals are independent noise. Over image tiles: the "
        "sandwich (J^T J)^-1 (sum over 8 x 8-pixel tiles of J_t^T r_t r_t^T J_t) (J^T J)^-1, "
        "which holds when the shader's error is shared within a tile (a glint it puts elsewhere, "
        "a wave it lacks); where it is well above the first, the constants move with the "
        "resolution and the scene by more than the Gauss-Newton error says."
    )
    table = identifiability_table(summary["identifiability"], summary["parameters"])
    return ["## Identifiability", "", intro, ""] + table + [""]


def identifiability_table(ident: dict, parameters: dict | None = None) -> list[str]:
    """The identifiability table: per constant its sensitivities, standard errors, the decision
    at the start and, given the ``parameters`` table, its status at the end (the one the
    Constants table gives)."""
    lines = [
        "| parameter | rel. sensitivity at start | at solution | rel. std. error at solution | "
        "rel. std. error over image tiles | rel. error from reference noise | "
        "decision at the start | status |",
        "|---|---|---|---|---|---|---|---|",
    ]
    parameters = parameters or {}
    start, sol = ident.get("start", {}), ident.get("solution", {})
    for name in start.get("names", []):
        i = start["names"].index(name)
        j = sol["names"].index(name) if name in sol.get("names", []) else None
        s1 = fmt(sol["sensitivity"][j]) if j is not None else "-"
        se = fmt(sol["rel_std_error"][j]) if j is not None and sol.get("rel_std_error") else "-"
        ne = fmt(sol["rel_noise_error"][j]) if j is not None and sol.get("rel_noise_error") else "-"
        te = fmt(sol["rel_tile_error"][j]) if j is not None and sol.get("rel_tile_error") else "-"
        status = parameters.get(name, {}).get("status", "-")
        lines.append(
            f"| `{name}` | {fmt(start['sensitivity'][i])} | {s1} | {se} | {te} | {ne} | "
            f"{start['decision'][i]} | {status} |"
        )
    lines.append("")
    for label, d in (("start", start), ("solution", sol)):
        if d.get("singular_values"):
            sv = ", ".join(fmt(v, 3) for v in d["singular_values"])
            lines.append(
                f"Singular values of the scaled Jacobian at the {label}: {sv} "
                f"(condition number {fmt(d.get('condition'), 3)})."
            )
    return lines
