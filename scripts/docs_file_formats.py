"""``docs/file-formats.md``, written by ``scripts/build_docs.py``: the files a user gives and the
result files the tool writes. Its tables come from the code and the committed results: the
file keys and the keys that go with them from the experiment schema, the limits from
``study.config.files`` and ``study.config.image_maths``, the columns of each table from its
committed Parquet file under ``docs/results``, the top-level entries of a tradeoff's
``summary.json`` from the committed one, and ``textures.json`` from
``study.export.textures.texture_record`` on the default experiment.
A column or entry without a description here fails the build (describe it below)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

REPO = Path(__file__).resolve().parent.parent
RESULTS = REPO / "docs" / "results"

# the keys that shape how a file is read or placed, beside the file keys themselves
COMPANION_KEYS = (
    "floor.shape",
    "floor.extent",
    "floor.depth",
    "floor.height_scale",
    "sky.rotation",
    "sky.scale",
    "sun.source",
    "mesh.position",
    "mesh.scale",
    "mesh.rotation",
    "mesh.albedo",
)

# column name -> meaning; a prefix ending in "." (or "[") stands for every column under it
COLUMNS = {
    "job.scene.experiment": "the experiment file the job's scene was loaded from",
    "job.scene.overrides": "the `--set` overrides of that scene (TOML `key=value` strings)",
    "job.experiment": "the experiment's `name`",
    "job.variant": "the shader (a name of the shader space, or `user:<file>`)",
    "job.kind": "how the schedule was chosen: `grid`, `scale` (the original's schedule times "
    "`job.scale`), `converged` (the error floor, not a candidate) or `fixed` (no raymarch)",
    "job.scale": "the factor on the original's schedule (kind `scale` and `converged`)",
    "job.factor": "the screen's downscale of `fit.resolution` (adaptive search)",
    "job.screen_version": "what a screen row holds (2: the per-pixel maps); a table of an earlier "
    "version is screened again",
    "job.point_version": "what a full point's row holds (2: the per-pixel maps); a table of an "
    "earlier version is measured again",
    "job.schedule.": "the schedule the point was measured at (`steps_grazing`, `steps_steep`, "
    "`loop_cap`; `refl_*` for a raycast reflection)",
    "job.start.": "the constants the fit started from (names of the shader's constants; a "
    "colour as a list of 3 linear RGB values, or one column per channel `[0]` .. `[2]`)",
    "job.solver": "the solver of the fit",
    "job.lr": "Adam's learning rate (null for other solvers)",
    "job.start_index": "which Latin-hypercube start",
    "job.names": "the constants fitted",
    "job.max_steps": "the solver's step limit",
    "job.which": "what was re-rendered with fewer samples: `reference` or `texture`",
    "job.spp": "its samples per pixel",
    "job.seed": "its seed",
    "key": "the job's key (a hash of the job): a re-run skips the jobs whose key has an `ok` row",
    "schema": "the table's row layout version (`study.sweep.table.SCHEMA_VERSION`): a re-run "
    "sets rows of another version aside in `<table>.schema<N>.parquet`",
    "status": "`ok` or `error`",
    "error": "the error message of a failed job (null when `ok`)",
    "seconds": "wall time of the job, s",
    "worker": "host name of the worker that ran it",
    "kernels_launched": "what Dr.Jit launched for the job (its kernel history): kernels and "
    "memory operations",
    "kernels_compiled": "JIT kernels compiled for the job (none found in Dr.Jit's kernel cache)",
    "kernels_cached": "JIT kernels taken from the kernel cache (in memory or on disk)",
    "kernels_replayed": "JIT kernels replayed from a frozen function's recording",
    "kernel_compile_ms": "code generation and compilation of the job's kernels, ms",
    "copies": "memory copies Dr.Jit made for the job (on a GPU: host-device transfers)",
    "copy_bytes": "their bytes",
    "flip": "FLIP on the water pixels against the reference (0 = identical)",
    "rmse": "RMSE on the water pixels, linear RGB",
    "fit_seconds": "wall time of the fit, s",
    "fit_iterations": "the solver's steps over the fit's rounds",
    "water_pixels": "pixels scored (the water mask)",
    "flip_blocks": "the FLIP map averaged over 4 x 4 pixel blocks, row-major, NaN where a block "
    "has no water (the search's paired noise estimate)",
    "flip_map": "the per-pixel FLIP map (a screen row: at the screen's resolution; a full point: "
    "at the experiment's), little-endian float16 bytes, row-major, NaN off the water (the "
    "level-of-detail policies are chosen from the full points')",
    "fetch_map": "the per-pixel texture fetches, as `flip_map`",
    "map_shape": "(height, width) of `flip_map` and `fetch_map`",
    "n_fitted": "constants fitted (or at a bound)",
    "aic": "Akaike information criterion of the fit residual",
    "bic": "Bayesian information criterion of the fit residual",
    "fetches_mean": "texture fetches per water pixel, mean (the machine-independent cost)",
    "fetches_p99": "texture fetches per water pixel, 99th percentile",
    "iterations_mean": "raymarch loop iterations per water pixel, mean",
    "iterations_p99": "raymarch loop iterations per water pixel, 99th percentile",
    "refl_iterations_mean": "reflection-march loop iterations per water pixel, mean",
    "refl_iterations_p99": "reflection-march loop iterations per water pixel, 99th percentile",
    "not_crossed": "share of water pixels whose ray never crossed the floor within the loop cap",
    "nonfinite_pixels": "water pixels the port rendered as NaN or infinite",
    "gl_ms_512": "llvmpipe frame time at 512x512, ms (median of `tradeoff.gl_repeats`)",
    "gl_ref_ms_512": "the fixed reference shader's frame time at 512x512 in the same job, ms",
    "gl_ratio_512": "`gl_ms_512 / gl_ref_ms_512`",
    "gl_ms_1080p": "llvmpipe frame time at 1920x1080, ms",
    "gl_ref_ms_1080p": "the reference shader's frame time at 1920x1080 in the same job, ms",
    "gl_ratio_1080p": "`gl_ms_1080p / gl_ref_ms_1080p` (the report's normalised GL ms multiplies "
    "it by the median reference time)",
    "port_ms_512": "the Dr.Jit port's frame time at 512x512, ms",
    "fitted.": "the fitted constants (as `job.start.`)",
    "status_of.": "each fitted constant's status (as `status.`; a colour's channels as "
    "`[0]` .. `[2]`)",
    "loss": "the final loss",
    "loss_start": "the loss at the start",
    "iterations": "the solver's steps",
    "converged": "whether the solver reported convergence",
    "message": "the solver's stop message",
    "failure": "how the run stopped (e.g. `converged`, `step_cap`)",
    "trace_loss": "the loss after each step",
    "trace_seconds": "the time of each step, s",
    "reference_noise": "the reference's noise (mean standard error on the water pixels)",
    "value.": "the fitted value of each constant",
    "status.": "each constant's status after the fit (e.g. `fitted`, `bound`)",
    "rel_se.": "each constant's standard error relative to its value",
    "experiment": "the experiment's `name`",
    "shader": "the shader measured",
    "scene_flip": "FLIP of the whole scene's water pixels",
    "reference_spp": "the reference's samples per pixel",
    "figure": "the scene's figure (`<name>/failures.png`)",
    "class": "the failure class (see [the failure catalogue](failures.md))",
    "pixels": "water pixels of the class",
    "pixel_share": "their share of the water pixels",
    "flip_share": "their share of the scene's FLIP (sum over the pixels)",
    "flip_inside": "mean FLIP on the class's pixels",
    "flip_outside": "mean FLIP on the other water pixels",
}

TABLES = (
    (
        "tradeoff/tradeoff.parquet",
        "`study tradeoff`: one row per point measured in full",
    ),
    ("tradeoff/screen.parquet", "`study tradeoff` (adaptive search): one row per screen point"),
    ("failures/failures.parquet", "`study failures`: one row per scene and failure class"),
    (
        "stability/multistart/multistart.parquet",
        "`study stability --phases multistart`: one row per solver run",
    ),
    ("stability/noise/noise.parquet", "`study stability --phases noise`: one row per re-fit"),
)

SUMMARY = {
    "budget": "the `--budget` limits (cost measure -> limit; empty without one)",
    "cost": "the cost measure the recommendation uses",
    "error": "the error measure",
    "experiments": "the experiment files",
    "exports": "per scene, the exported recommendation: folder, shader, constants, GL check, "
    "engine targets",
    "failures": "the points that failed, with their messages",
    "gl_reference_ms_1080p": "the reference shader's median frame time at 1920x1080, ms",
    "images": "per scene, the side-by-side figure's file",
    "n_failed": "points that failed",
    "n_points": "points measured in full",
    "panels": "per scene, each panel of the side-by-side: FLIP and RMSE",
    "scenes": "per scene: the front, the fronts by each cost, the recommendation, the original's "
    "point (`seed`), the best within its fetches, what the scene needs, each source alone, the "
    "marginals of the adaptive search, where a user's shader stands",
    "search": "how the points were chosen: mode, axes held, points, seconds",
    "tolerance": "the recommendation's tolerance on FLIP (a fraction)",
    "user_exports": "per scene, a user's own shader exported with its fitted constants",
}

# the files a user gives: (file, key, accepted, channels and values, orientation)
INPUT_ROWS = (
    (
        "floor heightmap",
        '`floor.heightmap` (with `floor.shape = "heightmap"`)',
        "EXR, or a 16-bit greyscale PNG (an 8-bit PNG is refused: 256 levels make terraces)",
        "one channel; the floor is at `y = -floor.depth + floor.height_scale * texel` "
        "(world units)",
        "covers `floor.extent` `[x0, z0, x1, z1]`: columns along +x from x0 to x1, row 0 at "
        "z0, texel centres at the cell centres, bilinear, clamped at the border; must cover "
        "the water",
    ),
    (
        "floor albedo",
        "`floor.albedo_image`",
        "PNG/JPEG (sRGB, decoded to linear) or EXR (linear)",
        "1 (grey), 3 or 4 channels (alpha ignored); albedo in [0, 1]",
        "as the heightmap",
    ),
    (
        "sky",
        "`sky.envmap`",
        "EXR only (linear radiance)",
        "RGB (or RGBA), radiance >= 0",
        "lat-long, width = 2 x height, Mitsuba's `envmap` convention: u = atan2(x, -z) / 2pi, "
        "v = acos(y) / pi, row 0 at the zenith; turned about +y by `sky.rotation` (from +x "
        "towards +z) and multiplied by `sky.scale`",
    ),
    (
        "mesh",
        "`mesh.file`",
        "OBJ or PLY (Mitsuba's `obj` / `ply` loaders; a PLY starts with `ply`)",
        "geometry; diffuse with `mesh.albedo` or `mesh.texture`",
        "scaled by `mesh.scale`, turned by `mesh.rotation` about +y, moved by "
        "`mesh.position`; it must lie entirely above the water",
    ),
    (
        "mesh texture",
        "`mesh.texture` (needs `mesh.file` with texture coordinates)",
        "as the floor albedo",
        "as the floor albedo",
        "the mesh's texture coordinates",
    ),
)


HEADER = """# File formats

