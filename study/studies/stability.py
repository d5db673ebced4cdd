"""``study stability``: where the fit's methods fail - solvers from many starts, the residual the
fit minimises, and the noise of the references - over one or several experiments, as sweeps on
the Dask engine (jobs in ``stability_jobs``; a re-run resumes from the Parquet tables).

Phases (``phases``):

* ``multistart``: for each scene, solver (:data:`SOLVERS`) and start (``starts`` points of a
  Latin hypercube over each fitted constant's box), one fit. A run *succeeds* when its final loss
  is within 0.1 % of the best loss of all runs on that scene. Per solver: success rate, time to
  that target (first step whose lowest loss reaches it; successful runs) and time to stop (all
  runs), median and p90; the relative spread (standard deviation / |median|) of each fitted
  constant over the runs, median over scenes; failures by class (``nonfinite``, ``step_cap``,
  ``error``, ``another_basin``: converged elsewhere). Adam runs at each learning rate of
  ``adam_lrs`` and is reported at the best one (highest success rate, then lowest median time),
  as a user tuning it would. Charts ``solvers.png`` (success rate against median time to stop,
  one point per solver) and ``spread.png``.
* ``loss``: the calibration of each scene with the linear-RGB residual and the ``log``
  residual (``study.fit.losses``), both judged by FLIP at full resolution.
* ``noise``: the calibration of the first scene against references at each of ``noise_spp``
  (texture spp held at ``noise_fixed_spp``) and with top-down textures at each of ``noise_spp``
  (reference spp held at ``noise_fixed_spp``; ``noise_inputs`` picks either or both),
  ``noise_seeds`` independent seeds each
  (``reference.seed``, which seeds the reference *and* the texture renders), at
  ``noise_resolution``. Per level and constant: mean over seeds, its standard error (standard
  deviation over seeds / sqrt(seeds)), bias against the highest level, and whether it agrees
  with the highest level within one combined standard error; the cheapest agreeing spp.
  Chart ``noise.png``.

Outputs in ``out``: ``multistart.parquet``, ``loss.parquet``, ``noise.parquet``, ``summary.json``,
``stability.md`` and the charts.
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from .._io import write_json
from .._progress import log as _log
from ..config.experiment import load_experiment
from ..report.stability import noise_figure, solver_figure, spread_figure, write_stability_report
from ..sweep import run_sweep, scene_spec
from .stability_jobs import (
    latin_hypercube,
    loss_job,
    multistart_job,
    noise_job,
    quantile,
    solver_left_out,
    start_boxes,
)

SOLVERS = ("levenberg_marquardt", "gauss_newton", "dogleg", "bfgs", "nelder_mead", "adam")
SUCCESS = 1e-3
PHASES = ("multistart", "loss", "noise")


def plan_multistart(
    specs: list[dict],
    exps: list,
    starts: int,
    solvers,
    adam_lrs,
    max_steps: int,
    nm_steps: int,
    seed: int = 0,
) -> list[dict]:
    jobs = []
    for spec, exp in zip(specs, exps):
        boxes = start_boxes(exp)
        names = list(boxes)
        pts = latin_hypercube(names, starts, seed, boxes)
        for solver in solvers:
            if solver_left_out(exp, solver):
                continue
            for lr in adam_lrs if solver == "adam" else [None]:
                for i, p in enumerate(pts):
                    jobs.append(
                        {
                            "scene": spec,
                            "experiment": exp.name,
                            "solver": solver,
                            "lr": lr,
                            "start_index": i,
                            "start": p,
                            "names": names,
                            "max_steps": nm_steps if solver == "nelder_mead" else max_steps,
                        }
                    )
    return jobs


def _flat_job(rows: list[dict]) -> list[dict]:
    """Rows of the sweep table with the job's inputs (``job.x`` columns) also under ``x``."""
    return [{**{k[4:]: v for k, v in r.items() if k.startswith("job.")}, **r} for r in rows]


def _time_to(trace_loss, trace_seconds, target):
    for v, t in zip(trace_loss or [], trace_seconds or []):
        if v is not None and v <= target:
            return t
    return None


