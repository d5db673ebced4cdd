"""Command line: ``study <command> ...``. Argument parsing only; the work is in
``study.commands``."""

from __future__ import annotations

import argparse
import sys

from . import commands
from ._backend import BackendError
from ._io import DiskFullError
from .config.experiment import ExperimentError
from .studies.stability import SOLVERS


def _set_arg(p, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` option of a command (into ``overrides``)."""
    p.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
        help=help_text,
    )  # fmt: skip


def _backend_arg(p: argparse.ArgumentParser, default: str | None, what: str) -> None:
    """``--backend`` (the Mitsuba / Dr.Jit variant; ``--variant`` is its old name)."""
    p.add_argument(
        "--backend",
        "--variant",
        dest="variant",
        choices=["llvm_ad_rgb", "cuda_ad_rgb"],
        default=default,
        help=f"Mitsuba / Dr.Jit backend ({what}; --variant is the old name)",
    )


def _common(p: argparse.ArgumentParser, many: bool = False) -> None:
    if many:
        p.add_argument(
            "experiment", nargs="+", help="experiment TOML file(s) (keys: docs/experiment-keys.md)"
        )
    else:
        p.add_argument("experiment", help="experiment TOML file (keys: docs/experiment-keys.md)")
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    _set_arg(p, "override an experiment key, e.g. --set water.ior=1.33 (repeatable)")
    _backend_arg(p, None, "default: the experiment's, normally llvm_ad_rgb")


def _sweep_common(p: argparse.ArgumentParser, experiments_help: str) -> None:
    """Arguments of the commands that run a Dask sweep over several experiments."""
    p.add_argument("experiments", nargs="+", metavar="EXPERIMENT", help=experiments_help)
    p.add_argument(
        "--out", required=True, help="output folder (created if missing; a re-run resumes)"
    )
    _set_arg(p, "override a key of every experiment (repeatable)")
    _backend_arg(p, "llvm_ad_rgb", "of the workers")
    _cluster_args(p)


def _cluster_args(p: argparse.ArgumentParser) -> None:
    """Where a sweep runs: a Dask scheduler, or a local cluster of ``--workers`` processes."""
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Dask scheduler address (default: $STUDY_SCHEDULER, else a local cluster)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="local cluster worker processes (default: one per core)",
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="study",
        description="Calibrate a real-time GLSL water shader against Mitsuba 3 references.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser(
        "render", help="render (or reuse the cached) reference and the shader inputs"
    )
    _common(p)
    p = sub.add_parser("preview", help="the port with default constants next to the reference")
    _common(p)
    p = sub.add_parser(
        "calibrate",
        help="reference, fit, export and report (the main job); several "
        "experiments: one constants block fitted on all of them (joint fit)",
    )
    _common(p, many=True)
    p.add_argument("--solver", default=None, help="override fit.solver")
    p = sub.add_parser(
        "generalise",
        help="joint fit over several experiments and leave-one-scene-out "
        "validation (generalise.md)",
    )
    _common(p, many=True)
    p.add_argument("--solver", default=None, help="override fit.solver")
    p = sub.add_parser(
        "tradeoff",
        help="speed against accuracy: variants x step schedules, refitted, "
        "costed and charted with Pareto fronts (a Dask sweep)",
    )
    _sweep_common(
        p,
        "experiment TOML file(s); each experiment's [tradeoff] table sets its variants "
        "and grid, the first's sets the tolerance",
    )
    p.add_argument(
        "--tolerance",
        type=float,
        default=None,
        help="recommend the cheapest point within this fraction of the best FLIP "
        "(default: tradeoff.tolerance, 0.02)",
    )
    p.add_argument(
        "--search",
        choices=("adaptive", "exhaustive"),
        default=None,
        help="adaptive: screen the shader space cheaply, measure the survivors in full; "
        "exhaustive: every shader and schedule in full (default: tradeoff.search, adaptive)",
    )
    p.add_argument(
        "--budget",
        action="append",
        default=[],
        metavar="COST=LIMIT",
        type=_budget_entry,
        help="recommend the lowest FLIP within the limit (repeatable): fetches=N (texture "
        "fetches per water pixel) or gl_ms=X (normalised llvmpipe ms at 1920x1080)",
    )
    _add_stability(sub)
    _add_failures(sub)
    _add_export(sub)
    _add_viewer(sub)
    return parser


def _budget_entry(text: str) -> tuple[str, float]:
    """``fetches=17.1`` -> ("fetches", 17.1); argparse reports the ValueError's message."""
    key, sep, value = text.partition("=")
    try:
        limit = float(value)
    except ValueError:
        limit = None
    if not sep or key.strip() not in ("fetches", "gl_ms") or limit is None or not limit > 0:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected fetches=N or gl_ms=X with a positive number"
        )
    return key.strip(), limit


def _add_stability(sub) -> None:
    p = sub.add_parser(
        "stability",
        help="where the fit fails: solvers from many starts, which residual, "
        "reference and texture noise (Dask sweeps; stability.md)",
    )
    _sweep_common(p, "experiment TOML file(s)")
    p.add_argument(
        "--phases",
        nargs="+",
        default=["multistart", "loss", "noise"],
        help="multistart, loss, noise (default: all)",
    )
    p.add_argument(
        "--starts", type=int, default=16, help="Latin-hypercube starts per scene and solver"
    )
    p.add_argument("--solvers", nargs="+", default=None, help="default: all six")
    p.add_argument("--adam-lrs", nargs="+", type=float, default=[0.02, 0.05, 0.1])
    p.add_argument("--max-steps", type=int, default=100, help="step cap (Nelder-Mead: 4x)")
    p.add_argument("--noise-spp", nargs="+", type=int, default=[64, 256, 1024, 4096])
    p.add_argument("--noise-fixed-spp", type=int, default=1024)
    p.add_argument("--noise-seeds", type=int, default=3)
    p.add_argument("--noise-resolution", type=int, default=96)
    p.add_argument(
        "--noise-inputs",
        nargs="+",
        default=["reference", "texture"],
        choices=["reference", "texture"],
        help="which renders the noise phase varies",
    )


def _add_failures(sub) -> None:
    p = sub.add_parser(
        "failures",
        help="classify every water pixel by where the shader's method "
        "fails; class maps beside FLIP maps, a table per class",
    )
    p.add_argument("experiments", nargs="+", metavar="EXPERIMENT", help="experiment TOML files")
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    _set_arg(p, "override an experiment key in every experiment (repeatable)")
    _backend_arg(p, None, "default: each experiment's")
    p.add_argument(
        "--shader", default=None, help="shader variant (default: each experiment's fit.shader)"
    )
    p.add_argument(
        "--constants",
        default=None,
        help="constants JSON (e.g. a calibrate's "
        "constants.json); default: each experiment's start constants",
    )
    _cluster_args(p)


def _add_export(sub) -> None:
    p = sub.add_parser("export", help="write the shaders with constants from a JSON file")
    p.add_argument(
        "constants",
        help="constants.json written by `study calibrate` or `study tradeoff` (in its "
        "shaders/), or a flat JSON object of constant name -> value",
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument(
        "--targets",
        default=None,
        help="engine targets besides GLSL, comma-separated: gles300,hlsl,msl,spirv,wgsl, or 'none' "
        "(default: every one the installed tools can make)",
    )
    p.add_argument(
        "--shaders",
        default=None,
        help="shaders of the space to write, comma-separated (default: the one the constants "
        "were fitted for; every shipped one for a flat JSON)",
    )


def _add_viewer(sub) -> None:
    p = sub.add_parser(
        "viewer",
        help="write OUT/viewer/, the calibrated shader live in WebGL 2 beside the reference "
        "(calibrate writes it; this writes it again for an existing result)",
    )
    p.add_argument("out", help="output folder of a `study calibrate` run")
    p.add_argument(
        "experiment", help="the experiment TOML file the calibration ran (its shader inputs)"
    )
    _set_arg(p, "the calibration's --set options (repeatable)")
    _backend_arg(p, None, "default: the calibration's")


def _command_line(argv) -> str:
    """The command as a user would type it (``study ...``), for a report's "Reproduce" line."""
    import shlex

    return shlex.join(["study", *(sys.argv[1:] if argv is None else argv)])


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)

    try:
        if args.command == "render":
            commands.run_render(args.experiment, args.out, args.overrides, args.variant)
        elif args.command == "preview":
            commands.run_preview(args.experiment, args.out, args.overrides, args.variant)
        elif args.command == "calibrate":
            commands.run_calibrate(
                args.experiment, args.out, args.overrides, args.variant, solver=args.solver
            )
        elif args.command == "generalise":
            commands.run_generalise(
                args.experiment, args.out, args.overrides, args.variant, solver=args.solver
            )
        elif args.command == "tradeoff":
            commands.run_tradeoff(
                args.experiments,
                args.out,
                args.overrides,
                args.variant,
                tolerance=args.tolerance,
                scheduler=args.scheduler,
                workers=args.workers,
                search=args.search,
                budget=dict(args.budget),
            )
        elif args.command == "stability":
            commands.run_stability(
                args.experiments,
                args.out,
                args.overrides,
                args.variant,
                scheduler=args.scheduler,
                workers=args.workers,
                phases=args.phases,
                starts=args.starts,
                solvers=args.solvers or SOLVERS,
                adam_lrs=args.adam_lrs,
                max_steps=args.max_steps,
                nm_steps=4 * args.max_steps,
                noise_spp=args.noise_spp,
                noise_fixed_spp=args.noise_fixed_spp,
                noise_seeds=args.noise_seeds,
                noise_resolution=args.noise_resolution,
                noise_inputs=args.noise_inputs,
                command=_command_line(argv),
            )
        elif args.command == "failures":
            commands.run_failures(
                args.experiments,
                args.out,
                args.overrides,
                args.variant,
                shader=args.shader,
                constants_json=args.constants,
                scheduler=args.scheduler,
                workers=args.workers,
            )
        elif args.command == "export":
            commands.run_export(args.constants, args.out, args.targets, args.shaders)
        elif args.command == "viewer":
            commands.run_viewer(args.out, args.experiment, args.overrides, args.variant)
    except (ExperimentError, BackendError, FileNotFoundError, ValueError) as exc:
        print(f"study {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except DiskFullError as exc:
        print(f"study {args.command}: error: {exc.strerror}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(
            f"\nstudy {args.command}: interrupted; finished results are kept, and the same "
            "command resumes from them",
            file=sys.stderr,
        )
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