The files you give an experiment, and the files the tool writes. World units, `+y` up, the
water plane at `y = 0`, colours linear RGB unless said otherwise. This page is generated by
`scripts/build_docs.py` (`scripts/docs_file_formats.py`) from the experiment schema, the readers
in `study/config/files.py` and the result files committed under `docs/results/`.
"""

INPUTS = """## Files you give

A file key names a file relative to the experiment file (in `--set`, to the working directory);
`""` means none (the built-in floor shape, the tiles, the gradient sky, no mesh). Every file is
read and checked when the experiment is loaded, and an error names the key and the file. Its
contents (SHA-256), not its path, enter the cache keys: a changed file is a new scene.

Images: {image_ext}, from 2 x 2 up to {max_texels:,} texels, every texel finite. An EXR is read
as stored (float; one channel of any name, or `RGB`/`RGBA`); a PNG or JPEG as its 8-bit values
/ 255 or 16-bit values / 65535. Meshes: {mesh_ext}.

{input_table}

With `sun.source = "envmap"` the sun is taken from the sky map: its brightest texel and the
texels connected to it brighter than {sun_threshold:g} x it; the brightest texel must be at
least {sun_contrast:g} x the median, or the map has no sun and is refused. The reference keeps
the map as it is; the shader gets the region as its light and the map with the region filled
in as its cube map. With `sun.source = "explicit"` the `sun.*` disc is added to the map; its
radius must be at least one texel of the map.

