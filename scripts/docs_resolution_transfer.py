"""The page of docs/results/resolution-transfer/: constants fitted at several resolutions, with
and without the game's pixel footprint, scored at 1920 x 1080
(``benchmarks/bench_resolution_transfer.py`` writes one JSON file per experiment there)."""

from __future__ import annotations

import json
from pathlib import Path

# the constants the table shows, where the shader fits them (the highlight and the water)
SHOWN = ("attenuation_distance", "water_color[1]", "specular_strength", "specular_exponent",
         "bumptex_mult")  # fmt: skip
STAND_IN = [960, 540]  # the fit that stands for a 1080p one on 2 cores


def resolution_transfer_page(folder: Path) -> str:
    """The Markdown of the page: one table per experiment file in ``folder``."""
    lines = [
        "# Constants for the game's resolution",
        "",
        "Each experiment's reference is path traced once at 1920 x 1080 (a reduced sample count: "
        "its measured noise is the floor under every figure). Its constants are then fitted at "
        "each fit resolution from the same start, with one sample at each fit pixel's centre, or "
        'with `fit.target_resolution = "1080p"`: each fit pixel shaded at the samples of the '
        "1080p pixels it covers (at most 4 x 4) and averaged. Every fit is scored at 1080p on the "
        "water pixels. The column 'against 960x540' is FLIP relative to the 960 x 540 fit's, the "
        "stand-in for a 1080p fit on 2 cores.",
        "",
    ]
    for path in sorted(folder.glob("*.json")):
        lines += _table(json.loads(path.read_text()))
    return "\n".join(lines) + "\n"


def _table(res: dict) -> list[str]:
    rows = res["rows"]
    # the study's shaders: the highlight and the water; a user's shader: every fitted constant
    shown = [n for n in SHOWN if any(n in r["constants"] for r in rows)] or [
        n for n in rows[0]["constants"] if rows[0]["status"].get(n) in ("fitted", "bound")
    ]
    ref = next((r for r in rows if r["fit_resolution"] == STAND_IN), None)
    ref_flip = ref["flip_1080p"] if ref else None
    head = "| fit | samples a pixel | fit seconds | FLIP at 1080p | against 960x540 | "
    lines = [
        f"## {res['experiment']} ({res['shader']})",
        "",
        f"Reference: {res['reference']['spp']} spp at 1080p, measured noise "
        f"{res['reference']['noise']:.3g} (RMS standard error on the water, linear RGB). Start "
        f"constants: FLIP {res['start']['flip_1080p']:.4f}. Machine: {res['machine']}.",
        "",
        f"Reproduce: `.venv/bin/python {res['command']}`",
        "",
        head + " | ".join(f"`{n}`" for n in shown) + " |",
        "|" + "---|" * (5 + len(shown)),
    ]
    for r in rows:
        w, h = r["fit_resolution"]
        s = r["supersample"]
        rel = f"{r['flip_1080p'] / ref_flip - 1:+.1%}" if ref_flip else "-"
        consts = " | ".join(
            f"{r['constants'][n]:.4g}" if n in r["constants"] else "-" for n in shown
        )
        lines.append(
            f"| {w}x{h} | {s}x{s} | {r['fit_seconds']:.0f} | {r['flip_1080p']:.4f} | {rel} | "
            f"{consts} |"
        )
    return lines + [""] + (_shift_table(rows, ref, shown) if ref else [])


def _shift_table(rows: list, ref: dict, shown: list) -> list[str]:
    """Each fit's relative shift of a constant from the 960 x 540 fit's against its own relative
    standard errors: Gauss-Newton's (independent residuals) and over image tiles (a model error
    shared within a tile). A shift is within an error when it is at most twice it."""
    lines = [
        "Shift of each constant from the 960x540 fit's, against the fit's own relative standard "
        "errors (Gauss-Newton; over 8 x 8-pixel image tiles): `yes` where the shift is within "
        "twice the error.",
        "",
        "| fit | samples a pixel | constant | shift | Gauss-Newton error | within | tile error | "
        "within |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r is ref:
            continue
        w, h = r["fit_resolution"]
        s = r["supersample"]
        for n in shown:
            if n not in r["constants"] or n not in ref["constants"] or not ref["constants"][n]:
                continue
            shift = abs(r["constants"][n] / ref["constants"][n] - 1)
            errs = r.get("errors", {}).get(n, {})
            gn, tiles = errs.get("gauss_newton"), errs.get("tiles")
            lines.append(
                f"| {w}x{h} | {s}x{s} | `{n}` | {shift:.1%} | {_pct(gn)} | {_within(shift, gn)} | "
                f"{_pct(tiles)} | {_within(shift, tiles)} |"
            )
    return lines + [""]


def _pct(v) -> str:
    return "-" if v is None else f"{v:.1%}"


def _within(shift: float, err) -> str:
    return "-" if err is None else ("yes" if shift <= 2 * err else "no")
