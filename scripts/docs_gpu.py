"""The tables of ``benchmarks/bench_gpu.py``: printed by the benchmark and written to
``docs/results/gpu/report.md`` by ``scripts/build_docs.py`` from the ``bench.json`` the benchmark
writes (``--json``), so the page's figures are the measured ones.

A ``bench.json`` holds one entry per invocation of the benchmark (``runs``): its command, the
machine (CPU model and cores, load averages before and after, GPU where one was found), and one
result per size and backend (stage seconds per pass, peak memory, the fit's resolution, the
reference's samples and noise, the fitted constants); ratios are taken within an invocation only.
"""

from __future__ import annotations

STAGES = ("startup", "setup", "reference", "inputs", "fit", "export", "gl")
ALWAYS = ("startup", "setup")  # timed in every run, whatever --stages picks
STAGE_NAMES = {
    "startup": "start-up (imports, backend; the first pass)",
    "setup": "setup (experiment, output folder)",
    "reference": "reference (path traced)",
    "inputs": "shader inputs",
    "fit": "fit (model, solver)",
    "export": "export",
    "gl": "GL check (llvmpipe)",
}
CPU, GPU = "llvm_ad_rgb", "cuda_ad_rgb"
MIB = 1024 * 1024


def _s(v) -> str:
    return "-" if v is None else f"{v:.1f}"


def _mib(v) -> str:
    return "-" if v is None else f"{v / MIB:.0f}"


def _ratio(a, b) -> str:
    return "-" if a is None or b is None or b <= 0 else f"{a / b:.1f}x"


def _size_text(size) -> str:
    return f"{size[0]}x{size[1]}"


def _group(results: list) -> dict:
    """{(size text, pass): {variant: (result, that pass's figures)}}, in the order run."""
    out: dict = {}
    for r in results:
        for name, p in (r.get("passes") or {}).items():
            out.setdefault((_size_text(r["size"]), name), {})[r["variant"]] = (r, p)
    return out


def _gl_check(r: dict, p: dict) -> dict:
    """The GL check's figures of a result's pass (``bench.json``), or of the result."""
    return p.get("gl_check") or r.get("gl_check") or {}


def gl_label(cols: list, by: dict, machine_gpu) -> str:
    """The GL check's row label, naming the OpenGL that ran it (``GL_RENDERER``, per backend
    where they differ); where none was recorded: llvmpipe on a machine without a GPU, "OpenGL not
    recorded" on one with a GPU (EGL may have picked the GPU's driver)."""
    known = [(c, _gl_check(*by[c]).get("gl_renderer") or by[c][0].get("gl_renderer"))
             for c in cols if c in by]  # fmt: skip
    known = [(c, g) for c, g in known if g]
    if not known:
        return "GL check (llvmpipe)" if not machine_gpu else "GL check (OpenGL not recorded)"
    if len({g for _, g in known}) == 1:
        return f"GL check ({known[0][1]})"
    return "GL check (" + "; ".join(f"{c}: {g}" for c, g in known) + ")"


def _stage_rows(cols: list, by: dict, stages: list, machine_gpu=None) -> list[str]:
    rows = []
    names = {**STAGE_NAMES, "gl": gl_label(cols, by, machine_gpu)}
    for st in [*stages, "total"]:
        vals = [by[c][1]["seconds"].get(st) if c in by else None for c in cols]
        if st == "total":
            vals = [by[c][1].get("total") if c in by else None for c in cols]
        cells = " | ".join(_s(v) for v in vals)
        ratio = f" | {_ratio(vals[0], vals[1])}" if len(cols) == 2 else ""
        rows.append(f"| {names.get(st, st)} | {cells}{ratio} |")
    return rows


def _memory_rows(cols: list, by: dict) -> list[str]:
    rows = []
    keys = [("drjit_peak", "peak Dr.Jit memory, MiB (its backend's allocator)"),
            ("rss_peak", "peak resident memory of the process, MiB"),
            ("nvidia_smi_peak", "peak GPU memory in use, MiB (nvidia-smi)")]  # fmt: skip
    for key, label in keys:
        vals = [by[c][1]["memory"].get(key) if c in by else None for c in cols]
        if all(v is None for v in vals):
            continue
        tail = " | |" if len(cols) == 2 else " |"
        rows.append(f"| {label} | {' | '.join(_mib(v) for v in vals)}{tail}")
    return rows


