"""The fit of a shader's constants over a list of frames, with explicit options.

Every calibration fits here: ``study calibrate`` (one frame, views, an animation's frames,
several experiments), ``study generalise`` and every point of the sweeps. One frame is fitted
by ``study.fit.calibrate.calibrate_model`` on its model; several by the same function on their
stacked, equally weighted residuals (``study.fit.joint.JointModel``). :class:`FitOptions` holds
everything that decides the fit besides the start constants, so a sweep point and ``study
calibrate`` given the same options and start fit the same constants.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .._backend import drjit_backend
from .._progress import log as _log
from ..config.errors import ExperimentError
from ..config.resolution import supersample_factor
from ..fit.calibrate import Calibration, calibrate_model
from ..fit.decorrelated import half_models, texture_half_models
from ..fit.joint import JointModel, joint_frozen
from ..fit.losses import LOSSES, STARTS_FROM, fit_ppd, transformed
from ..fit.solvers import SOLVERS


@dataclass(frozen=True)
class FitOptions:
    """What decides a fit besides its start.

    parameters: the constants to fit (``fit.parameters``; None: every one the shader reads
        that the experiment does not hold, ``model.parameter_names``).
    solver: a name of ``study.fit.solvers.SOLVERS``; max_steps: its iteration cap.
    basin_scan: scan the bump scale's loss for lower basins and refit from one
        (``study.fit.basins``; a single frame with the reference's standard error only).
    refine: refine on the decorrelated loss of the texture's independent halves
        (``fit.input_noise = "decorrelate"``: ``study.fit.decorrelated``).
    resolution: (width, height) pixels of the fit (None: ``fit.resolution``).
    loss: the error minimised, a key of ``study.fit.losses.LOSSES`` (``fit.loss``).
    target_resolution: (width, height) pixels the shader runs at in the game
        (``fit.target_resolution``, unset: ``resolution``); None: each fit pixel shaded once,
        at its centre. A fit pixel takes :meth:`supersample` samples per side.
    normal_equations: "solver" or "device" (``fit.normal_equations``): where the least-squares
        system is formed (``study.fit.normal_equations``).
    """

    parameters: tuple | None
    solver: str
    max_steps: int
    basin_scan: bool = True
    refine: bool = False
    resolution: tuple | None = None
    loss: str = "flip"
    target_resolution: tuple | None = None
    normal_equations: str = "solver"

    def __post_init__(self):
        check_loss(self.loss, self.solver, self.refine)
        if self.normal_equations == "device" and self.loss != "linear":
            raise ExperimentError(
                f'fit.normal_equations = "device" forms the squared error\'s system, and '
                f'fit.loss = "{self.loss}" transforms each residual on the host: set '
                'fit.normal_equations = "solver" (or fit.loss = "linear")'
            )

    @classmethod
    def of(cls, exp, solver: str | None = None, **changes) -> "FitOptions":
        """The options ``exp`` sets (``fit.parameters``, ``fit.solver``, ``fit.max_steps``,
        ``fit.input_noise``), ``solver`` and ``changes`` over them."""
        solver = check_solver(solver or exp.fit.solver)
        params = exp.fit.parameters
        opts = cls(
            parameters=None if params is None else tuple(params),
            solver=solver,
            max_steps=int(exp.fit.max_steps),
            refine=exp.fit.input_noise == "decorrelate",
            loss=str(exp.fit.loss),
            target_resolution=tuple(exp.fit.target_resolution or exp.resolution),
            normal_equations=str(exp.fit.normal_equations),
        )
        return dataclasses.replace(opts, **changes)

    @property
    def requested(self) -> list | None:
        return None if self.parameters is None else list(self.parameters)

    def supersample(self, exp) -> int:
        """Samples per side of a fit pixel of ``exp`` under these options
        (``study.config.resolution.supersample_factor``)."""
        return supersample_factor(self.resolution or exp.fit.resolution, self.target_resolution)


def check_solver(solver: str | None) -> str | None:
    """``solver`` when it names one of ``study.fit.solvers.SOLVERS`` (or is None); else
    ValueError naming the choices."""
    if solver is not None and solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}; choose one of {', '.join(SOLVERS)}")
    return solver


def check_loss(loss: str, solver: str | None, refine: bool) -> None:
    """ExperimentError, in one line naming the fix, when ``loss`` is unknown or cannot be used
    with ``solver`` or the texture-noise refinement (no fit falls back to another loss)."""
    if loss not in LOSSES:
        raise ExperimentError(f"unknown fit.loss {loss!r}; choose one of {', '.join(LOSSES)}")
    if loss == "linear":
        return
    if solver == "adam":
        raise ExperimentError(
            f'fit.loss = "{loss}" needs a least-squares solver, and adam fits the squared error '
            'only: set fit.solver = "levenberg_marquardt" (or fit.loss = "linear")'
        )
    if refine:
        raise ExperimentError(
            f'fit.input_noise = "decorrelate" refines the squared error only, not fit.loss = '
            f'"{loss}": set fit.input_noise = "ignore" (or fit.loss = "linear")'
        )


@dataclass
class Fit:
    """A fit's outcome: the ``models`` it ran on (one per frame, at the fit's resolution) and
    the ``calibration`` (``study.fit.calibrate.Calibration``)."""

    models: list
    calibration: Calibration


def frame_models(frames, shader, variant: str, options: FitOptions | None = None) -> list:
    """One model per frame (``Shader.model``) as ``options`` (default: those of the first
    frame's experiment, :meth:`FitOptions.of`) set it up: at their resolution, each fit pixel
    shaded :meth:`FitOptions.supersample` times per side, each model carrying its reference's
    per-pixel standard error and its residual that of the options' loss
    (``study.fit.losses``)."""
    frames = list(frames)
    options = options or FitOptions.of(frames[0].exp)
    backend = drjit_backend(variant)
    models = []
    for f in frames:
        model = shader.model(f.exp, f.inputs, f.ref.image, backend, options.resolution,
                             f.ref.stderr, options.supersample(f.exp))  # fmt: skip
        ppd = fit_ppd(model.reference.shape[1], f.ref.image.shape[1])
        models.append(transformed(model, options.loss, ppd))
    return models


def fit_frames(frames, shader, variant: str, options: FitOptions, start=None, models=None) -> Fit:
    """The constants of ``shader`` fitted over ``frames`` (a list of ``Frame``) with
    ``options``, from ``start`` (default: the start constants of the first frame's experiment).
    ``models``: the frames' models when built already (:func:`frame_models`). A loss of
    ``study.fit.losses.STARTS_FROM`` (``flip``) is fitted from the solution of its first
    stage's loss on the same models; the calibration's ``fit_summary["first_stage"]`` records
    that fit."""
    frames = list(frames)
    if models is None:
        models = frame_models(frames, shader, variant, options)
    elif any(getattr(m, "loss_name", "linear") != options.loss for m in models):
        raise ValueError(f"fit_frames: the models given are not those of fit.loss {options.loss!r}")
    first_loss = STARTS_FROM.get(options.loss)
    if first_loss is None:
        return _fit_once(frames, shader, variant, options, start, models)
    first_options = dataclasses.replace(options, loss=first_loss)
    first = _fit_once(frames, shader, variant, first_options, start,
                      [transformed(m.base, first_loss) for m in models])  # fmt: skip
    _log(f"calibrate: fit.loss = {options.loss!r} continues from the {first_loss} fit's solution")
    fit = _fit_once(frames, shader, variant, options, first.calibration.fitted, models)
    summary = first.calibration.fit_summary
    fit.calibration.fit_summary["first_stage"] = {
        "loss": first_loss,
        **{k: summary.get(k) for k in ("loss_start", "iterations", "n_jac_calls", "seconds")},
        "loss_value": summary.get("loss"),
    }
    return fit


def _fit_once(frames, shader, variant: str, options: FitOptions, start, models) -> Fit:
    """:func:`fit_frames` of one loss: ``models`` are that loss's."""
    first = frames[0]
    start = models[0].start_constants(first.exp) if start is None else start
    names = models[0].parameter_names(options.requested)
    w, h = options.resolution or first.exp.fit.resolution
    s = options.supersample(first.exp)
    _log(
        f"calibrate: fitting {', '.join(names)} of {models[0].label} with {options.solver} "
        f"(loss {options.loss}) on "
        f"{sum(int(m.mask.sum()) for m in models)} water pixels at {w}x{h}"
        + (f", {s}x{s} samples each (fit.target_resolution)" if s > 1 else "")
        + (f" ({len(frames)} frames)" if len(frames) > 1 else "")
    )
    if len(frames) == 1:
        halves, check = _halves(first, shader, variant, options)
        cal = calibrate_model(
            models[0],
            start,
            options.requested,
            options.solver,
            options.max_steps,
            frozen_by_scene=first.frozen,
            halves=halves,
            scan_basins=options.basin_scan,
            basin_check=check,
            on_device=options.normal_equations == "device",
        )
    else:
        cal = calibrate_model(
            JointModel(models, [f.name for f in frames]),
            start,
            options.requested,
            options.solver,
            options.max_steps,
            frozen_by_scene=joint_frozen([f.frozen for f in frames]),
            scan_basins=options.basin_scan,
            on_device=options.normal_equations == "device",
        )
    cal.parameters = shader.with_stages(cal.parameters)
    return Fit(models, cal)


def _halves(frame, shader, variant: str, options: FitOptions) -> tuple:
    """(the refinement's models on the texture's halves or None, the basin check's or None)."""
    exp, inputs, ref = frame.exp, frame.inputs, frame.ref.image
    backend = drjit_backend(variant)

    def model_of(half):
        return shader.model(exp, half, ref, backend, options.resolution,
                            supersample=options.supersample(exp))  # fmt: skip

    halves = half_models(exp, inputs, model_of) if options.refine else None
    # the basin check compares the halves' decorrelated squared error: for that loss only
    if not options.basin_scan or options.loss != "linear":
        return halves, None
    return halves, halves or texture_half_models(exp, inputs, model_of)
