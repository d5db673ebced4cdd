"""The experiment keys of the scene itself: image, camera, pool, floor, water, waves, the waves'
animation, sky, sun and mesh (``SCENE_KEYS``, in the docs' order), and :class:`Field`, the
description of one key. ``study.config.schema`` joins them with the study's keys
(``schema_study``)."""

from __future__ import annotations

from dataclasses import dataclass

from .resolution import PRESETS


@dataclass(frozen=True)
class Field:
    """One experiment key: its kind, default, meaning, units and allowed range or choices."""

    kind: str  # float, int, str, bool, vec2, vec3, vec2x4, int_or_auto, list_str, list_float,
    # path, extent, views
    default: object
    doc: str
    units: str = ""
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None


FLOOR_SHAPES = ("flat", "slope", "steps", "terrain", "heightmap")

SCENE_KEYS: dict[str, Field] = {
    "name": Field("str", "unnamed", "Name of the experiment (used in reports)."),
    "description": Field("str", "", "Free text."),
    "resolution": Field(
        "vec2",
        [256, 256],
        "Image width and height, or a preset: `720p` (1280 x 720), `1080p` (1920 x 1080), "
        "`1440p` (2560 x 1440).",
        "pixels",
        8,
        4096,
        choices=tuple(PRESETS),
    ),
    "variant": Field(
        "str",
        "llvm_ad_rgb",
        "Mitsuba variant; `cuda_ad_rgb` needs an NVIDIA GPU.",
        choices=("llvm_ad_rgb", "cuda_ad_rgb"),
    ),
    "camera.position": Field("vec3", [0.0, 3.2, 6.5], "Camera position.", "world units"),
    "camera.target": Field("vec3", [0.0, -1.0, 0.0], "Point the camera looks at.", "world units"),
    "camera.fov_y": Field("float", 45.0, "Vertical field of view.", "degrees", 1.0, 170.0),
    "camera.views": Field(
        "views",
        [],
        "More views of the same scene, each [position, target] like camera.position and "
        "camera.target (the first view): `study calibrate` fits one constants block over all "
        "views, `study generalise` leaves each out in turn, `study tradeoff` judges its shaders "
        "on every view; other commands use the first. [] = the one view.",
        "world units",
    ),
    "pool.half_extent": Field(
        "vec2", [4.0, 4.0], "Half size of the water surface in x and z.", "world units", 0.1, 1000.0
    ),
    "pool.wall_height": Field(
        "float",
        0.3,
        "Height of the pool walls above the water plane "
        "(geometry the reflection shader can reflect).",
        "world units",
        0.01,
        100.0,
    ),
    "pool.wall_width": Field(
        "float", 0.6, "Thickness of the walls around the pool.", "world units", 0.01, 100.0
    ),
    "pool.wall_albedo": Field(
        "vec3", [0.7, 0.68, 0.62], "Diffuse albedo of the walls.", "linear RGB", 0.0, 1.0
    ),
    "floor.shape": Field(
        "str", "slope", "Height function of the pool floor.", choices=FLOOR_SHAPES
    ),
    "floor.depth": Field(
        "float", 1.5, "Mean depth of the floor below the water plane.", "world units", 0.01, 100.0
    ),
    "floor.relief": Field(
        "float",
        0.8,
        "Height variation of the floor shape (slope: total rise "
        "across x; steps: total rise over the steps; terrain: peak-to-peak scale).",
        "world units",
        0.0,
        100.0,
    ),
    "floor.steps": Field("int", 4, "Number of steps for shape `steps`.", "", 1, 64),
    "floor.seed": Field("int", 0, "Random seed of shape `terrain`.", "", 0, 2**31 - 1),
    "floor.ledge": Field(
        "vec4",
        [0.0, 0.0, 0.0, 0.0],
        "Under-water slab (a ledge or bridge "
        "across the pool in z, its ends 0.02 from the walls) as [x_min, x_max, top y, "
        "thickness]; thickness 0 = none. The floor under it is hidden from the "
        "top-down textures (depth complexity 2).",
        "world units",
        -1000.0,
        1000.0,
    ),
    "floor.tile_size": Field(
        "float", 0.5, "Edge length of the floor tiles.", "world units", 0.01, 100.0
    ),
    "floor.tile_albedo": Field(
        "vec3", [0.75, 0.72, 0.62], "Albedo of the light tiles.", "linear RGB", 0.0, 1.0
    ),
    "floor.tile_albedo2": Field(
        "vec3", [0.18, 0.32, 0.45], "Albedo of the dark tiles.", "linear RGB", 0.0, 1.0
    ),
    "floor.heightmap": Field(
        "path",
        "",
        "Heightmap file for shape `heightmap`: a single-channel EXR or "
        "16-bit PNG over `floor.extent` (columns along x, row 0 at the low z); the "
        "floor is at y = -floor.depth + floor.height_scale * texel.",
        "file",
    ),
    "floor.height_scale": Field(
        "float",
        1.0,
        "World height of one heightmap unit (a 16-bit PNG's texels are 0..1).",
        "world units",
        0.0,
        100.0,
    ),
    "floor.albedo_image": Field(
        "path",
        "",
        "Floor albedo image over `floor.extent` instead of the "
        "tiles: sRGB PNG/JPEG or linear EXR, values in [0, 1].",
        "file",
    ),
    "floor.extent": Field(
        "extent",
        "pool",
        "World rectangle [x0, z0, x1, z1] the heightmap and "
        'albedo image cover (`"pool"`: the water\'s rectangle); must cover the water.',
        "world units",
    ),
    "water.ior": Field("float", 1.333, "Index of refraction of the water.", "", 1.0, 3.0),
    "water.sigma_t": Field(
        "vec3",
        [0.25, 0.06, 0.04],
        "Extinction coefficient of the water.",
        "1 / world unit, linear RGB",
        0.0,
        1000.0,
    ),
    "water.albedo": Field(
        "vec3",
        [0.0, 0.0, 0.0],
        "Single-scattering albedo of the water (0 = purely absorbing).",
        "linear RGB",
        0.0,
        1.0,
    ),
    "waves.amplitude": Field(
        "float",
        0.05,
        "Peak height scale of the wave surface (0 = calm, flat water).",
        "world units",
        0.0,
        10.0,
    ),
    "waves.normal_tile": Field(
        "float",
        2.0,
        "Size of one repeat of the normal map on the water.",
        "world units",
        0.01,
        1000.0,
    ),
    "waves.components": Field(
        "int",
        5,
        "Sine components of the tiling height field (distinct integer "
        "wave vectors from [-4, 4]^2; above 40, from the smallest grid [-K, K]^2 holding them).",
        "",
        1,
        64,
    ),
    "waves.seed": Field("int", 1, "Random seed of the wave components.", "", 0, 2**31 - 1),
    "waves.offsets": Field(
        "vec2x4",
        [[0.0, 0.0], [0.31, 0.17], [0.53, 0.71], [0.13, 0.47]],
        "Texture offsets wave1..wave4 of the four normal-map layers.",
        "texture units",
    ),
    "waves.slope_scale": Field(
        "float",
        1.0,
        "Slope scale the normal map was authored with "
        "relative to the true waves (the ideal BumptexMult).",
        "",
        0.01,
        100.0,
    ),
    "waves.normal_map_size": Field("int", 256, "Normal-map resolution.", "texels", 8, 4096),
    "waves.source": Field(
        "str",
        "study",
        "Where the reference's waves come from: `study`, the height field above (the study's "
        "shaders sample its normal map); `shader`, the surface whose normals the calibrated "
        "shader (fit.shader) computes at its start values, read from the variable its "
        "declaration names (`// @study normal NAME [world|tangent]`) and integrated (least "
        "squares) into a height field.",
        choices=("study", "shader"),
    ),
    "waves.height_scale": Field(
        "float",
        1.0,
        "With waves.source = shader: factor on the integrated surface's height (and so its "
        "slopes), a known truth for the shader's normal-strength constant to recover.",
        "",
        0.05,
        20.0,
    ),
    "waves.shader_grid": Field(
        "int",
        512,
        "With waves.source = shader: samples along the longer side of the water at which the "
        "shader's normals are read and integrated.",
        "samples",
        16,
        4096,
    ),
    "waves.time": Field(
        "float",
        0.0,
        "The clock a user's shader reads as `time` on a still frame and frame 0 (frame k of an "
        "animated experiment: waves.time + k * animation.time_step); with waves.source = "
        "shader, the reference's waves are read at it too.",
        "seconds",
        0.0,
        1e6,
    ),
    "animation.frames": Field(
        "int",
        1,
        "Frames of an animated experiment (1 = a still frame). Frame k moves the four "
        "normal-map layers to waves.offsets + k * time_step * velocities, on both sides: the "
        "shader's wave1..wave4 and the reference's displaced surface.",
        "",
        1,
        64,
    ),
    "animation.time_step": Field(
        "float", 1.0 / 30.0, "Time between two frames.", "seconds", 1e-4, 10.0
    ),
    "animation.velocities": Field(
        "vec2x4",
        [[0.3, 0.0], [-0.21, 0.21], [0.0, 0.3], [0.21, 0.21]],
        "Velocity of each normal-map layer wave1..wave4 (the application adds velocity * time "
        "to the layer's offset every frame).",
        "texture units per second",
    ),
    "sky.zenith": Field(
        "vec3", [0.25, 0.45, 0.9], "Sky radiance at the zenith.", "linear RGB", 0.0, 1e4
    ),
    "sky.horizon": Field(
        "vec3", [0.8, 0.85, 0.95], "Sky radiance at the horizon.", "linear RGB", 0.0, 1e4
    ),
    "sky.ground": Field(
        "vec3", [0.3, 0.28, 0.25], "Radiance below the horizon.", "linear RGB", 0.0, 1e4
    ),
    "sky.envmap": Field(
        "path",
        "",
        "HDR lat-long sky (RGB EXR, width = 2 x height, Mitsuba's envmap "
        "convention) instead of the gradient sky.",
        "file",
    ),
    "sky.rotation": Field(
        "float",
        0.0,
        "Turn of `sky.envmap` about +y (from +x towards +z).",
        "degrees",
        -360.0,
        360.0,
    ),
    "sky.scale": Field("float", 1.0, "Radiance scale of `sky.envmap`.", "", 0.0, 1e6),
    "sun.source": Field(
        "str",
        "explicit",
        "Where the sun comes from: `explicit` (the `sun.*` keys; "
        "added to `sky.envmap` if given) or `envmap` (the map's brightest region: "
        "direction, solid angle, radiance).",
        choices=("explicit", "envmap"),
    ),
    "sun.elevation": Field("float", 50.0, "Sun elevation above the horizon.", "degrees", 0.0, 90.0),
    "sun.azimuth": Field(
        "float", 200.0, "Sun azimuth, from +x towards +z.", "degrees", -360.0, 360.0
    ),
    "sun.radius": Field(
        "float",
        5.0,
        "Angular radius of the sun disc (at least 0.5: the sky map has 0.35 degree texels).",
        "degrees",
        0.5,
        20.0,
    ),
    "sun.radiance": Field(
        "vec3", [8.0, 7.5, 6.0], "Radiance of the sun disc (0 = no sun).", "linear RGB", 0.0, 1e6
    ),
    "mesh.file": Field(
        "path",
        "",
        "Mesh above the water (OBJ or PLY, loaded by Mitsuba): walls, shore, "
        "rocks; in the reference and in the reflection textures.",
        "file",
    ),
    "mesh.position": Field(
        "vec3", [0.0, 0.0, 0.0], "Translation of the mesh (applied last).", "world units", -1e4, 1e4
    ),
    "mesh.scale": Field("float", 1.0, "Uniform scale of the mesh (applied first).", "", 1e-3, 1e3),
    "mesh.rotation": Field(
        "float", 0.0, "Turn of the mesh about +y (from +x towards +z).", "degrees", -360.0, 360.0
    ),
    "mesh.albedo": Field(
        "vec3", [0.5, 0.5, 0.5], "Diffuse albedo of the mesh.", "linear RGB", 0.0, 1.0
    ),
    "mesh.texture": Field(
        "path",
        "",
        "Albedo image of the mesh (needs texture coordinates; sRGB PNG/JPEG "
        "or linear EXR) instead of `mesh.albedo`.",
        "file",
    ),
}
