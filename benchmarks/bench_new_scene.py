"""A new scene to its calibrated, exported, GL-checked shader: today's path vs the fast one.

For each experiment, on a cold render cache (a fresh private ``STUDY_CACHE`` per run) and in a
fresh process (as a new user's ``study calibrate``), runs the whole calibrate job once per path,
side by side:

* ``today``: the settings before the fast references (automatic reference spp up to 1024,
  independent samples, top-down texture path traced in colour at the experiment's former
  ``texture_spp``);
* ``new``: the shipped defaults;
* ``clean`` (optional, 10-15 min a scene): today's reference with a 2048-spp colour texture, the
  yardstick where today's 256-spp texture biases the fit (noise in the shader's inputs biases
  the constants it meets, unlike zero-mean noise in the reference: the attenuation distance
  shortens as the texture's noise grows, ``study.fit.decorrelated``);
* ``converged`` (optional, ~15 s a run more than ``new``): the new path with 16x the sun's
  photons, 4x the sky's directions and 4x the samples of the bounced light (scenes whose direct
  light is traced): its fits against the new path's at the same seeds (the same reference, so
  the per-seed differences are the textures' alone) measure the bias the new path's own texture
  noise leaves.

Prints per stage, in wall seconds and CPU seconds of the process (all threads; on a loaded
machine CPU seconds measure the work, wall seconds the wait):

  startup (imports, backend), scene build, JIT (kernel code generation and LLVM compilation,
  all stages), reference passes, noise estimation (water mask, spread of the seeds), texture
  renders (world y, lighting / colour, albedo, walls, the traced direct light), fit, export, GL
  check, rest (figures, report, evaluation), total;

then the fitted constants of each path against the *baseline* (``--baseline``, by default
``clean`` when run, else ``today``): the difference in the baseline's Gauss-Newton standard
errors, each path's standard error from its reference's Monte Carlo noise alone
(``rel_noise_error``), and FLIP (water pixels, full resolution) of each path's fitted shader
against the baseline's reference (and against its own). With ``--seeds N`` the paths named by \
``--seed-paths`` (default: the new one) run with
``reference.seed = 0 .. N-1`` (reference, texture, lighting and dry renders all reseeded): their
constants are given as mean and standard deviation over the seeds, the difference from the
baseline also in that standard deviation (what a user rerunning the scene would see move), and
the stage times are medians over the seeds. When the baseline itself runs over seeds, its seed
standard deviation is the measured standard error of one of its fits (reference *and* texture
noise, and the basin a fit lands in, which the Gauss-Newton standard error leaves out), and the
difference of the means is given in it too, with the standard error of that difference; where
a path ran the baseline's own references (same seeds, same reference settings and variant:
``new`` against ``converged``), the per-seed differences are averaged as well, the reference's
noise cancelling in them. With ``--repeats N`` each run is repeated and medians are printed.

``--merge A.json B.json ...`` prints the tables of earlier ``--json`` results together (the runs
of one experiment joined by path; a path in a later file replaces the earlier one's), e.g. the
baseline's seeds run on a GPU beside the new path's on the CPU; each path's variant is printed.

    .venv/bin/python benchmarks/bench_new_scene.py [EXPERIMENT.toml ...] [--repeats N]
        [--paths today new clean converged] [--seeds N] [--seed-paths today new converged]
        [--baseline PATH] [--variant cuda_ad_rgb] [--set KEY=VALUE ...] [--json OUT.json]
    .venv/bin/python benchmarks/bench_new_scene.py --merge A.json B.json [--baseline PATH]
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
TODAY = [
    'reference.texture_method="colour"',
    'reference.spp="auto"',
    "reference.target_noise=0.01",
    'reference.sampler="independent"',
    "reference.max_spp=1024",
]
# the texture_spp each shipped experiment used then
# (schema default 256; default and seed_lut set 1024)
TODAY_TEXTURE_SPP = {"default": 1024, "seed_lut": 1024}
CLEAN_TEXTURE_SPP = 2048  # the clean yardstick's colour texture
# the new path with its traced texture's noise cut 4x in standard deviation (the schema's
# defaults x 16 photons, x 4 directions and samples); the reference unchanged
CONVERGED = ["reference.sun_photons=256", "reference.sky_directions=144", "reference.bounce_spp=64"]
PATHS = ("today", "new", "clean", "converged")


def path_settings(path: str, name: str) -> list[str]:
    """``--set`` overrides of ``path`` for the experiment called ``name`` (``new``: none)."""
    if path == "today":
        return TODAY + [f"reference.texture_spp={TODAY_TEXTURE_SPP.get(name, 256)}"]
    if path == "clean":
        return TODAY + [f"reference.texture_spp={CLEAN_TEXTURE_SPP}"]
    if path == "converged":
        return list(CONVERGED)
    return []


def pick_baseline(paths, wanted: str | None) -> str | None:
    """The path the others are compared with: ``wanted`` if given (it must be among ``paths``),
    else ``clean``, else ``today``, else none."""
    if wanted is not None:
        if wanted not in paths:
            raise SystemExit(
                f"--baseline {wanted}: that path was not run (paths: {', '.join(paths)})"
            )
        return wanted
    return "clean" if "clean" in paths else "today" if "today" in paths else None


STAGES = [
    "startup",
    "scene build",
    "JIT",
    "reference passes",
    "noise estimation",
    "texture renders",
    "fit",
    "export",
    "GL check",
    "rest",
    "total",
]


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


def worker(
    experiment: str, path: str, out: Path, overrides: list[str], variant: str = "llvm_ad_rgb"
) -> dict:
    w_start, c_start = time.perf_counter(), time.process_time()
    import drjit as dr

    from study._backend import init_backend
    from study.commands import calibrate as calibrate_command
    from study.commands import outputs
    from study.config import experiment as exp_mod
    from study.scene import direct_light, lighting, mitsuba_scene, reference, shader_inputs

    init_backend(variant)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    name = exp_mod.load_experiment(experiment)["name"]
    sets = path_settings(path, name) + list(overrides)
    t = _Timer(dr)
    t._drain()
    t.wall, t.cpu = {}, {}
    t.wall["startup"], t.cpu["startup"] = (
        time.perf_counter() - w_start,
        time.process_time() - c_start,
    )
    t.wrap(mitsuba_scene, "build_scene", "scene build")
    t.wrap(reference, "render_passes", "reference passes")
    t.wrap(reference, "water_mask", "noise estimation")
    t.wrap(reference, "noise_of", "noise estimation")
    for fn in ("top_down_world_y", "render_top_down", "top_down_colour"):
        t.wrap(shader_inputs, fn, "texture renders")
    for fn in ("render_lighting", "render_dry"):
        t.wrap(lighting, fn, "texture renders")
    t.wrap(direct_light, "traced_direct", "texture renders")
    t.wrap(calibrate_command, "calibrate_model", "fit")
    t.wrap(outputs, "export_shaders", "export")
    t.wrap(outputs, "gl_check", "GL check")
    t.wrap(calibrate_command, "run_calibrate", "rest")
    w0, c0 = time.perf_counter(), time.process_time()
    summary = calibrate_command.run_calibrate(experiment, out, sets, variant, cache=out / "cache")
    t.wall["total"] = t.wall["startup"] + time.perf_counter() - w0
    t.cpu["total"] = t.cpu["startup"] + time.process_time() - c0
    params = {
        n: {
            "fitted": p["fitted"],
            "rel_se": p.get("rel_std_error"),
            "rel_noise": p.get("rel_noise_error"),
            "status": p["status"],
        }
        for n, p in summary["parameters"].items()
    }
    return {
        "experiment": name,
        "path": path,
        "variant": variant,
        "wall": t.wall,
        "cpu": t.cpu,
        "params": params,
        "flip_own": summary["error"]["flip"]["fitted"],
        "rmse_own": summary["error"]["rmse"]["fitted"],
        "reference_spp": summary["reference"]["spp"],
        "reference_noise": summary["reference"]["noise"],
        "kernels": t.kernels,
        "kernel_cache_hits": t.hits,
    }


def cross_flip(
    experiment: str,
    baseline: str,
    run_dirs: dict,
    overrides: list[str],
    variant: str = "llvm_ad_rgb",
) -> dict:
    """FLIP / RMSE (water pixels, full resolution) of each path's fitted constants (``run_dirs``:
    path -> its output folder) against the ``baseline`` path's reference, on its shader inputs."""
    from study._backend import drjit_backend, init_backend
    from study._metrics import errors
    from study.fit.model import ShaderModel
    from study.export.shaders import load_constants_json
    from study.config.experiment import load_experiment
    from study.scene.reference import load_or_render
    from study.scene.shader_inputs import load_or_build_shader_inputs

    variant = init_backend(variant)
    base = load_experiment(experiment)
    exp = load_experiment(experiment, path_settings(baseline, base["name"]) + overrides)
    cache = Path(run_dirs[baseline]) / "cache"
    quiet = lambda *_: None  # noqa: E731
    ref = load_or_render(exp, variant, cache=cache, log=quiet)
    inputs = load_or_build_shader_inputs(exp, variant, cache=cache, log=quiet)
    w, h = exp["resolution"]
    model = ShaderModel.from_experiment(
        exp, inputs, ref.image, backend=drjit_backend(variant), resolution=(w, h)
    )
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
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join([str(REPO)] + [p for p in [os.environ.get("PYTHONPATH")] if p]),
    )
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{p.stderr[-3000:]}")
    data = json.loads(res.read_text())
    res.unlink()
    return data


