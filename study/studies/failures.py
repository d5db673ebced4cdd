"""The shader's failure catalogue: every water pixel classified by where seed 000's method fails.

The method (raycast a top-down world-y texture along the refracted ray, interpolate the
crossing, look the colour up in a top-down texture; for ``water_reflection`` the same upwards
against bottom-up textures) has a domain. A pixel outside it falls into one or more classes
(:data:`CLASSES`, tested in this order; the first that holds is the pixel's *primary* class,
shown in the class map):

``invalid_refraction``: TIR, a back-facing normal or a non-finite vector.
    ``refract``'s ``k < 0`` (total internal reflection: ``R = 0``), or ``dot(vEye,
    vBumpTexMore) <= 0`` (the bumped normal faces away from the eye: ``refract`` is applied
    from the back of the facet, the transmitted ray is not the physical one), or a non-finite
    intermediate vector (``diagnostics['nonfinite']``). No threshold: each is a sign or an
    IEEE test. TIR cannot happen here: air to water has ``eta = refrCoeff <= 1`` (the valid
    range), so ``k >= 1 - eta^2 > 0``; the test is kept as a check. Steep waves seen from low
    produce the back-facing case.
``depth_complexity``: the surface the refracted ray meets is hidden from the top-down view.
    Found from the scene geometry, not from the shader: the refracted ray (from the pixel's
    point on the water plane, along ``normalize(R)``) is intersected with the experiment's
    Mitsuba geometry without the water; from the hit point, moved ``HIDDEN_OFFSET`` along the
    hit's normal towards the ray, a ray is cast straight up to the water plane. If it hits
    anything, the surface the ray sees is absent from the top-down textures (e.g. the floor
    under a ledge, the ledge's underside): the shader cannot show it. ``HIDDEN_OFFSET`` = 1e-3
    world units is 100x Mitsuba's float32 self-intersection scale at unit distances and far
    below any feature of the scenes (the thinnest ledge is 0.1).
``no_crossing``: the loop ran ``LOOP_CAP`` steps without crossing the floor
    (``diagnostics['crossed'] == 0``); the seed has no hit test, so the crossing is
    extrapolated from the last two steps. Exact, no threshold.
``outside_textures``: a top-down lookup fell outside the textures' [0, 1]^2 (the start, a loop
    step, or the interpolated point; clamp-to-edge returns the border texel). Exact.
``small_denominator``: ``|cpoy - cpy + depth - olddepth| < DENOMINATOR_EPS`` (1e-3 world units),
    the threshold the port-vs-GL check uses (``shaders_port.gl.compare``): the port and GL differ by
    ~3e-5 in positions and depths (float32 rasteriser interpolation), which over a denominator
    of 1e-3 moves the interpolation weight by ~3 %, and without a crossing the weight is
    unbounded.
``grazing``: ``normalize(R).y > -GRAZING_RY`` (0.25): the refracted ray is within ~14 degrees of
    horizontal (or points up). A depth error then moves the floor point sideways by
    ``tan > 3.9`` times as much, and the seed's schedule (``mix(10, 3, -R.y)`` ~ 8.25 steps per
    unit at 0.25) descends only ``LOOP_CAP * 0.25 / 8.25 = 1.2`` units in 40 steps, about the
    depth of the shipped pools. Flat water never refracts below ``|R.y| = sqrt(1 - 1/n^2) =
    0.66``, so these pixels come from bumped normals tilted by more than ~40 degrees.
``refl_left_textures`` (``water_reflection``): the reflection ray left the reflection textures'
    [0, 1]^2 before hitting anything (``refl_exit == 1``); the cube map is used, right only if
    nothing lies beyond the textures. Exact.
``refl_no_hit`` (``water_reflection``): the cube map was used although the reflection ray hits
    the geometry of the reflection textures: the loop stopped it short (``REFL_LOOP_CAP``, or the
    height cut below the geometry's top) or stepped over a thin feature. Found by continuing the
    ray in NumPy (:func:`reflection_would_hit`) in steps of ``REFL_FINE_STEP`` (1/4) texel, the
    shader's own hit test (``refl_world_y > y``, nearest texel) from the water plane until it
    leaves the textures or rises above their highest texel. A ray that leaves the textures or
    passes above all geometry is the method working, not failing.

The table (:func:`failure_table`) gives per class its share of the water pixels, its share of
the total FLIP error, and the mean FLIP inside and outside the class (classes overlap; the
``none`` row is the pixels in no class).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shaders_port.pipeline.raster import rasterize_water
from shaders_port.variants import get_variant

from .._backend import drjit_backend
from ..calibration.shader import Shader
from .._io import write_json
from .._metrics import flip_map
from ..config.experiment import load_experiments
from ..fit.model import constants_from_experiment, constants_json
from ..report.failures import failures_figure, scenes_of, write_failures_report
from ..scene.mitsuba_scene import build_geometry
from ..sweep import load_scene, run_sweep, scene_spec, write_table

GRAZING_RY = 0.25
DENOMINATOR_EPS = 1e-3
HIDDEN_OFFSET = 1e-3
REFL_FINE_STEP = 0.25  # texels per step of the fine march of reflection rays


@dataclass(frozen=True)
class FailureClass:
    key: str
    title: str
    rule: str
    reflection_only: bool = False


CLASSES: tuple[FailureClass, ...] = (
    FailureClass(
        "invalid_refraction",
        "TIR, back-facing normal or non-finite vector",
        "k < 0 or dot(vEye, vBumpTexMore) <= 0 or non-finite",
    ),
    FailureClass(
        "depth_complexity",
        "floor hidden from the top-down view (depth complexity > 1)",
        "refracted ray's first hit has geometry above it (Mitsuba ray queries)",
    ),
    FailureClass("no_crossing", "no crossing within LOOP_CAP (extrapolated)", "crossed == 0"),
    FailureClass(
        "outside_textures",
        "top-down lookup outside the textures",
        "a depth or colour lookup outside [0, 1]^2",
    ),
    FailureClass(
        "small_denominator",
        "interpolation denominator near 0",
        f"abs(denominator) < {DENOMINATOR_EPS:g}",
    ),
    FailureClass("grazing", "grazing (or upward) refraction", f"normalize(R).y > -{GRAZING_RY:g}"),
    FailureClass(
        "refl_left_textures",
        "reflection ray left the reflection textures",
        "refl_exit == outside",
        reflection_only=True,
    ),
    FailureClass(
        "refl_no_hit",
        "reflection ray missed geometry it hits, cube map used",
        "no hit, but a 1/4-texel march hits the reflection textures",
        reflection_only=True,
    ),
)
CLASS_KEYS = tuple(c.key for c in CLASSES)
REQUIRED = (
    "crossed",
    "denominator",
    "nonfinite",
    "refract_k",
    "cos_eye_normal",
    "refr_dir_y",
    "lookup_outside",
)


def classes_for(shader_has_reflection_loop: bool) -> tuple[FailureClass, ...]:
    return tuple(c for c in CLASSES if shader_has_reflection_loop or not c.reflection_only)


def classify(
    maps: dict,
    water: np.ndarray,
    *,
    hidden: np.ndarray | None = None,
    refl_missed: np.ndarray | None = None,
) -> dict:
    """Boolean (H, W) membership of every class for the port's diagnostics ``maps``.

    Args:
        maps: (H, W) float32 diagnostics of a ``render(..., diagnose=True)`` (see ``REQUIRED``;
            ``refl_exit`` for ``water_reflection``).
        water: (H, W) bool, the pixels to classify (others are False in every class).
        hidden: (H, W) bool from :func:`hidden_from_top_down` (None: the class is not
            evaluated and reported as absent, e.g. for synthetic inputs with no scene).
        refl_missed: (H, W) bool from :func:`reflection_would_hit` (needed when ``refl_exit``
            is present): the fine march hits the reflection textures' geometry.
    Returns: dict class key -> (H, W) bool, in the order of :data:`CLASSES` (reflection classes
    only when ``maps`` has ``refl_exit``).
    """
    missing = [k for k in REQUIRED if k not in maps]
    if missing:
        raise ValueError(f"diagnostics {missing} are missing: render the port with diagnose=True")
    w = np.asarray(water, bool)
    out = {
        "invalid_refraction": (maps["refract_k"] < 0)
        | (maps["cos_eye_normal"] <= 0)
        | (maps["nonfinite"] > 0)
        | ~np.isfinite(maps["refr_dir_y"]),
        "depth_complexity": np.zeros_like(w) if hidden is None else np.asarray(hidden, bool),
        "no_crossing": maps["crossed"] < 0.5,
        "outside_textures": maps["lookup_outside"] > 0.5,
        "small_denominator": ~(np.abs(maps["denominator"]) >= DENOMINATOR_EPS),  # NaN counts
        "grazing": ~(maps["refr_dir_y"] <= -GRAZING_RY),
    }
    if "refl_exit" in maps:
        if refl_missed is None:
            raise ValueError(
                "refl_missed (reflection_would_hit) is needed to classify "
                "water_reflection's reflection rays"
            )
        e = maps["refl_exit"]
        out["refl_left_textures"] = e == 1
        out["refl_no_hit"] = (e != 0) & np.asarray(refl_missed, bool)
    return {k: v & w for k, v in out.items()}


def primary_class(classes: dict, water: np.ndarray) -> np.ndarray:
    """(H, W) int: -1 off the water, 0 = no failure, i + 1 = the first class (in
    :data:`CLASS_KEYS` order) that holds."""
    label = np.where(water, 0, -1).astype(np.int16)
    for i in reversed(range(len(CLASS_KEYS))):
        k = CLASS_KEYS[i]
        if k in classes:
            label = np.where(classes[k], i + 1, label)
    return label


def failure_table(classes: dict, flip: np.ndarray, scored: np.ndarray) -> list[dict]:
    """One row per class plus ``none`` (pixels in no class) over the ``scored`` pixels:
    ``pixels``, ``pixel_share`` (of the scored water pixels), ``flip_share`` (of the summed FLIP),
    ``flip_inside`` / ``flip_outside`` (mean FLIP in / not in the class; NaN if empty)."""
    s = np.asarray(scored, bool)
    n = int(s.sum())
    if n == 0:
        raise ValueError("failure_table: no scored water pixel")
    f = np.asarray(flip, np.float64)
    total = float(f[s].sum())
    rows = []
    anyc = np.zeros_like(s)
    for k, m in classes.items():
        anyc |= m
    for k, m in list(classes.items()) + [("none", ~anyc)]:
        inside, outside = m & s, ~m & s
        rows.append(
            {
                "class": k,
                "pixels": int(inside.sum()),
                "pixel_share": inside.sum() / n,
                "flip_share": float(f[inside].sum()) / total if total > 0 else float("nan"),
                "flip_inside": float(f[inside].mean()) if inside.any() else float("nan"),
                "flip_outside": float(f[outside].mean()) if outside.any() else float("nan"),
            }
        )
    return rows


def reflection_would_hit(
    inputs, origins: np.ndarray, directions: np.ndarray, chunk: int = 4096
) -> np.ndarray:
    """(N,) bool: the ray ``origins + t directions`` (N, 3), marched in steps of
    ``REFL_FINE_STEP`` texels of ``refl_world_y``, meets a texel whose world y is above it (the
    shader's hit test, nearest texel, ``tex_matrix1``) before it leaves the textures' [0, 1]^2
    or rises above their highest texel. Rays pointing down never hit (False)."""
    ry = np.asarray(inputs.refl_world_y, np.float64)
    H, W = ry.shape
    top = float(ry.max())
    M = np.asarray(inputs.tex_matrix1, np.float64)
    o = np.asarray(origins, np.float64)
    d = np.asarray(directions, np.float64)
    out = np.zeros(len(o), bool)
    if top <= 0.0 or not len(o):
        return out
    # world length of a texel along the ray's horizontal direction: the smaller of the two axes
    texel = min(
        1.0 / (W * max(np.linalg.norm(M[0, :3]), 1e-12)),
        1.0 / (H * max(np.linalg.norm(M[1, :3]), 1e-12)),
    )
    step = REFL_FINE_STEP * texel
    ok = np.isfinite(d).all(1) & (d[:, 1] > 0)
    for a in range(0, len(o), chunk):
        sl = slice(a, a + chunk)
        oo, dd, good = o[sl], d[sl], ok[sl]
        t_top = np.where(good, top / np.where(good, dd[:, 1], 1.0), 0.0)
        n = int(np.ceil(min(t_top.max(), 1e4 * texel) / step)) + 1 if good.any() else 0
        hit = np.zeros(len(oo), bool)
        alive = good.copy()
        for k in range(1, n + 1):
            if not alive.any():
                break
            p = oo + (k * step) * dd
            s = p @ M[0, :3] + M[0, 3]
            t = p @ M[1, :3] + M[1, 3]
            inside = (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1) & (p[:, 1] <= top)
            alive &= inside
            i = np.clip((t * H).astype(np.int64), 0, H - 1)
            j = np.clip((s * W).astype(np.int64), 0, W - 1)
            h = alive & (ry[i, j] > p[:, 1])
            hit |= h
            alive &= ~h
        out[sl] = hit
    return out


def hidden_from_top_down(exp, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(N,) bool: the first surface the ray ``origins + t directions`` meets in the experiment's
    geometry without the water is hidden from straight above (see ``depth_complexity`` in the
    module doc). ``origins``/``directions``: (N, 3) float world units, unit directions; rays
    pointing up or non-finite give False. Needs the Mitsuba variant set
    (``study._backend.init_backend``)."""
    import mitsuba as mi

    o = np.asarray(origins, np.float64)
    d = np.asarray(directions, np.float64)
    ok = np.isfinite(d).all(1) & (d[:, 1] < 0)
    d = np.where(ok[:, None], d, np.array([0.0, -1.0, 0.0]))
    scene = mi.load_dict({"type": "scene", **build_geometry(mi, exp, water=False)})

    def vec(a, cls):
        a = np.asarray(a, np.float32)
        return cls(mi.Float(a[:, 0]), mi.Float(a[:, 1]), mi.Float(a[:, 2]))

    si = scene.ray_intersect(mi.Ray3f(vec(o, mi.Point3f), vec(d, mi.Vector3f)))
    valid = np.array(si.is_valid(), bool) & ok
    p = np.stack([np.array(si.p.x), np.array(si.p.y), np.array(si.p.z)], 1).astype(np.float64)
    n = np.stack([np.array(si.n.x), np.array(si.n.y), np.array(si.n.z)], 1).astype(np.float64)
    n = np.where(((n * d).sum(1) > 0)[:, None], -n, n)  # facing the incoming ray
    q = np.where(valid[:, None], p + HIDDEN_OFFSET * n, np.array([0.0, -1.0, 0.0]))
    q[:, 1] = np.minimum(q[:, 1], -HIDDEN_OFFSET)
    up = mi.Ray3f(vec(q, mi.Point3f), mi.Vector3f(0.0, 1.0, 0.0))
    up.maxt = mi.Float(np.asarray(-q[:, 1], np.float32))
    blocked = np.array(scene.ray_test(up), bool)
    return valid & blocked & (p[:, 1] < 0)


@dataclass
class SceneCatalogue:
    """The catalogue of one experiment: images (H, W, 3) linear RGB, maps (H, W)."""

    experiment: str
    shader: str
    reference: np.ndarray
    port: np.ndarray
    classes: dict  # key -> (H, W) bool
    label: np.ndarray  # (H, W) int, see primary_class
    flip: np.ndarray  # (H, W) float32 LDR-FLIP
    scored: np.ndarray  # (H, W) bool, the scored water pixels (as in the fit)
    rows: list  # failure_table rows

    def records(self) -> list[dict]:
        """Tidy rows (one per class) for a table file."""
        return [{"experiment": self.experiment, "shader": self.shader, **r} for r in self.rows]


def catalogue_scene(
    exp,
    reference: np.ndarray,
    inputs,
    constants,
    *,
    shader: str | None = None,
    backend: str | None = None,
    depth_complexity: bool = True,
) -> SceneCatalogue:
    """Render the port of ``shader`` (default ``fit.shader``) with its failure diagnostics at the
    experiment's resolution, classify the water pixels, and score them with FLIP against
    ``reference`` (H, W, 3) linear RGB. ``depth_complexity=False`` skips the Mitsuba queries."""
    import warnings

    w, h = exp.resolution
    handle = Shader.of(exp, shader)
    model = handle.model(exp, inputs, reference, backend, (w, h))
    # a user's shader: what the study's refracted ray and the scene can tell (USER_CLASSES)
    diagnosed, kept = (_user_maps, USER_CLASSES) if handle.is_user else (_study_maps, CLASS_KEYS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # non-finite pixels are a class here
        out = diagnosed(exp, handle, model, constants, backend)
    water = out["mask"] > 0.5
    hidden = None
    if depth_complexity:
        r = rasterize_water(model.inputs)
        dirs = np.stack([out[f"refr_dir_{c}"].ravel()[r.index] for c in "xyz"], 1)
        hid = hidden_from_top_down(exp, r.world, dirs)
        hidden = np.zeros(h * w, bool)
        hidden[r.index] = hid
        hidden = hidden.reshape(h, w)
    refl_missed = None
    if "refl_exit" in out:
        r = rasterize_water(model.inputs)
        dirs = np.stack([out[f"refl_dir_{c}"].ravel()[r.index] for c in "xyz"], 1)
        refl_missed = np.zeros(h * w, bool)
        refl_missed[r.index] = reflection_would_hit(model.inputs, r.world, dirs)
        refl_missed = refl_missed.reshape(h, w)
    classes = classify(out, water, hidden=hidden, refl_missed=refl_missed)
    classes = {k: v for k, v in classes.items() if k in kept}
    fmap = flip_map(model.reference, out["color"])
    rows = failure_table(classes, fmap, model.mask)
    return SceneCatalogue(
        exp.name,
        model.shader,
        model.reference,
        out["color"],
        classes,
        primary_class(classes, water),
        fmap,
        model.mask,
        rows,
    )


# the classes of a user's shader: the scene's (the study's refracted ray through the scene's
# waves meets a hidden floor, or grazes) and the shader's own non-finite pixels; the others are
# steps of the seed's raycast that a user's code need not have
USER_CLASSES = ("invalid_refraction", "depth_complexity", "grazing")


def _study_maps(exp, shader, model, constants, backend: str) -> dict:
    """The maps :func:`classify` reads, for a shader of the study's space: its port's render
    with every diagnostic."""
    return model.variant.render(model.inputs, constants, backend=backend, diagnose=True).numpy()


def _user_maps(exp, shader, model, constants: dict, backend: str) -> dict:
    """The maps :func:`classify` reads, for a user's shader (``Shader``): its render's
    colour, coverage and non-finite pixels with ``constants``, and the refracted ray of the
    study's ``water_refraction`` port at the experiment's start constants (the scene's waves
    and refraction index): ``refract_k``, ``cos_eye_normal``, ``refr_dir_*``."""

    mine = shader.render(model.inputs, constants, backend)
    study = (
        get_variant("water_refraction")
        .render(model.inputs, constants_from_experiment(exp), backend=backend, diagnose=True)
        .numpy()
    )
    out = dict(study)
    out.update(color=mine["color"], mask=mine["mask"], nonfinite=mine["nonfinite"])
    return out


# ---- the study on the sweep engine: one job per experiment ---------------------------------


def failures_job(job: dict) -> dict:
    """Sweep job (``study.sweep.run_sweep``): the catalogue of one scene. ``job``: ``scene`` (a
    scene spec), ``variant`` (Mitsuba), ``shader`` (or None: ``fit.shader``), ``constants`` (a
    ``Constants.to_dict()`` or None: the experiment's start constants), ``out`` (folder). Writes
    ``<out>/<name>/failures.png``; returns the scene's figures and per class its table row."""
    from pathlib import Path

    exp, ref, inputs = load_scene(job["scene"], job["variant"])
    shader = Shader.of(exp, job.get("shader"))
    inputs = shader.with_inputs(exp, inputs, job["variant"])
    constants = shader.start(exp, job.get("constants"))
    cat = catalogue_scene(
        exp,
        ref.image,
        inputs,
        constants,
        shader=job.get("shader"),
        backend=drjit_backend(job["variant"]),
    )
    folder = Path(job["out"]) / exp.name
    folder.mkdir(parents=True, exist_ok=True)
    failures_figure(
        folder / "failures.png",
        cat.reference,
        cat.port,
        cat.label,
        cat.flip,
        cat.scored,
        list(CLASS_KEYS),
        title=f"{exp.name}: {cat.shader}",
    )
    fields = ("pixels", "pixel_share", "flip_share", "flip_inside", "flip_outside")
    return {
        "experiment": exp.name,
        "shader": cat.shader,
        "figure": f"{exp.name}/failures.png",
        "flip": float(cat.flip[cat.scored].mean()),
        "water_pixels": int(cat.scored.sum()),
        "reference_spp": ref.spp,
        "reference_noise": ref.noise,
        "classes": {r["class"]: {k: r[k] for k in fields} for r in cat.rows},
    }


def tidy_rows(sweep_rows: list[dict]) -> list[dict]:
    """One row per (experiment, class) from the sweep's rows (status ok only)."""
    out = []
    for row in sweep_rows:
        if row.get("status") != "ok":
            continue
        for k in CLASS_KEYS + ("none",):
            if f"classes.{k}.pixels" not in row or row[f"classes.{k}.pixels"] is None:
                continue
            out.append(
                {
                    "experiment": row["experiment"],
                    "shader": row["shader"],
                    # the scene's own figures, repeated on each of its rows (the report's text)
                    "scene_flip": row["flip"],
                    "water_pixels": row["water_pixels"],
                    "reference_spp": row.get("reference_spp"),
                    "reference_noise": row.get("reference_noise"),
                    "figure": row["figure"],
                    "class": k,
                    **{
                        f: row[f"classes.{k}.{f}"]
                        for f in (
                            "pixels",
                            "pixel_share",
                            "flip_share",
                            "flip_inside",
                            "flip_outside",
                        )
                    },
                }
            )
    return out


def run_failures(
    experiments: list,
    out,
    overrides=None,
    *,
    variant: str = "llvm_ad_rgb",
    shader: str | None = None,
    constants=None,
    scheduler=None,
    workers=None,
    log=None,
) -> list[dict]:
    """``study failures``: one sweep job per experiment (:func:`failures_job`), then
    ``failures.parquet`` (one row per experiment and class), ``report.md`` and the sweep's own
    resumable table ``sweep.parquet`` in ``out``. ``constants``: a ``Constants`` for every scene
    (None: each experiment's start constants). Returns the tidy rows."""
    import sys
    from pathlib import Path

    log = log or (lambda m: print(m, file=sys.stderr, flush=True))
    exps = load_experiments(experiments, overrides)
    names = [e.name for e in exps]
    Shader.of(exps[0], shader)  # a shader of the space by name, or a file: checked here
    out_arg, out = str(out), Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    jobs = [
        {
            "scene": scene_spec(p, overrides or []),
            "variant": variant,
            "shader": shader,
            "constants": constants_json(constants) if constants is not None else None,
            "out": str(out),
        }
        for p in experiments
    ]
    rows = run_sweep(
        failures_job,
        jobs,
        out / "sweep.parquet",
        scheduler=scheduler,
        workers=workers,
        variant=variant,
        label="failures",
        log=log,
    )
    rows = rows[: len(jobs)]
    bad = [(n, r.get("error")) for n, r in zip(names, rows) if r.get("status") != "ok"]
    for n, err in bad:
        log(f"failures: {n} failed: {err}")
    if len(bad) == len(rows):
        raise RuntimeError(f"every experiment failed; first error: {bad[0][1]}")
    tidy = tidy_rows(rows)
    write_table(out / "failures.parquet", tidy)
    command = (
        "study failures "
        + " ".join(str(p) for p in experiments)
        + "".join(f" --set {o}" for o in overrides or [])
        + f" --out {out_arg}"
    )
    write_json(out / "summary.json", {"command": command, "experiments": names})
    scenes = scenes_of(tidy)
    write_failures_report(out, scenes, list(CLASSES), command)
    for s in scenes:
        log(
            f"failures: {s['experiment']}: "
            + ", ".join(
                f"{t['class']} {100 * t['pixel_share']:.1f} %" for t in s["rows"] if t["pixels"]
            )
        )
    log(f"failures: wrote {out}")
    return tidy
