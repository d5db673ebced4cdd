"""The whole calibration at a game's resolution: the stages of ``study calibrate`` on the CPU
and, where Dr.Jit finds a CUDA device, on the GPU, side by side from one run, with peak memory.

For each size (``--sizes``: ``WxH`` or a preset, ``720p`` / ``1080p`` / ``1440p``; default
256x256 and 1920x1080) and backend (``--backends``; default ``llvm_ad_rgb``, and ``cuda_ad_rgb``
when a CUDA device is present), a fresh process runs the stages of the calibrate command on the
experiment (default ``experiments/default.toml``) with ``resolution`` the size and
``fit.resolution = "auto"`` (the tool's choice for the device; ``--set`` overrides either):

* ``reference``: the path-traced reference (``study.scene.reference.load_or_render``);
* ``inputs``: the shader inputs (top-down textures and lighting, ``load_or_build_shader_inputs``);
* ``fit``: the model at ``fit.resolution`` and the solver (``study.commands.calibrate.fit_still``);
* ``export``: the fitted shader, its engine targets and textures written
  (``study.calibration.export.write_export``);
* ``gl``: the exported shader run on the OpenGL that headless EGL gives (Mesa llvmpipe on the
  CPU; on a GPU machine its driver, e.g. NVIDIA's) against the port on the backend, at the size
  (the same call). Each pass records the check's figures, its reason when it fails, the pixels it
  explains with their reasons and ``GL_RENDERER`` (``gl_check``; the result's ``gl_renderer``).

``--stages`` picks the stages printed; the stages before the last one picked run too (a fit
needs its reference; export and GL check are one call). Passes (``--passes``): ``cold`` starts
with empty render and kernel caches (Dr.Jit's, CUDA's and OptiX's in a fresh folder), ``warm``
follows in the same process with an empty render cache (kernels compiled). Peak memory per pass:
Dr.Jit's allocator watermark of the backend (host memory on LLVM, device memory on CUDA), the
process's peak resident memory, and on CUDA the peak of ``nvidia-smi``'s memory in use, sampled.
Kernels per pass and stage (``kernels``: ``study._kernels.KernelLedger``): launches by kind, JIT
kernels compiled, found in the kernel cache or replayed, memory copies and their bytes (on a
GPU, the host-device transfers). Ratios are CPU seconds over GPU seconds of the same
invocation. ``--parity`` compares the fitted constants of the two backends at each size in their
combined standard errors.

    .venv/bin/python benchmarks/bench_gpu.py [--sizes 256x256 1080p] [--backends llvm_ad_rgb
        cuda_ad_rgb] [--stages reference inputs fit export gl] [--passes cold warm]
        [--experiment E.toml] [--set KEY=VALUE ...] [--parity] [--title T] [--note N]
        [--json OUT.json [--append]] [--timeout S] [--dry-run]

``--json`` writes (or with ``--append`` adds to) the file ``scripts/build_docs.py`` turns into
``docs/results/gpu/report.md`` (tables: ``scripts/docs_gpu.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

from docs_gpu import ALWAYS, CPU, GPU, STAGES, invocation_lines  # noqa: E402

DEFAULT_SIZES = ("256x256", "1920x1080")
PASSES = ("cold", "warm")


def parse_size(text: str) -> list[int]:
    """``[width, height]`` of ``WxH`` or of a preset name (``study.config.resolution.PRESETS``)."""
    from study.config.resolution import PRESETS

    if text in PRESETS:
        return list(PRESETS[text])
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise SystemExit(f"--sizes {text!r}: give WxH (e.g. 1920x1080) or one of {list(PRESETS)}")
    return [w, h]


def cuda_present() -> bool:
    """Whether Dr.Jit finds a CUDA device on this machine."""
    import drjit as dr

    return bool(dr.has_backend(dr.JitBackend.CUDA))


# ------------------------------------------------------------------------------------ worker
class GpuMemory:
    """Peak of ``nvidia-smi``'s memory in use on device 0 (bytes) over the block, sampled every
    ``interval`` seconds in a thread; None without ``nvidia-smi``."""

    def __init__(self, interval: float = 0.25):
        self.exe, self.interval, self.peak = shutil.which("nvidia-smi"), interval, None
        self._stop = threading.Event()

    def _used(self) -> int | None:
        q = [self.exe, "--query-gpu=memory.used", "--format=csv,noheader,nounits", "-i", "0"]
        try:
            return int(subprocess.check_output(q, text=True, timeout=10).split()[0]) * 1024**2
        except (OSError, subprocess.SubprocessError, ValueError, IndexError):
            return None

    def _loop(self):
        while not self._stop.is_set():
            v = self._used()
            if v is not None:
                self.peak = v if self.peak is None else max(self.peak, v)
            self._stop.wait(self.interval)

    def __enter__(self):
        if self.exe:
            self._thread = threading.Thread(target=self._loop, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        if self.exe:
            self._stop.set()
            self._thread.join()
        return False


def _one_pass(spec: dict, root: Path) -> dict:
    """One pass of the stages (module doc) in a fresh render cache under ``root``: seconds per
    stage, peak memory, and what the fit found."""
    import drjit as dr

    from study._kernels import KernelLedger
    from study.calibration.export import fit_status, write_export
    from study.calibration.fitting import FitOptions, fit_frames
    from study.calibration.frames import Frame, load_scene_data, prepare
    from study.calibration.shader import Shader
    from study.export.result import jsonable

    last = max(STAGES.index(s) for s in spec["stages"])
    seconds: dict = {}
    t0 = time.perf_counter()
    exp, variant, out = prepare(
        spec["experiment"], root / "out", spec["overrides"], spec["variant"]
    )
    seconds["setup"] = time.perf_counter() - t0
    be = dr.JitBackend.CUDA if variant.startswith("cuda") else dr.JitBackend.LLVM
    dr.detail.malloc_clear_statistics()
    with GpuMemory() if be == dr.JitBackend.CUDA else _Null() as gpu, KernelLedger() as ledger:
        ref, inputs, t = load_scene_data(exp, variant, root / "cache")
        ledger.take("reference and inputs")
        seconds["reference"], seconds["inputs"] = t["reference_s"], t["inputs_s"]
        res = {"fit_resolution": exp.fit.resolution, "spp": ref.spp, "noise": ref.noise}
        if last >= STAGES.index("fit"):
            timings: dict = {}
            shader, t1 = Shader.of(exp), time.perf_counter()
            fit = fit_frames([Frame.of(exp, ref, inputs)], shader, variant, FitOptions.of(exp))
            seconds["fit"] = time.perf_counter() - t1
            ledger.take("fit")
            model, cal = fit.models[0], fit.calibration
            res["water_pixels"] = int(model.mask.sum())
            res["params"] = {
                n: {"fitted": p["fitted"], "rel_se": p.get("rel_std_error"), "status": p["status"]}
                for n, p in cal.parameters.items()
            }
            if last >= STAGES.index("export"):
                try:
                    status = fit_status(cal.parameters)
                    export = write_export(shader, exp, [inputs], cal.fitted, status, out,
                                          variant, timings)  # fmt: skip
                    res["gl_passed"] = export.gl[0].get("passed")
                    res["gl_check"] = jsonable(export.gl[0])  # its figures: why it failed
                    res["gl_renderer"] = res["gl_check"].get("gl_renderer")
                except RuntimeError as exc:  # no OpenGL / glslang here: the other stages stand
                    res["export_error"] = f"{type(exc).__name__}: {exc}"[:300]
                seconds["export"] = timings.get("export_s")
                seconds["gl"] = timings.get("gl_check_s")
                ledger.take("export and GL check")
    memory = {
        "drjit_peak": int(dr.detail.malloc_watermark(be)),
        "rss_peak": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
        "nvidia_smi_peak": getattr(gpu, "peak", None),
    }
    res.setdefault("water_pixels", None)
    shown = [s for s in STAGES if s in spec["stages"] or s in ALWAYS]
    total = sum(seconds[s] for s in shown if seconds.get(s) is not None)
    return {**res, "seconds": seconds, "total": total, "memory": memory, "kernels": ledger.stages}


class _Null:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def worker(spec: dict) -> dict:
    """Every pass of ``spec`` (size, variant, stages, passes, overrides) in this process."""
    t0 = time.perf_counter()
    from study._backend import init_backend
    from study.calibration import export, fitting, frames  # noqa: F401  (before the clock stops)

    init_backend(spec["variant"])  # a refusal (no CUDA) is the result's error
    startup = time.perf_counter() - t0
    root = Path(spec["root"])
    passes, last = {}, {}
    for i, name in enumerate(spec["passes"]):
        last = _one_pass(spec, root / name)
        if i == 0:
            last["seconds"] = {"startup": startup, **last["seconds"]}
            last["total"] += startup
        passes[name] = {k: last[k] for k in ("seconds", "total", "memory", "kernels")}
        if "gl_check" in last:  # the check of this pass: figures, reason, explained pixels, GL
            passes[name]["gl_check"] = last["gl_check"]
    keep = ("fit_resolution", "spp", "noise", "water_pixels", "params", "gl_passed", "gl_check",
            "gl_renderer", "export_error")  # fmt: skip
    return {"size": spec["size"], "variant": spec["variant"], "passes": passes,
            **{k: last.get(k) for k in keep}}  # fmt: skip


# ------------------------------------------------------------------------------------ driver
def _worker_env(root: Path) -> dict:
    """The environment of a worker: private render cache, fresh Dr.Jit / CUDA / OptiX kernel
    caches (a cold start), the repository on the path."""
    env = dict(os.environ, STUDY_CACHE=str(root / "cache"))
    for key, sub in (("DRJIT_CACHE_DIR", "drjit"), ("CUDA_CACHE_PATH", "cuda"),
                     ("OPTIX_CACHE_PATH", "optix")):  # fmt: skip
        (root / sub).mkdir(parents=True, exist_ok=True)
        env[key] = str(root / sub)
    env["PYTHONPATH"] = os.pathsep.join(
        [str(REPO)] + [p for p in [os.environ.get("PYTHONPATH")] if p]
    )
    return env


def run_worker(spec: dict, timeout: float) -> dict:
    """``spec`` in a fresh process; its result, or the error that stopped it."""
    root = Path(spec["root"])
    root.mkdir(parents=True, exist_ok=True)
    (root / "spec.json").write_text(json.dumps(spec))
    cmd = [sys.executable, __file__, "--worker", str(root / "spec.json")]
    try:
        p = subprocess.run(cmd, env=_worker_env(root), capture_output=True, text=True,
                           timeout=timeout)  # fmt: skip
    except subprocess.TimeoutExpired:
        return {"size": spec["size"], "variant": spec["variant"], "error": f"over {timeout:.0f} s"}
    result = root / "result.json"
    if p.returncode != 0 or not result.is_file():
        why = (p.stderr.strip().splitlines() or ["no output"])[-1][:300]
        return {"size": spec["size"], "variant": spec["variant"], "error": why}
    return json.loads(result.read_text())


def cpu_results_from(path: str, overrides: list) -> list:
    """The CPU results of the invocations in the ``bench.json`` at ``path`` that ran with the same
    ``--set`` overrides (the other side of a parity check run on another machine), latest last."""
    out = []
    for inv in json.loads(Path(path).read_text())["runs"]:
        if sorted(inv["overrides"]) == sorted(overrides):
            out += [r for r in inv["results"] if r["variant"] == CPU and r.get("params")]
    if not out:
        raise SystemExit(f"--parity-with {path}: no CPU result with the overrides {overrides}")
    return out


def parity(results: list) -> dict:
    """{size: {constant: {"cpu", "gpu", "z"}}}: the GPU's fitted value minus the CPU's over the
    root sum of squares of their standard errors, for each constant both fitted."""
    by: dict = {}
    for r in results:
        if r.get("params"):
            by.setdefault(f"{r['size'][0]}x{r['size'][1]}", {})[r["variant"]] = r["params"]
    out = {}
    for size, v in by.items():
        if CPU not in v or GPU not in v:
            continue
        rows = {}
        for n, a in v[CPU].items():
            b = v[GPU].get(n)
            if not b or a["status"] != "fitted" or b["status"] != "fitted":
                continue
            se = [abs(p["rel_se"] * p["fitted"]) for p in (a, b) if p.get("rel_se") is not None]
            if len(se) == 2 and sum(s * s for s in se) > 0:
                z = (b["fitted"] - a["fitted"]) / sum(s * s for s in se) ** 0.5
                rows[n] = {"cpu": a["fitted"], "gpu": b["fitted"], "z": z}
        out[size] = rows
    return out


def machine(gpu: bool) -> dict:
    """CPU model and cores, load averages now, the GPU's name (nvidia-smi) where there is one."""
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(x.split(":", 1)[1].strip() for x in f if x.startswith("model name"))
    except (OSError, StopIteration):
        pass
    name = None
    if gpu and shutil.which("nvidia-smi"):
        q = ["nvidia-smi", "--query-gpu=name,memory.total", "--format=csv,noheader"]
        name = subprocess.run(q, capture_output=True, text=True).stdout.strip() or None
    return {"cpu": cpu, "cores": os.cpu_count(), "load_before": list(os.getloadavg()),
            "gpu": name, "python": platform.python_version()}  # fmt: skip