def _kernel_rows(cols: list, by: dict) -> list[str]:
    """Per stage the kernel ledger recorded (``study._kernels``): launches, JIT kernels compiled
    / from the cache / replayed, memory copies and their MiB, one cell per backend."""
    stages: list = []
    for c in cols:
        for st in (by[c][1].get("kernels") or {}) if c in by else {}:
            stages += [st] if st not in stages else []
    rows = []
    for st in stages:
        cells = []
        for c in cols:
            k = ((by[c][1].get("kernels") or {}) if c in by else {}).get(st)
            cells.append("-" if k is None else (
                f"{k['launches']} ({k['jit_compiled']} / {k['jit_cache_hits']} / "
                f"{k['jit_replayed']}), {k['copies']} copies {k['copy_bytes'] / 2**20:.1f} MiB"
            ))  # fmt: skip
        tail = " | |" if len(cols) == 2 else " |"
        rows.append(f"| kernels of {st}: launches (JIT compiled / cached / replayed), copies | "
                    + " | ".join(cells) + tail)  # fmt: skip
    return rows


def _setting_line(cols: list, by: dict) -> str:
    bits = []
    for c in cols:
        if c not in by:
            continue
        r = by[c][0]
        bits.append(
            f"{c}: fit at {_size_text(r['fit_resolution'])}, reference {r['spp']} spp "
            f"(noise {r['noise']:.2e}), {r['water_pixels']} water pixels in the fit"
            + ("" if r.get("gl_passed") in (None, True) else ", GL check **failed**")
            + (f" ({why})" if (why := _gl_check(r, {}).get("reason")) else "")
            + (
                f", export and GL check not run ({r['export_error']})"
                if r.get("export_error")
                else ""
            )
        )
    return "; ".join(bits) + "."


def invocation_lines(inv: dict) -> list[str]:
    """The tables of one invocation (``bench.json``'s ``runs`` entry): per size and pass, the
    stages in seconds on each backend and their ratio, then peak memory."""
    m = inv["machine"]
    gpu = m.get("gpu") or "none found"
    lines = [
        f"Command: `{inv['command']}`",
        "",
        f"Machine: {m['cpu']} ({m['cores']} cores), GPU: {gpu}; load average "
        f"{m['load_before'][0]:.1f} before, {m['load_after'][0]:.1f} after"
        + (f" ({m['note']})" if m.get("note") else "")
        + ". Overrides: "
        + (", ".join(f"`{o}`" for o in inv["overrides"]) or "none")
        + ".",
        "",
    ]
    stages = inv["stages"]
    for (size, name), by in _group(inv["results"]).items():
        cols = [c for c in (CPU, GPU) if c in by]
        head = " | ".join(f"{c} s" for c in cols) + (" | CPU / GPU" if len(cols) == 2 else "")
        lines += [f"**{size}, {name}.** " + _setting_line(cols, by), ""]
        lines += [f"| stage | {head} |", "|---|" + "---|" * (len(cols) + (len(cols) == 2))]
        lines += _stage_rows(cols, by, stages, m.get("gpu")) + _memory_rows(cols, by)
        lines += _kernel_rows(cols, by) + [""]
    for r in inv["results"]:
        if r.get("error"):
            lines += [
                f"{_size_text(r['size'])} on {r['variant']}: not measured ({r['error']}).",
                "",
            ]
    for size, p in (inv.get("parity") or {}).items():
        worst = max((abs(v["z"]) for v in p.values()), default=0.0)
        cpu = f" (the CPU's from `{inv['parity_with']}`)" if inv.get("parity_with") else ""
        lines.append(
            f"Parity at {size}: the fitted constants on the GPU minus those on the CPU{cpu}, in "
            f"their combined standard errors: largest |z| = {worst:.2f}; "
            + ", ".join(f"{n} {v['z']:+.2f}" for n, v in p.items())
            + "."
        )
    return lines


def gpu_bench_page(bench: dict) -> str:
    """``docs/results/gpu/report.md``: every invocation of ``bench.json``."""
    lines = [
        "# The calibration's stages on the CPU and on a GPU",
        "",
        "Written by `scripts/build_docs.py` from `bench.json` (`benchmarks/bench_gpu.py --json`). "
        "Each table comes from one invocation: its columns ran in that invocation, one after the "
        "other, each in a fresh process; a `cold` pass starts with empty render and kernel "
        "caches, a `warm` pass follows it in the same process with an empty render cache.",
        "",
    ]
    for inv in bench["runs"]:
        lines += [f"## {inv['title']}", ""] + invocation_lines(inv)
    return "\n".join(lines).rstrip("\n") + "\n"