The keys ([all keys](experiment-keys.md)):

"""

OUTPUTS = """## Files the tool writes

Every command writes into its `--out` folder. EXR files are float32, linear RGB, row 0 at the
top, written atomically (a killed run leaves no half-written file); their provenance is a JSON
string in the header attribute `study_provenance`.

### `reference.exr` (`study render`, `study preview`)

The path-traced reference at `resolution`: the `RGB` layer, the mean of the passes. Its
provenance: `key` (the cache key), `scene_hash`, `experiment`, `spp` (rendered), `spp_asked`
(asked, or chosen by `reference.spp = "auto"`), `spp_per_pass` and `n_seeds` (passes of
independent seeds: `spp = n_seeds x spp_per_pass`, rounded up so that `sampler` can stratify:
128 asked are 4 passes of 35 for `multijitter`, 140), `sampler`, `seed`, `variant`, `versions`,
`scene_version`, `render_seconds`, `noise` (the mean standard error of the mean on the water
pixels), `auto_spp` (the pilot's figures) and `integrator`. The cached copy under
`.cache/references/` also has the per-pixel standard error (layer `stderr`, (H, W, 3)).

### `summary.json`

Every command writes one: what it ran (experiment, backend, timings) and every number its
report is written from. The top-level entries of `study tradeoff`'s:

"""

PANELS = """
### `images_<scene>.png`, `.exr` and `.json` (`study tradeoff`)

The side-by-side figure and the data it is drawn from, so that it can be drawn again
(`scripts/build_docs.py` does). `images_<scene>.exr`: the reference as its `RGB` layer, every
other panel as an (H, W, 3) layer `panel_1`, `panel_2`, ..., and the water pixels scored as
an (H, W) layer `mask` (1 on water). `images_<scene>.json`: `title`, `figure` and `panels`, in
the figure's order, each with `title`, `layer` and (not the reference) `flip` and `rmse` on the
water pixels.

### Tables (Parquet)

Sweeps write one Parquet row per job, appended as jobs finish; a re-run resumes from the table.
A name ending in `.` stands for the columns under it. The columns of the committed tables:

"""

TEXTURES = """
### `shaders/textures/` (`study calibrate`, `study tradeoff`, `study export`)

The fitted constants hold only with the two textures they were fitted with, written beside
the exported shaders as float32 EXR (upload them as float textures, not 8-bit):

* `fresnel_lut.exr`: N x 1 texels (one row), R = transmission, G = reflection, B = 0; texel i
  at s = (i + 0.5) / N, s the cosine between the normal and the view ray; nearest, clamp to
  edge. The transmission is `1 - R`, or `(1 - R) / n^2` with
  `reference.fresnel_transmission = "radiance"` (an engine's usual LUT then shows the water
  n^2 times too bright through the surface).
* `normal_map.exr`: S x S texels, `0.5 n + 0.5` per channel (+y up in world space), bilinear,
  repeat; row 0 of the file is t = 0 (upload in file order).
* for a user's shader, every other texture it reads that the engine uploads: `dudv_map.exr`,
  `waves_normal_map.exr`, `user_normal_map.exr`, `sky_cube_{px,nx,py,ny,pz,nz}.exr`
  (`reflection_cube_*.exr`), each
  under `shipped` in `textures.json` (files, size, encoding, filter, wrap, mipmaps, `bound_as`:
  the shader's sampler names); the engine's own render targets it reads under `rendered`
  (`bound_as`, `what`), no file.
* `textures.json`: what the constants assume of both, and under `scene` the values the fit
  used that an engine sets (the light, the waves' offsets and velocities, the top-down
  camera's rectangle, size and `uTextureMatrix0`, rows; the binding sheets' "Values the fit
  used"), e.g. for `experiments/default.toml`:

"""

CONSTANTS_ROWS = [
    (
        "`shader`",
        "the shader the constants were fitted for (one of the study's space, or your file)",
    ),
    (
        "`constants`",
        "GLSL name -> value (a number, or a list of 4 for a `vec4`) of every constant the "
        "shader reads",
    ),
    (
        "`constants_not_read`",
        '`{"why": ..., "values": {...}}`: the rest of the study\'s constants block, which this '
        "shader never reads (exported at these values, which change nothing)",
    ),
    (
        "`constant_names`",
        "GLSL name -> the study's descriptive name (`BumptexMult` -> `bumptex_mult`)",
    ),
    (
        "`parameters`",
        "per fitted scalar (GLSL name): `default` (the start), `fitted`, `status` (`fitted`, "
        "`bound`, `frozen`), `reason`, sensitivities, standard errors, `name` (the study's); "
        "`stage` (`fragment`, `vertex`, `both`: the stages that read it) for your shader after "
        "your own vertex shader",
    ),
    ("`error`", "RMSE and FLIP on the water pixels, `default` and `fitted` (joint: per scene)"),
    (
        "`fit`, `solver`, `iterations`, `converged`, `message`",
        "the solver, its steps and why it stopped",
    ),
    (
        "`identifiability`",
        "sensitivities, standard errors and singular values at the start and the solution",
    ),
    (
        "`reference`",
        "samples per pixel (asked and rendered), sampler, measured noise, cache file",
    ),
    (
        "`textures`",
        "what `shaders/textures/textures.json` says: the Fresnel LUT's law, the normal map",
    ),
    (
        "`gl_check`, `engine_targets`",
        "the exported shader on llvmpipe against the port; each engine target, what checked it",
    ),
    (
        "`shader_file`, `shader_sha256`, `declaration`",
        "your own shader's calibration only: its file, the SHA-256 of the text the calibration "
        "leaves, its declaration (the constants of both stages)",
    ),
    (
        "`vertex_file`, `vertex_grid`, `vertex_defines`",
        "your own vertex shader's calibration only: its file, the grid it ran on, its defines",
    ),
]
CONSTANTS = (
    """
### `constants.json`

What `study calibrate` writes (one scene, several scenes jointly, or the frames of an animated
experiment) and what `study export` takes back; a tradeoff writes one for its recommendation,
`recommended/constants.json`. One JSON object; every constant named as the shader's GLSL names it
(`ATTENUATION_DISTANCE`, `BumptexMult`, a component of a vector `waterColor[1]`):

| key | what |
|---|---|
"""
    + "".join(f"| {k} | {w} |\n" for k, w in CONSTANTS_ROWS)
    + """
`study export` also reads the files earlier versions wrote (the study's descriptive names, all
constants in one `constants` table), and a flat object `{name: value}` of either kind of name
(the rest at the study's defaults).
"""
)


def _schema_rows() -> list[str]:
    from study.config.schema import SCHEMA

    keys = [k for k, f in SCHEMA.items() if f.kind == "path"] + list(COMPANION_KEYS)
    lines = ["| key | type | default | units | allowed | meaning |", "|---|---|---|---|---|---|"]
    for key in keys:
        f = SCHEMA[key]
        allowed = (
            ", ".join(f"`{c}`" for c in f.choices)
            if f.choices
            else (f"[{f.lo:g}, {f.hi:g}]" if f.lo is not None else "")
        )
        lines.append(
            f"| `{key}` | {f.kind} | `{json.dumps(f.default)}` | {f.units} | {allowed} | {f.doc} |"
        )
    return lines


def _describe(column: str) -> tuple[str, str]:
    """(the name shown, its meaning) of ``column``: itself, or the prefix that covers it."""
    if column in COLUMNS:
        return column, COLUMNS[column]
    for prefix in sorted((p for p in COLUMNS if p.endswith(".")), key=len, reverse=True):
        if column.startswith(prefix):
            return prefix, COLUMNS[prefix]
    raise KeyError(
        f"column {column!r} has no description: add it to COLUMNS in {Path(__file__).name}"
    )


def _table_lines(rel: str, what: str) -> list[str]:
    import pyarrow.parquet as pq

    schema = pq.read_schema(RESULTS / rel)
    shown = {}
    for name, kind in zip(schema.names, schema.types):
        label, meaning = _describe(name)
        kind = str(kind)
        kind = (
            "list" if kind.startswith("list") else "null (empty here)" if kind == "null" else kind
        )
        shown.setdefault(label, (kind, meaning))
    lines = [f"`{Path(rel).name}` ({what}):", "", "| column | type | meaning |", "|---|---|---|"]
    lines += [f"| `{k}` | {t} | {m} |" for k, (t, m) in shown.items()]
    return lines + [""]


def _summary_lines() -> list[str]:
    summary = json.loads((RESULTS / "tradeoff" / "summary.json").read_text())
    missing = sorted(set(summary) - set(SUMMARY))
    if missing:
        raise KeyError(f"summary.json entries without a description: {missing} (add to SUMMARY)")
    lines = ["| entry | meaning |", "|---|---|"]
    return lines + [f"| `{k}` | {SUMMARY[k]} |" for k in sorted(summary)]


def _textures_json() -> list[str]:
    import numpy as np

    from study.config.experiment import load_experiment
    from study.export.textures import texture_record

    exp = load_experiment(REPO / "experiments" / "default.toml")
    import inspect

    from shaders_port.inputs import fresnel_lut

    from shaders_port.inputs import ortho_tex_matrix
    from study.scene.shader_inputs import light_of
    from study.scene.topdown import texture_extent

    n = inspect.signature(fresnel_lut).parameters["n"].default  # the LUT's size
    size = int(exp.waves.normal_map_size)
    lightpos, lightcolor = light_of(exp)
    texels = int(exp.reference.texture_size)
    inputs = SimpleNamespace(
        fresnel_lut=np.zeros((n, 2)),
        normal_map=np.zeros((size, size, 3)),
        lightpos=lightpos,
        lightcolor=lightcolor,
        waves=np.asarray(exp.waves.offsets),
        world_y=np.zeros((texels, texels)),
        tex_matrix0=ortho_tex_matrix(*texture_extent(exp)),
    )
    text = json.dumps(texture_record(exp, inputs), indent=1)
    return ["```json", text, "```", ""]


def file_formats_page() -> str:
    """The Markdown of ``docs/file-formats.md``."""
    from study.config import files, image_maths

    lines = [HEADER]
    lines.append(
        INPUTS.format(
            image_ext=", ".join(e.lstrip(".").upper() for e in files.IMAGE_EXT),
            mesh_ext=", ".join(e.lstrip(".").upper() for e in files.MESH_EXT),
            max_texels=files.MAX_TEXELS,
            sun_threshold=image_maths.SUN_THRESHOLD,
            sun_contrast=image_maths.SUN_CONTRAST,
            input_table="\n".join(
                [
                    "| file | key | accepted | channels and values | orientation |",
                    "|---|---|---|---|---|",
                    *("| " + " | ".join(r) + " |" for r in INPUT_ROWS),
                ]
            ),
        )
    )
    lines += _schema_rows()
    lines += ["", OUTPUTS]
    lines += _summary_lines()
    lines.append(PANELS)
    for rel, what in TABLES:
        lines += _table_lines(rel, what)
    lines.append(TEXTURES)
    lines += _textures_json()
    lines.append(CONSTANTS)
    return "\n".join(lines)
