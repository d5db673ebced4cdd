"""The page of docs/results/normal-equations/: a fit's seconds with the least-squares system
handed to the solver whole (``fit.normal_equations = "solver"``) or formed where the shader
runs (``"device"``), from the ``bench.json`` that ``benchmarks/bench_normal_equations.py``
writes."""

from __future__ import annotations

FORMS = ("solver", "device")


def _mb(v: float) -> str:
    return f"{v / 1e6:.2f} MB" if v >= 1e4 else f"{v / 1e3:.2f} kB"


def normal_equations_page(bench: dict) -> str:
    """The Markdown of the page."""
    rows = bench["rows"]
    lines = [
        "# The fit's system on the device",
        "",
        "Each fit recovers seven constants of `water_refraction` (the water's colour, its "
        "attenuation, the highlight's strength and exponent, the bump scale) from a target "
        "rendered at known constants on the tests' synthetic pool, with Levenberg-Marquardt and "
        "the calibration's settings. `solver`: the solver receives the residual and the "
        "Jacobian, three rows a water pixel. `device`: Dr.Jit forms J^T J, J^T r and r^T r from "
        "the shader's lanes and the solver receives k + 1 rows with the same normal equations "
        '(`fit.normal_equations = "device"`). Both in one process, side by side. '
        f"Machine: {bench['machine']}; load average {bench['load_average_after'][0]:.1f} at the "
        "end.",
        "",
        f"Reproduce: `.venv/bin/python {bench['command']}`",
        "",
        "| size | residuals | form | one Jacobian evaluation, s | bytes read back | fit, s "
        "(first: with the solver's compile) | fit, s (again) | of it in the model, s | steps | "
        "evaluations |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for form in FORMS:
            f = r["forms"][form]
            ev, cold, warm = f["evaluation"], f["fits"][0], f["fits"][1]
            lines.append(
                f"| {r['size']}x{r['size']} | {r['residuals']:,} | `{form}` | "
                f"{ev['seconds']:.3f} | {_mb(ev['read_back_bytes'])} | {cold['seconds']:.2f} | "
                f"{warm['seconds']:.2f} | {warm['seconds_in_model']:.2f} | {warm['steps']} | "
                f"{warm['jacobian_evaluations']} |"
            )
    lines += [
        "",
        "Of it in the model: the seconds of the fit spent in the model's evaluations (the shader "
        "on its backend and what is read back); the rest is the solver on the host.",
        "",
        "Bytes read back: what one evaluation hands to the host (from the arrays' sizes): the "
        "image, its mask and diagnostics and the Jacobian's lanes, against the (k + 1)^2 Gram "
        "matrix and a count. On the CPU backend NumPy shares Dr.Jit's memory; on a GPU these "
        "bytes cross the bus at every evaluation.",
        "",
        "The two forms' fitted constants differ by at most (relative): "
        + ", ".join(
            f"{r['max_rel_constant_difference']:.1e} at {r['size']}x{r['size']}" for r in rows
        )
        + ".",
        "",
        "## Kernels of one evaluation",
        "",
        "From Dr.Jit's kernel history (`study._kernels`): launches, of them JIT kernels "
        "compiled / taken from the kernel cache / replayed from a frozen recording, and the "
        "launches by kind.",
        "",
        "| size | form | launches | JIT compiled / cached / replayed | by kind |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        for form in FORMS:
            k = r["forms"][form]["evaluation"]["kernels"]
            kinds = ", ".join(f"{n} {c}" for n, c in sorted(k["by_kind"].items()))
            lines.append(
                f"| {r['size']}x{r['size']} | `{form}` | {k['launches']} | "
                f"{k['jit_compiled']} / {k['jit_cache_hits']} / {k['jit_replayed']} | {kinds} |"
            )
    return "\n".join(lines) + "\n"
