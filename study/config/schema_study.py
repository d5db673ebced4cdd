"""The experiment keys of the study run on a scene: the reference render (``reference.*``), the
fit (``fit.*``), the tradeoff sweep (``tradeoff.*``) and the start constants (``constants.*``,
one per ``CONSTANT_SPECS`` entry): ``STUDY_KEYS``, in the docs' order."""

from __future__ import annotations

from shaders_port import CONSTANT_SPECS
from shaders_port.variants import SHIPPED

from .resolution import AUTO, PRESETS
from .schema_scene import Field

SHADERS = tuple(SHIPPED)
SOLVERS = ("levenberg_marquardt", "gauss_newton", "dogleg", "bfgs", "nelder_mead", "adam")
FIT_PARAMETERS = (
    "attenuation_distance",
    "bumptex_mult",
    "steps_grazing",
    "steps_steep",
    "water_color",
    "reflect_color",
    "specular_strength",
    "specular_exponent",
    # read by shader variants only (a variant fits them in place of the seed's
    # constants it replaces, see shaders_port.variants.Variant.replaces)
    "absorption_r",
    "absorption_g",
    "absorption_b",
    "specular_roughness",
    "sun_disc_radius",
    "sun_disc_softness",
    "sun_disc_radiance",
    # the baseline shader's (seeds 001-004)
    "refraction_index",
    "refraction_strength",
    "chromatic_dispersion",
    "reflect_distortion",
)