def _set_args(sets: list[str]) -> list[str]:
    """``--set KEY=VALUE`` arguments of a worker's command line."""
    return [a for s in sets for a in ("--set", s)]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiments", nargs="*", default=None)
    ap.add_argument("--paths", nargs="+", default=["today", "new"], choices=PATHS)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument(
        "--seeds", type=int, default=1, help="run --seed-paths with reference.seed = 0 .. N-1"
    )
    ap.add_argument(
        "--seed-paths",
        nargs="+",
        default=["new"],
        choices=PATHS,
        help="the paths that --seeds reseeds (default: new)",
    )
    ap.add_argument(
        "--merge", nargs="+", type=Path, help="print the tables of earlier --json results together"
    )
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--variant", default="llvm_ad_rgb", choices=["llvm_ad_rgb", "cuda_ad_rgb"])
    ap.add_argument(
        "--baseline",
        choices=PATHS,
        help="the path the others are compared with (default: clean if run, else today)",
    )
    ap.add_argument("--json", type=Path)
    ap.add_argument(
        "--worker", nargs=3, metavar=("EXPERIMENT", "PATH", "OUT"), help=argparse.SUPPRESS
    )
    ap.add_argument(
        "--cross", nargs=3, metavar=("EXPERIMENT", "BASELINE", "DIRS_JSON"), help=argparse.SUPPRESS
    )
    ap.add_argument("--result", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.repeats < 1 or args.seeds < 1:
        ap.error("--repeats and --seeds take a count of at least 1")
    if args.worker:
        e, p, o = args.worker
        args.result.write_text(json.dumps(worker(e, p, Path(o), args.overrides, args.variant)))
        return
    if args.cross:
        e, b, dirs = args.cross
        args.result.write_text(
            json.dumps(cross_flip(e, b, json.loads(dirs), args.overrides, args.variant))
        )
        return

    if args.merge:
        _print_merged(args.merge, args.baseline)
        return
    paths = list(dict.fromkeys(args.paths))
    baseline = pick_baseline(paths, args.baseline)
    exps = args.experiments or sorted(str(p) for p in (REPO / "experiments").glob("*.toml"))
    load = os.getloadavg()
    print(
        f"# bench_new_scene: {os.cpu_count()} cores, load average {load[0]:.1f} / {load[1]:.1f} / "
        f"{load[2]:.1f} at start; {args.variant}; {args.repeats} repeat(s), "
        f"{args.seeds} seed(s) of "
        f"{' and '.join(args.seed_paths)}, medians; wall s (CPU s)",
        flush=True,
    )
    results = []
    for e in exps:
        runs = {p: [] for p in paths}
        dirs = {}
        for r in range(args.repeats):
            for seed in range(args.seeds):
                for p in paths:  # side by side: today, new, today, new, ...
                    if p not in args.seed_paths and seed > 0:
                        continue
                    d = Path(tempfile.mkdtemp(prefix=f"bench_{Path(e).stem}_{p}_"))
                    seeded = p in args.seed_paths and args.seeds > 1
                    sets = args.overrides + ([f"reference.seed={seed}"] if seeded else [])
                    runs[p].append(
                        dict(
                            _run(
                                [
                                    "--worker",
                                    e,
                                    p,
                                    str(d),
                                    "--variant",
                                    args.variant,
                                    *_set_args(sets),
                                ]
                            ),
                            seed=seed,
                        )
                    )
                    if seed == 0:
                        dirs[p] = str(d)
                    print(
                        f"  {Path(e).stem} {p} run {r + 1} seed {seed}: "
                        f"{runs[p][-1]['wall']['total']:.1f} s wall",
                        flush=True,
                    )
                    if args.json:  # after every run: a run cut short loses only itself
                        args.json.write_text(
                            json.dumps(
                                results
                                + [
                                    {
                                        "experiment": Path(e).stem,
                                        "baseline": baseline,
                                        "runs": runs,
                                        "cross": {},
                                    }
                                ],
                                indent=1,
                            )
                        )
        cross = (
            _run(
                [
                    "--cross",
                    e,
                    baseline,
                    json.dumps(dirs),
                    "--variant",
                    args.variant,
                    *_set_args(args.overrides),
                ]
            )
            if baseline and len(paths) > 1
            else {}
        )
        results.append(
            {"experiment": Path(e).stem, "baseline": baseline, "runs": runs, "cross": cross}
        )
        if args.json:  # after every scene: a later failure loses nothing
            args.json.write_text(json.dumps(results, indent=1))
        _print(Path(e).stem, runs, cross, baseline)
    load = os.getloadavg()
    print(f"# load average at the end {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


def _seed_stats(runs: list[dict], name: str) -> tuple[float | None, float | None, int]:
    """(mean, sample standard deviation or None, count) of constant ``name`` over a path's seeds
    (the last repeat of each seed) where it was fitted (a seed may freeze it: no value)."""
    by_seed = {r["seed"]: r["params"][name]["fitted"] for r in runs if name in r["params"]}
    v = [x for x in by_seed.values() if x is not None]
    if not v:
        return None, None, 0
    return statistics.fmean(v), (statistics.stdev(v) if len(v) > 1 else None), len(v)


def _print(name: str, runs: dict, cross: dict, baseline: str | None) -> None:
    paths = list(runs)
    med = {
        p: {
            kind: {s: statistics.median(r[kind].get(s, 0.0) for r in runs[p]) for s in STAGES}
            for kind in ("wall", "cpu")
        }
        for p in paths
    }
    print(f"\n## {name}\n")
    print("| stage | " + " | ".join(f"{p} wall s (CPU s)" for p in paths) + " |")
    print("|---|" + "---|" * len(paths))
    for s in STAGES:
        print(
            f"| {s} | "
            + " | ".join(f"{med[p]['wall'][s]:.1f} ({med[p]['cpu'][s]:.1f})" for p in paths)
            + " |"
        )
    first = {p: [r for r in runs[p] if r["seed"] == 0][-1] for p in paths}
    print("\n| | " + " | ".join(paths) + " |")
    print("|---|" + "---|" * len(paths))
    print("| variant | " + " | ".join(first[p].get("variant", "llvm_ad_rgb") for p in paths) + " |")
    print(
        "| reference spp, noise | "
        + " | ".join(
            f"{first[p]['reference_spp']}, {first[p]['reference_noise']:.4f}" for p in paths
        )
        + " |"
    )
    print(
        "| FLIP / RMSE vs own reference | "
        + " | ".join(f"{first[p]['flip_own']:.4f} / {first[p]['rmse_own']:.4f}" for p in paths)
        + " |"
    )
    if cross:
        print(
            f"| FLIP / RMSE vs {baseline}'s reference | "
            + " | ".join(f"{cross[p]['flip']:.4f} / {cross[p]['rmse']:.4f}" for p in paths)
            + " |"
        )
    print(
        "| kernels (disk-cache hits) | "
        + " | ".join(f"{first[p]['kernels']} ({first[p]['kernel_cache_hits']})" for p in paths)
        + " |"
    )
    if baseline is None:
        for p in paths:
            print(
                f"\n| constant | {p}: fitted (rel. SE) [status] | mean +- SD over "
                "seeds |\n|---|---|---|"
            )
            for n, pa in first[p]["params"].items():
                mean, sd, k = _seed_stats(runs[p], n)
                spread = f"{_v(mean)} +- {_v(sd, 2)} ({k})" if k > 1 else "-"
                print(
                    f"| {n} | {_v(pa['fitted'])} ({_v(pa['rel_se'])}) [{pa['status']}] | {spread} |"
                )
        sys.stdout.flush()
        return
    others = [p for p in paths if p != baseline]
    base = first[baseline]["params"]
    nb = len({r["seed"] for r in runs[baseline]})
    if nb > 1:  # the baseline's own seed spread: the measured standard error of one of its fits
        print(
            f"\n| constant | {baseline}: mean +- SD over {nb} seeds (GN rel. SE of seed 0) | "
            + " | ".join(
                f"{p}: mean +- SD over seeds | ({p} - {baseline}) / {baseline}'s seed SD (+- "
                "SE of the difference) "
                f"| in GN SE"
                for p in others
            )
            + " |"
        )
        print("|---|---|" + "---|---|---|" * len(others))
        for n, pa in base.items():
            mb, sb, kb = _seed_stats(runs[baseline], n)
            se_abs = _se_abs(pa)
            cells = []
            for p in others:
                mp, sp, kp = _seed_stats(runs[p], n)
                if mp is None or mb is None:
                    cells.append(f"{_v(mp)} | - | -")
                    continue
                d = mp - mb
                z = d / sb if sb else None
                sd_d = ((sb**2 / kb if sb else 0.0) + (sp**2 / kp if sp else 0.0)) ** 0.5
                zd = f" (+- {_v(sd_d / sb, 2)})" if sb and sd_d else ""
                cells.append(
                    f"{_v(mp)} +- {_v(sp, 2)} ({kp}) | {_v(z, 2)}{zd} | "
                    f"{_v(d / se_abs if se_abs else None, 2)}"
                )
            print(
                f"| {n} | {_v(mb)} +- {_v(sb, 2)} ({kb}) ({_v(pa['rel_se'])}) [{pa['status']}] | "
                + " | ".join(cells)
                + " |"
            )
        _print_paired(runs, baseline, others, base)
        _print_extrapolated(name, runs, base)
        sys.stdout.flush()
        return
    print(
        f"\n| constant | {baseline} (rel. SE; from reference noise) | "
        + " | ".join(
            f"{p} (from reference noise, or mean +- SD over seeds) | ({p} - {baseline}) / SE"
            for p in others
        )
        + " |"
    )
    print("|---|---|" + "---|---|" * len(others))
    for n, pa in base.items():
        va, se = pa["fitted"], pa["rel_se"]
        se_abs = se * abs(va) if se else None
        cells = []
        for p in others:
            pb = first[p]["params"].get(n, {})
            mean, sd, k = _seed_stats(runs[p], n) if pb else (None, None, 0)
            z = (mean - va) / se_abs if mean is not None and va is not None and se_abs else None
            if k > 1:
                zs = (mean - va) / sd if sd and va is not None else None
                cells.append(
                    f"{_v(mean)} +- {_v(sd, 2)} over {k} seeds [{pb.get('status')}] | "
                    f"{_v(z, 2)} (in seed SD: {_v(zs, 2)})"
                )
            else:
                cells.append(
                    f"{_v(mean)} ({_v(pb.get('rel_noise'))}) [{pb.get('status')}] | {_v(z, 2)}"
                )
        print(
            f"| {n} | {_v(va)} ({_v(se)}; {_v(pa.get('rel_noise'))}) [{pa['status']}] | "
            + " | ".join(cells)
            + " |"
        )
    sys.stdout.flush()


def _se_abs(pa: dict) -> float | None:
    """The Gauss-Newton standard error of a fitted constant (its ``params`` entry), or None."""
    return pa["rel_se"] * abs(pa["fitted"]) if pa["rel_se"] and pa["fitted"] is not None else None


def _paired(
    runs_b: list[dict], runs_p: list[dict], name: str
) -> tuple[float, float | None, int] | None:
    """(mean, its standard error or None, count) of the per-seed difference p - baseline of
    constant ``name`` over the seeds both ran with *the same reference* (same variant, spp and
    measured noise, so the same render: the difference is the texture's alone), or None when
    they share no such seed."""
    b = {r["seed"]: r for r in runs_b}
    d = []
    for r in runs_p:
        rb = b.get(r["seed"])
        if (
            rb is None
            or rb.get("variant") != r.get("variant")
            or rb["reference_spp"] != r["reference_spp"]
            or rb["reference_noise"] != r["reference_noise"]
        ):
            continue
        vb, vp = rb["params"].get(name, {}).get("fitted"), r["params"].get(name, {}).get("fitted")
        if vb is not None and vp is not None:
            d.append(vp - vb)
    if not d:
        return None
    return (
        statistics.fmean(d),
        (statistics.stdev(d) / len(d) ** 0.5 if len(d) > 1 else None),
        len(d),
    )


def _print_paired(runs: dict, baseline: str, others: list[str], base: dict) -> None:
    """Per-seed differences from the baseline where a path ran the baseline's own reference (e.g.
    ``new`` against ``converged``): the reference's noise cancels, what is left is the textures'."""
    rows = {p: {n: _paired(runs[baseline], runs[p], n) for n in base} for p in others}
    shown = [p for p in others if any(v is not None for v in rows[p].values())]
    if not shown:
        return
    print(
        "\n| constant | "
        + " | ".join(
            f"{p} - {baseline}, same reference, in GN SE: mean +- SE (seeds)" for p in shown
        )
        + " |"
    )
    print("|---|" + "---|" * len(shown))
    for n, pa in base.items():
        se_abs = _se_abs(pa)
        cells = []
        for p in shown:
            v = rows[p][n]
            if v is None or not se_abs:
                cells.append("-")
                continue
            m, e, k = v
            cells.append(
                f"{_v(m / se_abs, 2)}"
                + (f" +- {_v(e / se_abs, 2)}" if e is not None else "")
                + f" ({k})"
            )
        print(f"| {n} | " + " | ".join(cells) + " |")


def _print_extrapolated(name: str, runs: dict, base: dict) -> None:
    """The path tracer's constants without texture noise, where ``today`` and ``clean`` ran the
    same seeds: texture noise biases a fit by about its variance, which falls as 1 / spp, so
    ``v(inf) = v(clean) + (v(clean) - v(today)) * (1 / s_clean) / (1 / s_today - 1 / s_clean)`` (the
    per-seed shift today -> clean averaged over the common seeds); each other path's mean against
    it, in the Gauss-Newton SE of the baseline's seed 0."""
    if "today" not in runs or "clean" not in runs:
        return
    s_today, s_clean = TODAY_TEXTURE_SPP.get(name, 256), CLEAN_TEXTURE_SPP
    w = (1.0 / s_clean) / (1.0 / s_today - 1.0 / s_clean)
    others = [p for p in runs if p not in ("today", "clean")]
    print(
        f"\n| constant | path tracer without texture noise ({s_today} and "
        f"{s_clean} spp in 1/spp) | " + " | ".join(f"{p} - it, in GN SE" for p in others) + " |"
    )
    print("|---|---|" + "---|" * len(others))
    for n, pa in base.items():
        shift = _paired(runs["today"], runs["clean"], n)
        mc = _seed_stats(runs["clean"], n)[0]
        se_abs = _se_abs(pa)
        if shift is None or mc is None:
            print(f"| {n} | - |" + " - |" * len(others))
            continue
        v_inf = mc + w * shift[0]
        cells = []
        for p in others:
            mp = _seed_stats(runs[p], n)[0]
            cells.append(_v((mp - v_inf) / se_abs, 2) if mp is not None and se_abs else "-")
        print(
            f"| {n} | {_v(v_inf)} (shift today -> clean {_v(shift[0])}, {shift[2]} seeds) | "
            + " | ".join(cells)
            + " |"
        )


def _print_merged(files: list[Path], wanted: str | None = None) -> None:
    """The tables of earlier ``--json`` results, the runs of one experiment joined by path."""
    merged: dict[str, dict] = {}
    for f in files:
        for res in json.loads(f.read_text()):
            m = merged.setdefault(res["experiment"], {"runs": {}, "cross": {}})
            m["runs"].update({p: r for p, r in res["runs"].items() if r})
            m["cross"].update(res.get("cross") or {})
    for name, m in merged.items():
        runs = {p: m["runs"][p] for p in PATHS if p in m["runs"]}
        baseline = pick_baseline(list(runs), wanted)
        cross = m["cross"] if all(p in m["cross"] for p in runs) else {}
        _print(name, runs, cross, baseline)


def _v(x, p=4):
    return f"{x:.{p}g}" if isinstance(x, (int, float)) else "-"


if __name__ == "__main__":
    main()