def analyse_multistart(rows: list[dict]) -> dict:
    """Per scene the best loss, per run success and class, per solver the figures of the module
    doc (Adam at its best learning rate)."""
    rows = _flat_job(rows)
    ok = [r for r in rows if r.get("status") == "ok"]
    best = {}
    for r in ok:
        if r.get("loss") is not None:
            best[r["experiment"]] = min(best.get(r["experiment"], math.inf), r["loss"])
    for r in rows:
        b = best.get(r.get("experiment"))
        r["success"] = bool(
            r.get("status") == "ok"
            and r.get("loss") is not None
            and b is not None
            and r["loss"] <= b * (1 + SUCCESS)
        )
        r["class"] = (
            "sweep_error"
            if r.get("status") != "ok"
            else "success"
            if r["success"]
            else r["failure"]
            if r["failure"] != "converged"
            else "another_basin"
        )
        r["time_to_target"] = (
            _time_to(r.get("trace_loss"), r.get("trace_seconds"), b * (1 + SUCCESS))
            if r["success"]
            else None
        )
    groups = {}
    for r in rows:
        label = r["solver"] if r["solver"] != "adam" else f"adam lr={r['lr']:g}"
        groups.setdefault(label, []).append(r)
    per = {label: _solver_stats(rs) for label, rs in groups.items()}
    adams = {k: v for k, v in per.items() if k.startswith("adam")}
    best_adam = (
        min(
            adams,
            key=lambda k: (-adams[k]["success_rate"], adams[k]["time_to_stop_median"] or math.inf),
        )
        if adams
        else None
    )
    return {
        "best_loss": best,
        "solvers": per,
        "best_adam": best_adam,
        "reported": [k for k in per if not k.startswith("adam")]
        + ([best_adam] if best_adam else []),
    }


def _solver_stats(rs: list[dict]) -> dict:
    n = len(rs)
    classes = {}
    for r in rs:
        classes[r["class"]] = classes.get(r["class"], 0) + 1
    tt = [r["time_to_target"] for r in rs if r["time_to_target"] is not None]
    ts = [r.get("fit_seconds") for r in rs if r.get("fit_seconds") is not None]
    spread = {}
    for scene in sorted({r["experiment"] for r in rs}):
        sub = [
            r
            for r in rs
            if r["experiment"] == scene and r.get("status") == "ok" and r.get("loss") is not None
        ]
        for k in sorted({k for r in sub for k in r if k.startswith("fitted.")}):
            vals = [r[k] for r in sub if r.get(k) is not None]
            if len(vals) >= 2:
                med = statistics.median(vals)
                spread.setdefault(k[len("fitted.") :], []).append(
                    statistics.stdev(vals) / max(abs(med), 1e-12)
                )
    return {
        "runs": n,
        "success_rate": sum(r["success"] for r in rs) / n if n else 0.0,
        "time_to_target_median": quantile(tt, 0.5),
        "time_to_target_p90": quantile(tt, 0.9),
        "time_to_stop_median": quantile(ts, 0.5),
        "time_to_stop_p90": quantile(ts, 0.9),
        "iterations_median": quantile([r.get("iterations") for r in rs], 0.5),
        "classes": classes,
        "rel_spread": {k: statistics.median(v) for k, v in spread.items()},
    }


def plan_loss(specs, exps) -> list[dict]:
    return [
        {"scene": s, "experiment": e.name, "loss": loss}
        for s, e in zip(specs, exps)
        for loss in ("linear", "log")
    ]


def analyse_loss(rows: list[dict]) -> dict:
    rows = _flat_job(rows)
    table = {}
    for r in rows:
        if r.get("status") == "ok":
            table.setdefault(r["experiment"], {})[r["loss"]] = {
                "flip": r["flip"],
                "rmse": r["rmse"],
            }
    wins = {"linear": 0, "log": 0}
    for d in table.values():
        if "linear" in d and "log" in d:
            wins["log" if d["log"]["flip"] < d["linear"]["flip"] else "linear"] += 1
    mean = {
        k: statistics.mean([d[k]["flip"] for d in table.values() if k in d])
        if any(k in d for d in table.values())
        else None
        for k in ("linear", "log")
    }
    return {
        "per_scene": table,
        "wins": wins,
        "mean_flip": mean,
        "winner": min(
            (k for k in mean if mean[k] is not None), key=lambda k: mean[k], default=None
        ),
    }


