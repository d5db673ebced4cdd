"""The result of a calibration as one typed record: what ``constants.json`` holds.

``study calibrate`` (one scene) and its joint form (several scenes, one constants block) both
write a :class:`CalibrationResult`; the reports read it back from the JSON. Fields shared by
both forms come first; the one-scene and joint-only fields are ``None`` when they do not apply
and are then left out of the JSON. Numbers are plain Python floats (non-finite ones written as
``null``), so the file is strict JSON.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, asdict, dataclass, field, fields

import numpy as np

from shaders_port import GLSL_NAMES, glsl_scalar, study_scalar
from shaders_port.variants import get_variant


def jsonable(x):
    """``x`` with numpy scalars and arrays turned into Python numbers and lists, tuples into
    lists, dict keys into strings and non-finite floats into ``None`` (strict JSON)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    return x


@dataclass
class CalibrationResult:
    """One calibration, as written to ``constants.json``, every constant named as the shader's
    GLSL names it (:func:`glsl_named`).

    Shared:
        shader: the shader variant fitted (``shaders_port.variants``).
        backend: the Mitsuba variant the reference was rendered with (e.g. ``llvm_ad_rgb``).
        parameters: constant -> {"status", "value", "start", ...} (``study.fit.calibrate``).
        constants: the fitted constants, ``Constants.to_dict()`` (what ``study export`` reads).
        error: one scene: {"rmse": {"default", "fitted"}, "flip": {...}} on the water pixels at
            the experiment's resolution; joint: scene -> {"default": {...}, "fitted": {...}}.
        solver: the solver's name; loss: the error it minimised (``fit.loss``, a key of
        ``study.fit.losses.LOSSES``; "linear" in files written before it was recorded); fit: its
        summary (iterations, converged, message, steps).
        identifiability: the identifiability analysis at the fitted constants.
        timings: stage -> seconds.
        gl_check: the exported shader on OpenGL against the port (``study.export.gl_check``).
    One scene:
        experiment, fit_resolution / resolution ([width, height] pixels), supersample (samples
        per side of a fit pixel; 1 in files written before it was recorded) and
        target_resolution (the game's [width, height] it stands for), fit_error ({"flip",
        "rmse"} of the fitted constants at the fit's resolution: the image the fit saw, its
        samples folded, against the reference box-downsampled), step_sweep (the
        integer step schedule's sweep), reference (spp, noise, path, key), diagnostics (the
        port's diagnostics over the water), sun, parsimony (information criteria).
    Joint:
        experiments (paths), scenes (names), weights (scene -> weight of its residuals).
    Both, when written: engine_targets (the HLSL, Metal, GLSL ES and SPIR-V exports and what
    checked each, ``study.export.gl_check.target_checks``); textures (the Fresnel LUT and the
    normal map the constants assume, exported beside them: ``study.export.textures``); export
    (what the export wrote, in the report's words: ``files`` and ``constants``).
    """

    shader: str
    backend: str
    parameters: dict
    constants: dict
    error: dict
    solver: str
    fit: dict
    identifiability: dict
    timings: dict
    gl_check: dict
    loss: str = "linear"
    experiment: str | None = None
    fit_resolution: list | None = None
    resolution: list | None = None
    supersample: int = 1
    target_resolution: list | None = None
    fit_error: dict | None = None
    step_sweep: dict | None = None
    reference: dict | None = None
    diagnostics: dict | None = None
    sun: dict | None = None
    parsimony: dict | None = None
    experiments: list | None = None
    scenes: list | None = None
    weights: dict | None = None
    engine_targets: dict | None = None
    textures: dict | None = None
    export: dict | None = None
    extra: dict = field(default_factory=dict)

    @property
    def joint(self) -> bool:
        return self.scenes is not None

    def to_json(self) -> dict:
        """The JSON object of ``constants.json``: the fields (``None`` ones left out), the fit's
        ``iterations``, ``converged`` and ``message`` at the top level too, ``joint`` when joint."""
        d = {k: v for k, v in asdict(self).items() if v is not None and k != "extra"}
        d.update(
            iterations=self.fit.get("iterations", 0),
            converged=self.fit.get("converged", False),
            message=self.fit.get("message", ""),
        )
        if self.joint:
            d["joint"] = True
        d.update(self.extra)
        d = jsonable(d)
        return d if "shader_file" in d else glsl_named(d)

    @classmethod
    def from_json(cls, data: dict) -> "CalibrationResult":
        """The record of a ``constants.json`` object (keys not of this class kept in ``extra``)."""
        names = {f.name for f in fields(cls)} - {"extra"}
        derived = {"iterations", "converged", "message", "joint", "constant_names"}
        derived |= {"constants_not_read"}  # merged back into ``constants``: to_json splits them
        if isinstance(data.get("constants"), dict):
            rest = (data.get("constants_not_read") or {}).get("values", {})
            data = {**data, "constants": {**rest, **data["constants"]}}
        required = [f.name for f in fields(cls) if f.default is MISSING and f.name != "extra"]
        missing = [n for n in required if n not in data]
        if missing:
            raise ValueError(f"not a calibration result: missing {missing}")
        extra = {k: v for k, v in data.items() if k not in names | derived}
        return cls(**{k: v for k, v in data.items() if k in names}, extra=extra)


def glsl_renamed(x):
    """``x`` (JSON-able) with every dict key and every string that is a study constant's name
    (or one of its components) renamed to the GLSL's name."""
    if isinstance(x, dict):
        return {glsl_scalar(k): glsl_renamed(v) for k, v in x.items()}
    if isinstance(x, list):
        return [glsl_renamed(v) for v in x]
    return glsl_scalar(x) if isinstance(x, str) else x


def glsl_named(d: dict) -> dict:
    """A calibration of one of the study's shaders as its JSON names it: every constant by its
    GLSL name (``ATTENUATION_DISTANCE``, ``waterColor[1]``; ``parameters[...]["name"]`` and
    ``constant_names`` give the study's descriptive name beside it); ``constants`` holds what
    the shader reads, ``constants_not_read`` the rest of the constants block (exported at those
    values, read by no line of this shader). Idempotent: a record already so named is unchanged."""
    out = glsl_renamed({k: v for k, v in d.items() if k not in ("constants", "constants_not_read")})
    values = {glsl_scalar(k): v for k, v in d["constants"].items()}
    values.update((d.get("constants_not_read") or {}).get("values", {}))
    try:
        reads = {GLSL_NAMES[n] for n in get_variant(d["shader"]).reads()}
    except (KeyError, ValueError):
        reads = set(values)
    out["constants"] = {k: v for k, v in values.items() if k in reads}
    rest = {k: v for k, v in values.items() if k not in reads}
    if rest:
        out["constants_not_read"] = {
            "why": f"declared in the constants block but read by no line of {d['shader']}: "
            "exported at these values, which change nothing",
            "values": rest,
        }
    out["constant_names"] = {k: study_scalar(k) for k in values}
    out["parameters"] = {
        k: {**p, "name": study_scalar(k)} for k, p in out.get("parameters", {}).items()
    }
    return out
