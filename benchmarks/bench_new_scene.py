"""A new scene to its calibrated, exported, GL-checked shader: today's path vs the fast one.

For each experiment, on a cold render cache (a fresh private ``STUDY_CACHE`` per run) and in a
fresh process (as a new user's ``study calibrate``), runs the whole calibrate job twice, side by
side: ``today`` (the settings before the fast references: automatic reference spp up to 1024,
top-down texture path traced in colour at the experiment's former ``texture_spp``) and ``new``
(the shipped defaults). Prints per stage, in wall seconds and CPU seconds of the process (all
threads; on a loaded machine CPU seconds measure the work, wall seconds the wait):

  startup (imports, backend), scene build, JIT (kernel code generation and LLVM compilation,
  all stages), reference passes, noise estimation (water mask, spread of the seeds), texture
  renders (world y, lighting / colour, albedo, walls), fit, export, GL check, rest (figures,
  report, evaluation), total;

then the fitted constants of both paths, whether the new ones lie within one standard error
(the Gauss-Newton standard error of today's fit) of today's, each path's standard error from its
reference's Monte Carlo noise alone (``rel_noise_error``), and FLIP (water pixels, full
resolution) of each path's fitted shader against *today's* reference (and against its own).
With ``--repeats N`` each run is repeated and medians are printed.

    .venv/bin/python benchmarks/bench_new_scene.py [EXPERIMENT.toml ...] [--repeats N] [--paths today new]
        [--set KEY=VALUE ...] [--json OUT.json]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

# today's path: the reference and texture settings of main before the fast references
TODAY = ["reference.texture_method=\"colour\"", "reference.spp=\"auto\"", "reference.target_noise=0.01",
         "reference.sampler=\"independent\"",
         "reference.max_spp=1024"]
# the texture_spp each shipped experiment used then (schema default 256; default and seed_lut set 1024)
TODAY_TEXTURE_SPP = {"default": 1024, "seed_lut": 1024}
STAGES = ["startup", "scene build", "JIT", "reference passes", "noise estimation", "texture renders",
          "fit", "export", "GL check", "rest", "total"]


# ------------------------------------------------------------------------------------ worker
class _Timer:
    """Exclusive wall / CPU time per stage (a stage's time excludes the stages nested in it), with
    the kernel compilation inside each stage (Dr.Jit's kernel history: code generation + LLVM
    back end, wall clock) moved to its own stage ``JIT`` (compilation runs on one thread, so its
    CPU time is taken equal to its wall time)."""

    def __init__(self, dr):
        self.dr, self.wall, self.cpu, self.stack = dr, {}, {}, []

    def _drain(self) -> None:
        hist = self.dr.kernel_history()
        jit = sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in hist) / 1e3
        self.kernels = getattr(self, "kernels", 0) + len(hist)
        self.hits = getattr(self, "hits", 0) + sum(1 for k in hist if k.get("cache_hit"))
        st = self.stack[-1][0] if self.stack else "rest"
        for d in (self.wall, self.cpu):
            d[st] = d.get(st, 0.0) - jit
            d["JIT"] = d.get("JIT", 0.0) + jit

    def wrap(self, module, name: str, stage: str):
        fn = getattr(module, name)

        def timed(*a, **k):
            self._drain()
            self.stack.append([stage, time.perf_counter(), time.process_time(), 0.0, 0.0])
            try:
                return fn(*a, **k)
            finally:
                self._drain()
                st, w0, c0, cw, cc = self.stack.pop()
                dw, dc = time.perf_counter() - w0, time.process_time() - c0
                self.wall[st] = self.wall.get(st, 0.0) + dw - cw
                self.cpu[st] = self.cpu.get(st, 0.0) + dc - cc
                if self.stack:
                    self.stack[-1][3] += dw
                    self.stack[-1][4] += dc
        setattr(module, name, timed)


def worker(experiment: str, path: str, out: Path, overrides: list[str]) -> dict:
    w_start, c_start = time.perf_counter(), time.process_time()
    import drjit as dr

    from study import _jobs
    from study._backend import init_backend
    from study.fit import calibrate
    from study.report import export
    from study.scene import experiment as exp_mod
    from study.scene import lighting, mitsuba_scene, reference, shader_inputs

    init_backend("llvm_ad_rgb")
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    name = exp_mod.load_experiment(experiment)["name"]
    sets = list(overrides)
    if path == "today":
        sets = TODAY + [f"reference.texture_spp={TODAY_TEXTURE_SPP.get(name, 256)}"] + sets
    t = _Timer(dr)
    t._drain()
    t.wall, t.cpu = {}, {}
    t.wall["startup"], t.cpu["startup"] = time.perf_counter() - w_start, time.process_time() - c_start
    t.wrap(mitsuba_scene, "build_scene", "scene build")
    t.wrap(reference, "render_passes", "reference passes")
    t.wrap(reference, "water_mask", "noise estimation")
    t.wrap(reference, "noise_of", "noise estimation")
    for fn in ("top_down_world_y", "_render_top_down", "top_down_colour"):
        t.wrap(shader_inputs, fn, "texture renders")
    for fn in ("render_lighting", "render_dry"):
        t.wrap(lighting, fn, "texture renders")
    t.wrap(calibrate, "calibrate_model", "fit")
    t.wrap(export, "export_shaders", "export")
    t.wrap(_jobs, "gl_check", "GL check")
    t.wrap(_jobs, "run_calibrate", "rest")
    w0, c0 = time.perf_counter(), time.process_time()
    summary = _jobs.run_calibrate(experiment, out, sets, cache=out / "cache")
    t.wall["total"] = t.wall["startup"] + time.perf_counter() - w0
    t.cpu["total"] = t.cpu["startup"] + time.process_time() - c0
    params = {n: {"fitted": p["fitted"], "rel_se": p.get("rel_std_error"), "rel_noise": p.get("rel_noise_error"),
                  "status": p["status"]}
              for n, p in summary["parameters"].items()}
    return {"experiment": name, "path": path, "wall": t.wall, "cpu": t.cpu, "params": params,
            "flip_own": summary["error"]["flip"]["fitted"], "rmse_own": summary["error"]["rmse"]["fitted"],
            "reference_spp": summary["reference"]["spp"], "reference_noise": summary["reference"]["noise"],
            "kernels": t.kernels, "kernel_cache_hits": t.hits}


def cross_flip(experiment: str, run_dirs: dict, overrides: list[str]) -> dict:
    """FLIP / RMSE (water pixels, full resolution) of each path's fitted constants against today's
    reference, on today's shader inputs."""
    from study._backend import drjit_backend, init_backend
    from study._metrics import errors
    from study.fit.model import ShaderModel
    from study.report.export import load_constants_json
    from study.scene.experiment import load_experiment
    from study.scene.reference import load_or_render
    from study.scene.shader_inputs import load_or_build_shader_inputs

    variant = init_backend("llvm_ad_rgb")
    base = load_experiment(experiment)
    sets = TODAY + [f"reference.texture_spp={TODAY_TEXTURE_SPP.get(base['name'], 256)}"] + overrides
    exp = load_experiment(experiment, sets)
    cache = Path(run_dirs["today"]) / "cache"
    quiet = lambda *_: None  # noqa: E731
    ref = load_or_render(exp, variant, cache=cache, log=quiet)
    inputs = load_or_build_shader_inputs(exp, variant, cache=cache, log=quiet)
    w, h = exp["resolution"]
    model = ShaderModel.from_experiment(exp, inputs, ref.image, backend=drjit_backend(variant), resolution=(w, h))
    out = {}
    for path, d in run_dirs.items():
        img, _ = model.render(load_constants_json(Path(d) / "constants.json"))
        out[path] = errors(ref.image, img, model.mask)
    return out


# ------------------------------------------------------------------------------------ driver
def _run(args_list: list[str]) -> dict:
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        res = Path(f.name)
    cmd = [sys.executable, __file__, *args_list, "--result", str(res)]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{p.stderr[-3000:]}")
    data = json.loads(res.read_text())
    res.unlink()
    return data


def _fmt(x, w=8, p=1):
    return f"{x:>{w}.{p}f}" if isinstance(x, (int, float)) else f"{'-':>{w}}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("experiments", nargs="*", default=None)
    ap.add_argument("--paths", nargs="+", default=["today", "new"], choices=["today", "new"])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--json", type=Path)
    ap.add_argument("--worker", nargs=3, metavar=("EXPERIMENT", "PATH", "OUT"), help=argparse.SUPPRESS)
    ap.add_argument("--cross", nargs=3, metavar=("EXPERIMENT", "TODAY_DIR", "NEW_DIR"), help=argparse.SUPPRESS)
    ap.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        e, p, o = args.worker
        args.result.write_text(json.dumps(worker(e, p, Path(o), args.overrides)))
        return
    if args.cross:
        e, a, b = args.cross
        args.result.write_text(json.dumps(cross_flip(e, {"today": a, "new": b}, args.overrides)))
        return

    exps = args.experiments or sorted(str(p) for p in (REPO / "experiments").glob("*.toml"))
    load = os.getloadavg()
    print(f"# bench_new_scene: {os.cpu_count()} cores, load average {load[0]:.1f} / {load[1]:.1f} / "
          f"{load[2]:.1f} at start; {args.repeats} repeat(s), medians; wall s (CPU s)", flush=True)
    results = []
    for e in exps:
        runs = {p: [] for p in args.paths}
        dirs = {}
        for r in range(args.repeats):
            for p in args.paths:              # side by side: today, new, today, new, ...
                d = Path(tempfile.mkdtemp(prefix=f"bench_{Path(e).stem}_{p}_"))
                sets = sum((["--set", s] for s in args.overrides), [])
                runs[p].append(_run(["--worker", e, p, str(d), *sets]))
                dirs[p] = d
                print(f"  {Path(e).stem} {p} run {r + 1}: {runs[p][-1]['wall']['total']:.1f} s wall", flush=True)
        cross = _run(["--cross", e, str(dirs["today"]), str(dirs["new"])]) if len(args.paths) == 2 else {}
        results.append({"experiment": Path(e).stem, "runs": runs, "cross": cross})
        _print(Path(e).stem, runs, cross)
    load = os.getloadavg()
    print(f"# load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


def _print(name: str, runs: dict, cross: dict) -> None:
    paths = list(runs)
    med = {p: {kind: {s: statistics.median(r[kind].get(s, 0.0) for r in runs[p]) for s in STAGES}
               for kind in ("wall", "cpu")} for p in paths}
    print(f"\n## {name}\n")
    print("| stage | " + " | ".join(f"{p} wall s (CPU s)" for p in paths) + " |")
    print("|---|" + "---|" * len(paths))
    for s in STAGES:
        print(f"| {s} | " + " | ".join(f"{med[p]['wall'][s]:.1f} ({med[p]['cpu'][s]:.1f})" for p in paths) + " |")
    last = {p: runs[p][-1] for p in paths}
    print("\n| | " + " | ".join(paths) + " |")
    print("|---|" + "---|" * len(paths))
    print("| reference spp, noise | " + " | ".join(f"{last[p]['reference_spp']}, {last[p]['reference_noise']:.4f}"
                                             for p in paths) + " |")
    print("| FLIP / RMSE vs own reference | " + " | ".join(f"{last[p]['flip_own']:.4f} / {last[p]['rmse_own']:.4f}"
                                                      for p in paths) + " |")
    if cross:
        print("| FLIP / RMSE vs today's reference | " + " | ".join(
            f"{cross[p]['flip']:.4f} / {cross[p]['rmse']:.4f}" for p in paths) + " |")
    print("| kernels (disk-cache hits) | " + " | ".join(f"{last[p]['kernels']} ({last[p]['kernel_cache_hits']})"
                                                    for p in paths) + " |")
    if len(paths) == 1:
        print("\n| constant | fitted (rel. SE) [status] |\n|---|---|")
        for n, pa in last[paths[0]]["params"].items():
            print(f"| {n} | {_v(pa['fitted'])} ({_v(pa['rel_se'])}) [{pa['status']}] |")
    if len(paths) == 2:
        a, b = last["today"]["params"], last["new"]["params"]
        print("\n| constant | today (rel. SE; from reference noise) | new (from reference noise) | "
              "(new - today) / SE |")
        print("|---|---|---|---|")
        for n, pa in a.items():
            pb = b.get(n, {})
            va, vb, se = pa["fitted"], pb.get("fitted"), pa["rel_se"]
            z = (vb - va) / (se * abs(va)) if None not in (va, vb, se) and se * abs(va) > 0 else None
            print(f"| {n} | {_v(va)} ({_v(se)}; {_v(pa.get('rel_noise'))}) [{pa['status']}] | {_v(vb)} "
                  f"({_v(pb.get('rel_noise'))}) [{pb.get('status')}] | {_v(z, 2)} |")
    sys.stdout.flush()


def _v(x, p=4):
    return f"{x:.{p}g}" if isinstance(x, (int, float)) else "-"


if __name__ == "__main__":
    main()