STUDY_KEYS: dict[str, Field] = {
    "reference.spp": Field(
        "int_or_auto",
        128,
        "Samples per pixel, or `auto` to reach "
        "`reference.target_noise`. Zero-mean noise in the reference moves the fitted "
        "constants at random, without bias: on the default scene, from 1024 samples "
        "per fit pixel down to 256 (here 64 spp at 256x256 fitted at 128x128) the mean "
        "fitted constants of three seeds stay within 1.3 % of those at 4096 (the "
        "specular pair, set by a few glints; the others within 0.5 %; `study "
        "stability --phases noise`, README). The FLIP the report prints is against "
        "this reference, so its noise raises it: raise the spp for a final figure.",
        "",
        1,
        65536,
    ),
    "reference.target_noise": Field(
        "float",
        0.01,
        'Target RMS standard error on water pixels for `spp = "auto"`.',
        "linear RGB",
        1e-5,
        1.0,
    ),
    "reference.max_spp": Field("int", 1024, "Upper bound of the automatic spp.", "", 4, 65536),
    "reference.sampler": Field(
        "str",
        "multijitter",
        "Sampler of the reference render: `multijitter` "
        "(Kensler's correlated multi-jittered strata per pass), `independent`, or "
        "`stratified` (kept to reproduce earlier references: its dimensions are "
        "correlated and it renders deep chromatic water about 1 % too bright). Each "
        "pass's spp is rounded up to the sampler's grid (128 spp: 4 x 35). At equal "
        "samples the jittered passes have 2.8x less variance on the water and 5.5x "
        "less on the sun's glitter than independent ones (measured on the default "
        "scene, docs/fast-references.md), which is where the reference's noise moves "
        "the fitted specular pair.",
        choices=("multijitter", "independent", "stratified"),
    ),
    "reference.seed": Field(
        "int",
        0,
        "Base sampler seed (the per-pass seeds derived from it stay "
        "within Mitsuba's 32-bit seeds).",
        "",
        0,
        2**28 - 1,
    ),
    "reference.max_depth": Field("int", 12, "Maximum path length.", "", 2, 256),
    "reference.texture_size": Field(
        "int", 256, "Resolution of the top-down shader textures.", "texels", 16, 4096
    ),
    "reference.texture_spp": Field(
        "int",
        32,
        "Samples per texel of the top-down texture: of the "
        'lighting render (`texture_method = "lighting"`, denoised by default: '
        "32 is the measured sweet spot, see the README) or of the colour render "
        '(`"colour"`: use 512 or more, its noise biases the fit).',
        "",
        1,
        65536,
    ),
    "reference.texture_method": Field(
        "str",
        "lighting",
        "How the top-down refraction texture "
        "is rendered: `lighting` (the floor's lighting path traced at "
        "`reference.lighting_size` texels over the pool, times its known "
        "albedo at `reference.texture_size`; walls from a colour render "
        "at `reference.wall_spp`) or `colour` (the colour path traced "
        "at `reference.texture_size`).",
        choices=("lighting", "colour"),
    ),
    "reference.lighting_size": Field(
        "int",
        128,
        "Texels per side of the lighting render over the "
        'pool (`texture_method = "lighting"`; at most `reference.texture_size`).',
        "texels",
        8,
        4096,
    ),
    "reference.lighting_denoise": Field(
        "str",
        "oidn",
        "Denoise the lighting render (`texture_method = "
        '"lighting"`): `oidn` (Intel Open Image Denoise, guided by the floor '
        "albedo, the texture's mean over the pool then matched per colour channel "
        "to the raw mean of the same samples), `oidn_unmatched` (denoised, its "
        "own brightness kept) or `none` (raw path tracing: raise "
        "`reference.texture_spp` to 256 or more). Measured effect on the fitted "
        "constants: docs/fast-references.md.",
        choices=("none", "oidn", "oidn_unmatched"),
    ),
    "reference.lighting_direct": Field(
        "str",
        "traced",
        "The floor's direct light through the waves "
        '(`texture_method = "lighting"` under water): `traced` (ray traced '
        "without the path tracer's noise: the sun from the sun, its caustics "
        "sharp; the sky gathered at the floor; only the light that bounced path "
        "traced and denoised; scattering water, `water.albedo` > 0, keeps "
        "`path`) or `path` (all of it path traced and denoised, the caustics "
        "smoothed). docs/fast-references.md.",
        choices=("traced", "path"),
    ),
    "reference.sun_bounces": Field(
        "str",
        "path",
        "The sun's light that bounced under water (off the "
        "walls, the floor, the water's underside) with `lighting_direct = "
        '"traced"`: `path` (path traced and denoised with the sky\'s: fireflies '
        "that the denoiser darkens, 2-4 % in red at the feet of sunlit walls) or "
        "`photons` (light traced from the sun with its direct light, the path tracer "
        "then rendering the sky's bounced light alone: those bands within 1 %, "
        "+2-3 s; the fitted constants move by less than 0.2 SE). README, Fast "
        "references.",
        choices=("path", "photons"),
    ),
    "reference.bounce_spp": Field(
        "int",
        16,
        "Samples per texel of the path-traced lighting with "
        '`lighting_direct = "traced"` (only the light that bounced is kept from '
        "it; `texture_spp` otherwise).",
        "",
        1,
        65536,
    ),
    "reference.sun_photons": Field(
        "int",
        16,
        "Photons per texture texel for the traced sunlight "
        '(`lighting_direct = "traced"`; about 2/3 of them land in the pool).',
        "",
        1,
        65536,
    ),
    "reference.sky_directions": Field(
        "int",
        36,
        "Directions per texture texel, in each of two "
        "independent halves, for the traced skylight (`lighting_direct = "
        '"traced"`; a square number).',
        "",
        1,
        4096,
    ),
    "reference.wall_spp": Field(
        "int",
        16,
        "Samples per pixel of the dry colour render used "
        "outside the pool and for the floor albedo (`texture_method = "
        '"lighting"`; multi-jittered, rounded up to its grid).',
        "",
        1,
        65536,
    ),
    "reference.wall_denoise": Field(
        "str",
        "oidn",
        "Denoise the dry render that the refraction texture "
        'takes outside the pool (`texture_method = "lighting"`; `reference.wall_spp`): '
        "`oidn` (Open Image Denoise guided by its albedo, its mean outside the pool "
        "matched to the raw mean there) or `none` (raw: 5-8 % noise per texel at 16 "
        "spp, which biases the fit). docs/fast-references.md.",
        choices=("oidn", "none"),
    ),
    "reference.refraction_lighting": Field(
        "str",
        "underwater",
        "How the top-down refraction "
        "texture is lit: `underwater` (the floor as lit through the "
        "water) or `dry` (no water, as the original shader's application does).",
        choices=("underwater", "dry"),
    ),
    "reference.fresnel_transmission": Field(
        "str",
        "energy",
        "Transmission channel of the shader's "
        "Fresnel LUT: `energy` (1 - R, as usual) or `radiance` "
        "((1 - R) / ior^2: radiance leaving the water is compressed "
        "into Snell's window, which the shader otherwise omits).",
        choices=("energy", "radiance"),
    ),
    "reference.water_mesh": Field(
        "int",
        384,
        "Grid resolution of the displaced water surface mesh.",
        "vertices per side",
        8,
        4096,
    ),
    "fit.shader": Field(
        "str",
        "water_refraction",
        "Shader to fit: a shipped variant or any configuration of the shader space, named as "
        "`docs/shader-space.md` says (e.g. `water_reflection_beer_walls`); or the path of your "
        "own GLSL fragment shader (`.frag`, relative to the experiment file), calibrated "
        "through SPIR-V (`docs/user-shader.md`).",
    ),
    "fit.declare": Field(
        "list_str",
        None,
        "Declaration of your own `fit.shader` besides its `// @study` pragmas (the same "
        "lines without `// @study`, so an engine's file needs no edit), one line each: "
        "`constant NAME LOW HIGH` (a constant to fit and its range, declared in `fit.shader` "
        "or `fit.vertex`; `constant NAME LOW HIGH START` for a uniform without initializer), "
        "`bind NAME INPUT` (the shader's sampler or uniform NAME is the study's INPUT; a "
        "name only `fit.vertex` reads binds there, to a vertex meaning such as `model`, "
        "`view`, `projection`, `position` or `uv`, or to an input), "
        "`value NAME V[,V...]` (a uniform the engine sets, in either stage; a matrix's "
        "numbers column after column), `normal NAME "
        "[world|tangent]`, `up y|z` or `normal_map FILE` (relative to the experiment file, "
        "also when the line is given with `--set`).",
    ),
    "fit.include_paths": Field(
        "list_str",
        None,
        "Folders (relative to the experiment file) searched, after the including file's own "
        'folder, for the `#include "x.glsl"` files of your own `fit.shader`.',
    ),
    "fit.defines": Field(
        "list_str",
        None,
        "Preprocessor names your own `fit.shader` is compiled with, as an engine sets them: "
        '`"NAME"` or `"NAME=VALUE"` each (e.g. `["WAVE_LAYERS=2", "USE_FOG"]`); `"!NAME"` '
        "leaves the function NAME out of the stage (the other stage's entry point of a file "
        'compiled for both, as Urho3D\'s loader does); `"#version 150"` is the version line '
        "your engine puts before a file that has none.",
    ),
    "fit.vertex_defines": Field(
        "list_str",
        None,
        "Preprocessor names your own `fit.vertex` is compiled with, where they differ from the "
        "fragment shader's (an engine that compiles one file for both stages, e.g. Urho3D's "
        '`["COMPILEVS", "VS=main", "!PS"]` against `fit.defines = ["COMPILEPS", "PS=main", '
        '"!VS"]`); unset: '
        "`fit.defines`.",
    ),
    "fit.vertex": Field(
        "path",
        "",
        "Your own vertex shader for your `fit.shader` (`.vert`, relative to the experiment file), "
        "in place of the study's `water.vert`: run on every vertex of a grid over the water "
        'quad, its triangles rasterised and its outputs interpolated as OpenGL does; `"auto"`: '
        "the file beside `fit.shader` with its name and `.vert` (`water.frag` -> `water.vert`). "
        "Its `// @study constant` pragmas are fitted with the fragment shader's. "
        "Unset: the study's `water.vert` (`docs/user-shader.md`).",
    ),
    "fit.vertex_grid": Field(
        "vec2",
        [64, 64],
        "Cells of the grid `fit.vertex` runs on, along x and z (two triangles each).",
        "cells",
        1,
        1024,
    ),
    "fit.write_back": Field(
        "str",
        "copy",
        "Where the fitted constants of your own `fit.shader` go: `copy` (into "
        "`shaders/<file>` of the output folder) or `file` (also into your file itself, the "
        "initializers replaced and every other byte kept, once the GL check has passed).",
        choices=("copy", "file"),
    ),
    "fit.parameters": Field(
        "list_str",
        None,
        "Constants to fit (frozen automatically when the scene does not identify them). Unset: "
        "every continuous constant `fit.shader` reads (not its step schedule); a listed constant "
        "it does not read is dropped with a note.",
        choices=FIT_PARAMETERS,
    ),
    "fit.solver": Field("str", "levenberg_marquardt", "Solver.", choices=SOLVERS),
    "fit.max_steps": Field("int", 100, "Solver iteration cap.", "", 1, 100000),
    "fit.loss": Field(
        "str",
        "flip",
        "The error the fit minimises: `flip` (the mean LDR-FLIP map the report gives, through a "
        "differentiable FLIP, fitted from the squared error's solution: the lowest FLIP on "
        "each of the six shipped experiments measured), `linear` (squared error in linear "
        "RGB: a third of the fit's time), `log` (squared error of log(RGB + 0.02)) or "
        "`transport` (in each 8 x 8 tile of the fit image, the sorted values against the "
        "reference's sorted values: a glint moved within its tile costs a quarter). All but "
        '`linear` need a least-squares solver and `fit.input_noise = "ignore"`: set '
        '`fit.loss = "linear"` with `fit.solver = "adam"` or `fit.input_noise = "decorrelate"`. '
        'docs/user-shader.md "What the fit minimises".',
        choices=("linear", "log", "flip", "transport"),
    ),
    "fit.normal_equations": Field(
        "str",
        "solver",
        "Where the least-squares system is formed: `solver` (the solver receives every residual "
        "and the whole Jacobian, 3 x water pixels rows) or `device` (Dr.Jit forms J^T J, J^T r "
        "and the loss where the shader runs and the solver receives k + 1 rows with the same "
        "normal equations: nothing of the image is read back during the fit, which is what a "
        "fit at 1080p or on a GPU needs). Same steps up to rounding; needs `fit.loss = "
        '"linear"`. docs/where-it-runs.md.',
        choices=("solver", "device"),
    ),
    "fit.resolution": Field(
        "vec2",
        [128, 128],
        "Image size the fit runs at (the reference is "
        "rendered at `resolution`, then box-downsampled when smaller), a preset (as "
        "`resolution`), or `auto`: chosen from the device and the scene, `resolution` divided "
        "by the smallest factor common to both sides that leaves at most 128 x 128 pixels on the "
        "CPU (`llvm_ad_rgb`) or 1920 x 1080 on a GPU (`cuda_ad_rgb`: full resolution up to "
        "1080p); the device is the run's (`--backend`, else `variant`). docs/where-it-runs.md.",
        "pixels",
        8,
        4096,
        choices=(AUTO, *PRESETS),
    ),
    "fit.target_resolution": Field(
        "vec2",
        None,
        "The resolution the shader runs at in the game, or a preset (as `resolution`). Each fit "
        "pixel is shaded at that resolution's pixel footprint: its target rows over "
        "`fit.resolution`'s rows, rounded, samples per side (at most 4), averaged. Unset: "
        '`resolution`, the reference\'s. docs/user-shader.md "The pixels it sees".',
        "pixels",
        8,
        8192,
        choices=tuple(PRESETS),
    ),
    "fit.input_noise": Field(
        "str",
        "ignore",
        "What the fit does about Monte Carlo noise in the "
        "refraction texture, which biases least squares (errors in the inputs): "
        "`ignore` (least squares on the texture as given) or `decorrelate` (then "
        "damped Newton steps on the decorrelated loss over the texture's two "
        "independent raw halves, which cancels their noise in expectation; the "
        "least-squares start, and so the basin, comes from the texture as given, "
        "denoised or not; needs "
        '`reference.texture_method = "lighting"`).',
        choices=("ignore", "decorrelate"),
    ),
    "tradeoff.search": Field(
        "str",
        "adaptive",
        "How `study tradeoff` searches the shader space: `adaptive` (a cheap screen of the "
        "configurations and schedules, then the survivors in full) or `exhaustive` (every "
        "configuration and schedule in full, for checking).",
        choices=("adaptive", "exhaustive"),
    ),
    "tradeoff.lod": Field(
        "bool",
        True,
        "Choose a level-of-detail policy (a configuration per band of the water, by distance "
        "or footprint) from the full points' per-pixel maps and draw it as one shader "
        "(`policy/`); false leaves it out (and, in the adaptive search, the bands it proposes "
        "to the full rung).",
    ),
    "tradeoff.variants": Field(
        "list_str",
        None,
        "The shaders `study tradeoff` compares (names of the shader space); unset: the whole "
        "space, with the axes of `tradeoff.fix` pinned.",
    ),
    "tradeoff.fix": Field(
        "list_str",
        [],
        'Axes of the shader space held at one choice, as `"axis=choice"` (e.g. '
        '`"textures=float"`); see `docs/shader-space.md`.',
    ),
    "tradeoff.max_shaders": Field(
        "int",
        64,
        "Configurations the adaptive search screens at most (its walk stops there; the default "
        "scene's best shader is three choices from the original, which 40 did not reach).",
        "",
        1,
        10000,
    ),
    "tradeoff.max_scheduled": Field(
        "int",
        6,
        "Shader configurations whose step schedules the adaptive search screens at most: the "
        "walk's survivors closest to the front.",
        "",
        1,
        10000,
    ),
    "tradeoff.max_full": Field(
        "int",
        16,
        "Screen points the adaptive search measures in full at most: the surviving points "
        "closest to the screen's front.",
        "",
        1,
        10000,
    ),
    "tradeoff.screen_factor": Field(
        "int",
        1,
        "The adaptive search screens at `fit.resolution` divided by this factor (a larger "
        "factor is cheaper but misjudges what turns with the pixel's footprint: the sun's "
        "disc loses to Phong at 64x64 and wins at 128x128).",
        "",
        1,
        64,
    ),
    "tradeoff.noise_z": Field(
        "float",
        2.0,
        "A point is dropped by the adaptive search when another costs no more and its FLIP "
        "is lower by more than this many standard errors of the paired difference.",
        "",
        0.0,
        100.0,
    ),
    "tradeoff.steps_grazing": Field(
        "list_float",
        [5.0, 20.0],
        "`STEPS_GRAZING` values of the schedule grid (full grid with the next two keys).",
        "steps",
        0.5,
        1000.0,
    ),
    "tradeoff.steps_steep": Field(
        "list_float", [1.5, 6.0], "`STEPS_STEEP` values of the grid.", "steps", 0.5, 1000.0
    ),
    "tradeoff.loop_cap": Field(
        "list_float", [20, 40], "`LOOP_CAP` values of the grid (integers).", "iterations", 1, 10000
    ),
    "tradeoff.scales": Field(
        "list_float",
        [0.25, 0.5, 1.0, 2.0, 4.0],
        "Schedules added to the grid: the "
        "original shader's (10, 3, 40) (and for `water_reflection` its reflection schedule) "
        "times each factor, so every halving of the step count is measured.",
        "",
        0.01,
        100.0,
    ),
    "tradeoff.converged_scale": Field(
        "float",
        16.0,
        "Factor on the original shader's schedule of the converged "
        "raymarch that measures each variant's error floor.",
        "",
        1.0,
        1000.0,
    ),
    "tradeoff.tolerance": Field(
        "float",
        0.02,
        "Recommend the cheapest configuration whose FLIP is within this fraction of the best FLIP.",
        "",
        0.0,
        10.0,
    ),
    "tradeoff.gl_repeats": Field(
        "int", 5, "Frames timed per GL measurement (median reported).", "", 3, 1000
    ),
}
# start values the scene's sun gives unless the experiment sets them (study.config.experiment,
# SUN_DISC_STARTS)
_FROM_THE_SUN = {
    "sun_disc_radius": " Unset: the sun's angular radius (`sun.radius`, or the sky map's sun).",
    "sun_disc_radiance": " Unset: the largest channel of the sun's radiance (`lightcolor` is "
    "the radiance divided by it).",
}
for _name, (_glsl, _kind, _default, (_lo, _hi)) in CONSTANT_SPECS.items():
    if _kind.endswith("vec4"):
        STUDY_KEYS[f"constants.{_name}"] = Field(
            "vec4", list(_default), f"Start value of `{_glsl}`.", "linear RGBA", _lo, _hi
        )
    else:
        STUDY_KEYS[f"constants.{_name}"] = Field(
            "int" if _kind.endswith("int") else "float",
            _default,
            f"Start value of `{_glsl}`." + _FROM_THE_SUN.get(_name, ""),
            "degrees" if _name == "sun_disc_radius" else "",
            _lo,
            _hi,
        )