def _args(argv):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--sizes", nargs="+", default=list(DEFAULT_SIZES))
    ap.add_argument("--backends", nargs="+", choices=[CPU, GPU], default=None)
    picks = [s for s in STAGES if s not in ALWAYS]
    ap.add_argument("--stages", nargs="+", choices=picks, default=picks)
    ap.add_argument("--passes", nargs="+", choices=PASSES, default=["cold"])
    ap.add_argument("--experiment", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--parity", action="store_true", help="compare the fitted constants")
    ap.add_argument(
        "--parity-with", default=None, metavar="BENCH.json",
        help="the CPU side of --parity from an earlier --json run with the same overrides",
    )  # fmt: skip
    ap.add_argument("--title", default=None, help="the invocation's heading in the docs page")
    ap.add_argument("--note", default=None, help="a remark on the machine (e.g. busy)")
    ap.add_argument("--json", default=None, help="write the results here")
    ap.add_argument("--append", action="store_true", help="add to the --json file's runs")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per worker")
    ap.add_argument("--out", default=None, help="work folder (default: a temporary one)")
    ap.add_argument("--dry-run", action="store_true", help="print the workers, run nothing")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    return ap.parse_args(argv)


def _specs(a, root: Path, backends: list) -> list[dict]:
    specs = []
    for text in a.sizes:
        w, h = parse_size(text)
        keys = {o.split("=", 1)[0].strip() for o in a.overrides}
        sets = [f"resolution=[{w}, {h}]"] * ("resolution" not in keys)
        sets += ['fit.resolution="auto"'] * ("fit.resolution" not in keys)
        for b in backends:
            specs.append({"experiment": a.experiment, "size": [w, h], "variant": b,
                          "stages": a.stages, "passes": a.passes, "overrides": sets + a.overrides,
                          "root": str(root / f"{w}x{h}_{b}")})  # fmt: skip
    return specs


def main(argv=None) -> int:
    a = _args(argv)
    if a.worker:
        spec = json.loads(Path(a.worker).read_text())
        result = worker(spec)
        (Path(spec["root"]) / "result.json").write_text(json.dumps(result))
        return 0
    gpu = cuda_present()
    backends = a.backends or ([CPU, GPU] if gpu else [CPU])
    root = Path(a.out or ("OUT" if a.dry_run else tempfile.mkdtemp(prefix="bench_gpu_")))
    specs = _specs(a, root, backends)
    if a.dry_run:
        for s in specs:
            print(json.dumps(s))
        print(f"{len(specs)} worker(s); CUDA device present: {gpu}")
        return 0
    other = cpu_results_from(a.parity_with, a.overrides) if a.parity_with else []
    m = machine(gpu)
    results = []
    for s in specs:
        print(f"bench_gpu: {s['size'][0]}x{s['size'][1]} on {s['variant']} ...", file=sys.stderr)
        results.append(run_worker(s, a.timeout))
    m["load_after"] = list(os.getloadavg())
    m["note"] = a.note
    inv = {"title": a.title or f"{', '.join(a.sizes)} on {', '.join(backends)}",
           "command": shlex.join(["benchmarks/bench_gpu.py", *(argv or sys.argv[1:])]),
           "machine": m, "overrides": a.overrides, "stages": [*ALWAYS, *a.stages],
           "results": results, "parity": parity(other + results) if a.parity else None,
           "parity_with": a.parity_with}  # fmt: skip
    print("\n".join(invocation_lines(inv)))
    if a.json:
        path = Path(a.json)
        bench = json.loads(path.read_text()) if a.append and path.is_file() else {"runs": []}
        bench["runs"].append(inv)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(bench, indent=1) + "\n")
    return 1 if any(r.get("error") for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