def plan_noise(
    path: str,
    base_overrides: list,
    levels,
    fixed: int,
    seeds: int,
    resolution: int,
    inputs=("reference", "texture"),
) -> list[dict]:
    res = [f"resolution=[{resolution},{resolution}]", f"fit.resolution=[{resolution},{resolution}]"]
    jobs = []
    for which in inputs:
        for spp in levels:
            for s in range(seeds):
                ref_spp, tex_spp = (spp, fixed) if which == "reference" else (fixed, spp)
                # the texture's path-traced samples whichever way the direct light is made
                ov = (
                    list(base_overrides)
                    + res
                    + [
                        f"reference.spp={ref_spp}",
                        f"reference.texture_spp={tex_spp}",
                        f"reference.bounce_spp={tex_spp}",
                        f"reference.seed={1000 + s}",
                    ]
                )
                jobs.append(
                    {"scene": scene_spec(path, ov), "which": which, "spp": spp, "seed": 1000 + s}
                )
    return jobs


def analyse_noise(rows: list[dict]) -> dict:
    rows = _flat_job(rows)
    out = {}
    for which in ("reference", "texture"):
        sub = [r for r in rows if r.get("which") == which and r.get("status") == "ok"]
        levels = sorted({r["spp"] for r in sub})
        if not levels:
            continue
        names = sorted({k[len("value.") :] for r in sub for k in r if k.startswith("value.")})
        stats = {}
        for spp in levels:
            rs = [r for r in sub if r["spp"] == spp]
            stats[spp] = {}
            for n in names:
                vals = [r[f"value.{n}"] for r in rs if r.get(f"value.{n}") is not None]
                if not vals:
                    continue
                mean = statistics.mean(vals)
                se = statistics.stdev(vals) / math.sqrt(len(vals)) if len(vals) > 1 else None
                stats[spp][n] = {
                    "mean": mean,
                    "se": se,
                    "n": len(vals),
                    "status": sorted({r.get(f"status.{n}") for r in rs}),
                }
        top = levels[-1]
        agree = {}
        for spp in levels:
            for n, d in stats[spp].items():
                t = stats[top].get(n)
                if t is None:
                    continue
                d["bias"] = d["mean"] - t["mean"]
                se = math.sqrt((d["se"] or 0.0) ** 2 + (t["se"] or 0.0) ** 2) if spp != top else 0.0
                d["bias_se"] = se
                # a constant at its bound on every seed (no spread, no bias) agrees too
                d["agrees"] = spp == top or abs(d["bias"]) <= se
            agree[spp] = all(d.get("agrees", False) for d in stats[spp].values())
        cheapest = next((s for s in levels if all(agree[t] for t in levels if t >= s)), top)
        out[which] = {
            "levels": levels,
            "stats": stats,
            "agrees": agree,
            "cheapest_agreeing": cheapest,
        }
    return out


def _check_arguments(phases, solvers, starts, noise_seeds, noise_inputs) -> None:
    if not noise_inputs or any(w not in ("reference", "texture") for w in noise_inputs):
        raise ValueError(
            "noise_inputs must be a non-empty subset of ('reference', "
            f"'texture'), got {noise_inputs}"
        )
    bad = [p for p in phases if p not in PHASES]
    if bad:
        raise ValueError(f"unknown phase(s) {bad}; choose from {PHASES}")
    bad = [s for s in solvers if s not in SOLVERS]
    if bad:
        raise ValueError(f"unknown solver(s) {bad}; choose from {SOLVERS}")
    if starts < 1 or noise_seeds < 1:
        raise ValueError("need starts >= 1 and noise_seeds >= 1")


