"""The tradeoff's recommended point, and a user's own shader, calibrated and exported as ``study
calibrate`` does it (``study.calibration.run.calibrate``): the point's fit run again from the
point's start with the point's options (the same constants as its row), its start and fitted
constants scored at full resolution, the export into every engine target with the textures
the constants assume and its GL check, ``constants.json`` (a ``CalibrationResult``: every
constant's status), ``report.md``, figures and the viewer, in ``recommended/`` (one scene) or
``recommended/<scene>/``; a user's shader that is not the recommendation in ``yours/`` alike.
"""

from __future__ import annotations

from pathlib import Path

from ..calibration.frames import Frame, Frames
from ..calibration.run import calibrate
from ..calibration.shader import Shader
from ..fit.model import get_value
from ..sweep import load_scene
from .tradeoff_analysis import config_label, point_record
from .tradeoff_jobs import job_options, job_start
from .tradeoff_user import own_shaders

RELATIVE_MATCH = 1e-6  # the export's constants against the row's: the same fit, run again


def job_of(row: dict) -> dict:
    """The job of a table row (its flattened ``job.*`` columns): ``variant``, ``start`` (None
    when the job had none) and ``schedule``."""
    job = {"variant": row["job.variant"], "start": None, "schedule": {}}
    for k, v in row.items():
        for part in ("start", "schedule"):
            if k.startswith(f"job.{part}.") and v is not None:
                job[part] = job[part] or {}
                job[part][k[len(f"job.{part}.") :]] = v
    return job


def point_row(rows: list, scene: str, label: str) -> dict:
    """The measured row of the point ``label`` on ``scene`` (not the converged raymarch)."""
    return next(
        r
        for r in rows
        if r.get("job.experiment") == scene
        and r["status"] == "ok"
        and config_label(point_record(r)) == label
        and r.get("job.kind") != "converged"
    )


def calibrate_point(spec: dict, row: dict, folder: Path, variant: str, log) -> dict:
    """The point of ``row`` on the scene ``spec`` calibrated into ``folder`` (module
    docstring). Returns the record the tradeoff's summary keeps: ``folder`` (relative to the
    study's output folder: set by the caller), ``variant``, ``label``, ``constants``,
    ``parameters`` (each constant's status), ``gl_check``, ``engine_targets``."""
    exp, ref, inputs = load_scene(spec, variant)
    job = job_of(row)
    shader = Shader.of_table(exp, job["variant"])
    frame = Frame.of(exp, ref, shader.with_inputs(exp, inputs, variant))
    frames = Frames("still", variant, [frame], {}, exp)
    summary, fit = calibrate(
        frames, folder, job_options(exp, shader), shader, job_start(shader, job)
    )
    _check_same(fit.calibration, row, log)
    return {
        "variant": job["variant"],
        "label": config_label(point_record(row)),
        "constants": summary["constants"],
        "parameters": {n: p["status"] for n, p in summary["parameters"].items()},
        "gl_check": summary["gl_check"],
        "engine_targets": summary.get("engine_targets", {}),
    }


def _check_same(cal, row: dict, log) -> None:
    """A warning when the export's fitted constants differ from the row's beyond
    :data:`RELATIVE_MATCH` (the sweep ran another fit than ``study calibrate``)."""
    worst = 0.0
    for n in cal.parameters:
        key = f"fitted.{n.split('[')[0]}"
        if key not in row and f"fitted.{n}" not in row:
            continue
        theirs = row.get(f"fitted.{n}", row.get(key))
        if isinstance(theirs, (list, tuple)):
            theirs = theirs[int(n.split("[")[1].rstrip("]"))] if "[" in n else None
        if theirs is None:
            continue
        ours = get_value(cal.fitted, n)
        worst = max(worst, abs(ours - theirs) / max(abs(theirs), 1e-12))
    if worst > RELATIVE_MATCH:
        log(
            f"tradeoff: WARNING: the exported constants differ from the point's by {worst:.3g} "
            "(relative): the export's fit is not the point's"
        )


def export_points(exps, specs, summary: dict, rows: list, out: Path, variant: str, log) -> tuple:
    """Per scene, the recommendation calibrated into ``recommended[/<scene>]`` and, where the
    experiment's ``fit.shader`` is a user's file that is not the recommendation, that shader
    into ``yours[/<scene>]``. Returns ({scene: record}, {scene: the user's record}) (records as
    :func:`calibrate_point`, ``folder`` relative to ``out``; the user's with ``file``, its
    written file)."""
    exports, yours = {}, {}
    for exp, spec in zip(exps, specs):
        sub = [] if len(exps) == 1 else [exp.name]
        rec = summary["scenes"][exp.name]["recommended"]
        if rec is None:
            log(f"tradeoff: no successful point on {exp.name}; nothing exported")
        else:
            folder = out.joinpath("recommended", *sub)
            e = calibrate_point(spec, point_row(rows, exp.name, rec["label"]), folder, variant, log)
            exports[exp.name] = {**e, "folder": str(folder.relative_to(out))}
            _say(log, exp.name, "the recommendation", exports[exp.name])
        for mine in own_shaders(exp):
            e = _export_yours(spec, exp.name, mine, rec, rows, exports, out, sub, variant, log)
            if e is not None:
                core = Path(e["folder"]) / "shaders" / "core" / mine.label
                yours[exp.name] = {**e, "file": str(core)}
    return exports, yours


def _export_yours(spec, scene, mine, rec, rows, exports, out, sub, variant, log) -> dict | None:
    """The user's shader ``mine`` on ``scene``: the recommendation's export when it is the
    recommended point, else its own point calibrated into ``yours[/<scene>]``; None when its
    point failed."""
    if rec is not None and rec["variant"] == mine.table_name:
        return exports[scene]
    row = next((r for r in rows if r.get("job.experiment") == scene and r["status"] == "ok"
                and r.get("job.variant") == mine.table_name), None)  # fmt: skip
    if row is None:
        return None
    folder = out.joinpath("yours", *sub)
    e = {**calibrate_point(spec, row, folder, variant, log), "folder": str(folder.relative_to(out))}
    _say(log, scene, "your shader", e)
    return e


def _say(log, scene: str, what: str, e: dict) -> None:
    gl = e["gl_check"]
    verdict = "not run" if gl.get("ran") is False else ("passed" if gl.get("passed") else "FAILED")
    log(f"tradeoff: {scene}: exported {what}, {e['label']}, to {e['folder']} (GL check {verdict})")
