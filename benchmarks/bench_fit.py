"""Solvers side by side on one experiment (default: experiments/default.toml at 256x256).

For each solver: seconds to converge, iterations, Dr.Jit value/Jacobian calls, final loss
and FLIP (full resolution, water pixels). Then Adam (Mitsuba's tutorial loop, the baseline)
is run until it reaches the best optimistix loss (x (1 + 1e-3)) or its iteration cap, and
the speed ratio is printed. The reference must be rendered first (it is cached):

    .venv/bin/study render experiments/default.toml --out out/default-render
    .venv/bin/python benchmarks/bench_fit.py [EXPERIMENT.toml] [--set KEY=VALUE ...]

Also measures what happens when a gradient solver is pointed at a step count
(``steps_grazing``, piecewise constant in its effect): its AD derivative, a central finite
difference, and how far Levenberg-Marquardt moves it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

SOLVERS = ["levenberg_marquardt", "gauss_newton", "dogleg", "bfgs", "nelder_mead"]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("experiment", nargs="?", default=str(REPO / "experiments" / "default.toml"))
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--adam-steps", type=int, default=600)
    ap.add_argument("--adam-lr", type=float, default=0.05)
    ap.add_argument("--max-steps", type=int, default=200)
    args = ap.parse_args()

    from study import init_backend, load_experiment
    from study.fit.calibrate import make_problem
    from study.fit.solvers import fit
    from study.fit.identify import probe_gradient_solver
    from study._metrics import flip
    from study.fit.model import ShaderModel, constants_from_experiment
    from study.fit.model import expand_parameters, with_values
    from study.scene.reference import load_or_render
    from study.scene.shader_inputs import load_or_build_shader_inputs

    init_backend("llvm_ad_rgb")
    exp = load_experiment(args.experiment, ["fit.resolution=[256, 256]"] + args.overrides)
    ref = load_or_render(exp, "llvm_ad_rgb", log=lambda m: print(m, file=sys.stderr))
    inputs = load_or_build_shader_inputs(
        exp, "llvm_ad_rgb", log=lambda m: print(m, file=sys.stderr)
    )
    model = ShaderModel.from_experiment(exp, inputs, ref.image)
    start = constants_from_experiment(exp)
    # drop what the scene does not identify, as `study calibrate` does
    from study.fit.calibrate import scene_frozen
    from study.fit.identify import identify

    names = [
        n
        for n in expand_parameters(exp["fit.parameters"])
        if not n.startswith("steps_") and n not in scene_frozen(exp)
    ]
    problem = make_problem(model, start, names, progress=False)
    _, J = model.residual_and_jacobian(start, names)
    rep = identify(J, names, scales=[problem.params[n].typical for n in names])
    names = [n for n in names if not rep.freeze[n]]
    problem = make_problem(model, start, names, progress=False)
    w, h = exp["resolution"]
    print(
        f"experiment {exp['name']}, fit at {w}x{h}, {int(model.mask.sum())} water pixels, "
        f"parameters {names}, reference {ref.spp} spp (noise {ref.noise:.3g})"
    )

    def flip_of(values: dict) -> float:
        img, _ = model.render(with_values(start, values))
        return flip(model.reference, img, model.mask)

    rows = []
    for solver in SOLVERS:
        res = fit(
            problem, solver=solver, max_steps=args.max_steps if solver != "nelder_mead" else 2000
        )
        rows.append((solver, res))
    res = fit(problem, solver="adam", max_steps=args.adam_steps, lr=args.adam_lr, patience=None)
    rows.append(("adam", res))
    best_loss = min(r.loss for _, r in rows)
    target = best_loss * (1 + 1e-3)

    def time_to(res) -> float | None:
        """Seconds until the first evaluation within 0.1 % of the best loss of any solver
        (evaluations are assumed to cost the same: the time is prorated)."""
        hit = next((i for i, v in enumerate(res.losses) if v <= target), None)
        return None if hit is None else res.seconds * (hit + 1) / len(res.losses)

    print(f"target loss: best of all solvers x 1.001 = {target:.6g}")
    print(
        f"{'solver':>20} {'total s':>8} {'to target s':>11} {'iters':>6} "
        f"{'values':>7} {'jacobians':>9} "
        f"{'final loss':>11} {'FLIP':>7}  converged / message"
    )
    times = {}
    for solver, res in rows:
        tt = time_to(res)
        times[solver] = tt
        print(
            f"{solver:>20} {res.seconds:8.2f} {('%.2f' % tt) if tt is not None else 'never':>11} "
            f"{res.iterations:6d} {res.n_value_calls:7d} {res.n_jac_calls:9d} {res.loss:11.6g} "
            f"{flip_of({n: res.constants[n] for n in names}):7.4f}  {res.converged} "
            f"/ {res.message[:60]}",
            flush=True,
        )
    reached = {s: t for s, t in times.items() if t is not None and s != "adam"}
    if reached:
        best = min(reached, key=reached.get)
        adam_t = times["adam"]
        print(
            f"\nfastest optimistix solver to the target: {best} {reached[best]:.2f} s; Adam "
            + (
                f"{adam_t:.2f} s, ratio Adam / {best} = {adam_t / reached[best]:.2f}x"
                if adam_t is not None
                else f"never reached it in {args.adam_steps} iterations (ratio > "
                f"{rows[-1][1].seconds / reached[best]:.1f}x)"
            )
        )

    # a gradient solver pointed at a step count anyway
    sp = make_problem(model, start, ["steps_grazing"], progress=False)
    probe = probe_gradient_solver(sp, "steps_grazing", solver="levenberg_marquardt")
    print(
        "\nLevenberg-Marquardt on steps_grazing alone:",
        {k: (round(v, 6) if isinstance(v, float) else v) for k, v in probe.items() if k != "fit"},
        "| LM message:",
        probe["fit"].message,
    )


if __name__ == "__main__":
    main()