def _multistart_phase(
    client, out, specs, exps, starts, solvers, adam_lrs, max_steps, nm_steps, log
) -> dict:
    """The multi-start phase: its sweep (multistart.parquet), analysis and two figures; a
    solver a scene's shader cannot use is left out of that scene, with a note (``left_out``)."""
    left_out = [
        {"scene": exp.name, "solver": s, "why": why}
        for exp in exps
        for s in solvers
        if (why := solver_left_out(exp, s))
    ]
    for row in left_out:
        log(f"stability: {row['solver']} left out on {row['scene']}: {row['why']}")
    jobs = plan_multistart(specs, exps, starts, solvers, adam_lrs, max_steps, nm_steps)
    rows = run_sweep(
        multistart_job,
        jobs,
        out / "multistart.parquet",
        client=client,
        label="stability: multi-start",
        log=log,
    )
    ms = analyse_multistart(rows[: len(jobs)])
    solver_figure(out / "solvers.png", ms)
    spread_figure(out / "spread.png", ms)
    return {
        **ms,
        "starts": starts,
        "max_steps": max_steps,
        "nm_steps": nm_steps,
        "adam_lrs": list(adam_lrs),
        "left_out": left_out,
    }


def _noise_phase(client, out, experiment, overrides, noise, log) -> dict:
    """The noise phase on the first experiment: its sweep (noise.parquet), analysis, figure.
    ``noise``: (spp list, fixed spp, seeds, resolution, inputs varied)."""
    spp, fixed_spp, seeds, resolution, inputs = noise
    jobs = plan_noise(str(experiment), overrides, list(spp), fixed_spp, seeds, resolution, inputs)
    rows = run_sweep(
        noise_job, jobs, out / "noise.parquet", client=client, label="stability: noise", log=log
    )
    summary = {
        **analyse_noise(rows[: len(jobs)]),
        "fixed_spp": fixed_spp,
        "seeds": seeds,
        "resolution": resolution,
    }
    noise_figure(out / "noise.png", summary)
    return summary


def run_stability(
    experiments: list,
    out,
    overrides=None,
    *,
    phases=PHASES,
    starts: int = 16,
    solvers=SOLVERS,
    adam_lrs=(0.02, 0.05, 0.1),
    max_steps: int = 100,
    nm_steps: int = 400,
    noise_spp=(64, 256, 1024, 4096),
    noise_fixed_spp: int = 1024,
    noise_seeds: int = 3,
    noise_resolution: int = 96,
    noise_inputs=("reference", "texture"),
    scheduler=None,
    workers=None,
    variant: str = "llvm_ad_rgb",
    log=_log,
    command: str | None = None,
) -> dict:
    """Run the study (see the module doc); returns the summary written to ``summary.json``
    (``command``: the command line that ran it, quoted in the report)."""
    _check_arguments(phases, solvers, starts, noise_seeds, noise_inputs)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    overrides = list(overrides or [])
    exps = [load_experiment(p, overrides) for p in experiments]
    specs = [scene_spec(p, overrides) for p in experiments]
    summary = {
        "experiments": [str(p) for p in experiments],
        "overrides": overrides,
        "phases": list(phases),
    }
    if command:
        summary["command"] = command
    # local: distributed takes 0.65 s to import, paid only when a sweep runs
    from ..sweep.cluster import open_client

    with open_client(scheduler, workers, variant, log=log) as client:
        if "loss" in phases:
            jobs = plan_loss(specs, exps)
            rows = run_sweep(
                loss_job,
                jobs,
                out / "loss.parquet",
                client=client,
                label="stability: loss",
                log=log,
            )
            summary["loss"] = analyse_loss(rows[: len(jobs)])
        if "multistart" in phases:
            summary["multistart"] = _multistart_phase(
                client, out, specs, exps, starts, solvers, adam_lrs, max_steps, nm_steps, log
            )
        if "noise" in phases:
            noise = (noise_spp, noise_fixed_spp, noise_seeds, noise_resolution, noise_inputs)
            summary["noise"] = _noise_phase(client, out, experiments[0], overrides, noise, log)
    write_json(out / "summary.json", summary)
    write_stability_report(out, summary)
    log(f"stability: wrote {out / 'stability.md'}")
    return summary
