"""``docs/engine-inputs.md``, written by ``scripts/build_docs.py``: every input a user's fragment
shader can read, from ``shaders_port.spirv.translated.STUDY_INPUTS`` (the study's own and those
of ``shaders_port.spirv.engine_inputs``) and the engines' names of
``engine_inputs.ENGINE_ALIASES``. An input without its conventions here fails the build
(describe it in :data:`CONVENTIONS`)."""

from __future__ import annotations

# input -> (orientation and units, colour space or encoding, filter and wrap)
CONVENTIONS = {
    "varyingVecWorldPosition": ("point on the water plane, world units (y = 0)", "-", "-"),
    "varyingVecEye": ("water point -> camera, world units, not normalised", "-", "-"),
    "varyingVecLight": ("water point -> light, world units, not normalised", "-", "-"),
    "vTexCoord0": ("(x, z) / normal_tile + wave1, 0, 1", "-", "-"),
    "vTexCoord1": ("(x, z) / normal_tile + wave2, 0, 1", "-", "-"),
    "vTexCoord2": ("(x, z) / normal_tile + wave3, 0, 1", "-", "-"),
    "vTexCoord3": ("(x, z) / normal_tile + wave4, 0, 1", "-", "-"),
    "gl_FragCoord": ("window pixels, origin bottom left; z window depth; w = 1 / clip w", "-",
                     "-"),
    "refractionTexture": ("top-down view; (s, t) = uTextureMatrix0 * world", "linear RGB",
                          "bilinear, clamp"),
    "worldYComponent": ("top-down view; (s, t) = uTextureMatrix0 * world", "world y (.r), world "
                        "units", "nearest, clamp"),
    "normalMap": ("(s, t) = vTexCoord; s along +x, t along +z", "world normal 0.5 n + 0.5 (r = x, "
                  "g = y up, b = z)", "bilinear, repeat"),
    "reflectionTexture": ("GL cube map; the texel of d holds the sky in d * (1, -1, 1) (below)",
                          "linear RGB", "bilinear, clamp, per face"),
    "fresnelLookup": ("s = cos(theta) in [0, 1] (N x 1)", ".r transmission, .g reflection",
                      "nearest, clamp"),
    "worldYComponentReflection": ("view from below; (s, t) = uTextureMatrix1 * world",
                                  "world y (.r), -1e3 where empty", "nearest, clamp"),
    "reflectionBottom": ("view from below; (s, t) = uTextureMatrix1 * world", "linear RGB",
                         "bilinear, clamp"),
    "sceneColor": ("screen space: (s, t) = gl_FragCoord.xy / screenSize", "linear RGB",
                   "bilinear, clamp"),
    "sceneDepth": ("screen space, as sceneColor", "window depth in [0, 1], GL's non-linear; 1 "
                   "where nothing was hit", "nearest, clamp"),
    "reflection_sampler": ("mirrored camera's window: (s, t) = textureProj with "
                           "reflection_texture_matrix", "linear RGB", "bilinear, clamp"),
    "slopeMoments": ("(s, t) = vTexCoord, as normalMap", "(sx, sz, sx^2, sz^2): the normal map's "
                     "slopes -n.xz / max(n.y, 0.05) and their squares, RGBA32F",
                     "trilinear (mipmapped, box levels), repeat"),
    "heightMap": ("(s, t) = vTexCoord, as normalMap", "the waves' height over the water plane in "
                  "tile lengths (.r), integrated from the normal map's slopes", "bilinear, repeat"),
    "uTextureMatrix0": ("world -> (s, t) of refractionTexture, worldYComponent", "-", "-"),
    "uTextureMatrix1": ("world -> (s, t) of the reflection textures", "-", "-"),
    "uModelViewProjectionMatrix": ("world -> clip, OpenGL (NDC z in [-1, 1])", "-", "-"),
    "uModelViewProjectionMatrixInverse": ("clip -> world", "-", "-"),
    "uNormalMatrix": ("world -> eye rotation (eye looks down -z)", "-", "-"),
    "o2v_projection_reflection": ("world -> clip of the mirrored camera", "-", "-"),
    "screenSize": ("pixels (width, height)", "-", "-"),
    "viewpos": ("world units", "-", "-"),
    "lightpos": ("world units (the sun's direction, 1000 units away)", "-", "-"),
    "lightcolor": ("-", "linear RGB, the sun's radiance normalised", "-"),
    "reflection_texture_matrix": ("world -> (s, t, r, q); textureProj reads reflection_sampler",
                                  "-", "-"),
    "refraction_sampler": ("screen space, as sceneColor", "linear RGB", "bilinear, clamp"),
    "depth_sampler": ("screen space, as sceneColor", "window depth in [0, 1], GL's non-linear",
                      "nearest, clamp"),
    "camera_near": ("world units (0.05 for the study's cameras)", "-", "-"),
    "camera_far": ("world units (100 for the study's cameras)", "-", "-"),
    "camera_near_far": ("(camera_near, camera_far), world units", "-", "-"),
    "dudv_map": ("(s, t) = vTexCoord, as normalMap", "RG = 0.5 + 0.5 (-dh/dx, -dh/dz), B = 0",
                 "bilinear, repeat"),
    "time": ("seconds", "-", "-"),
    "sun_direction": ("unit vector towards the light, world space", "-", "-"),
    "sun_color": ("-", "linear RGB (lightcolor)", "-"),
    "camera_position": ("world units (viewpos)", "-", "-"),
    "inverse_view_projection": ("clip -> world", "-", "-"),
    "sky_cube": ("GL cube map; the texel of d holds the sky in d", "linear RGB",
                 "bilinear, clamp, per face"),
    "user_normal_map": ("the shader's own coordinates; the file's top row at t = 1",
                        "the file's RGB / 255, no sRGB decoding", "trilinear (mipmapped), "
                        "repeat"),
    "waves_normal_map": ("the shader's own coordinates (the waves' are normalMap's); tangent "
                         "space, x along u = world +x, y along v = world +z, z up",
                         "RGB = 0.5 + 0.5 (n_x, n_z, n_y)", "trilinear (mipmapped), repeat"),
}  # fmt: skip

HEADER = """# Engine inputs: every input your shader can read

This page is generated by `scripts/build_docs.py` from the code
(`shaders_port.spirv.translated.STUDY_INPUTS`, `shaders_port.spirv.engine_inputs`), so it lists
exactly what a fragment shader of yours ([Calibrating your own shader](user-shader.md)) can
read. A name of the table binds itself; an engine's name of the last column binds itself too;
any other name of your shader binds with the line of the *bind* column (in the shader, or as
`fit.declare = ["bind myName INPUT"]`), `myName` your sampler's or uniform's name.

Conventions of every input: world units, right-handed, `+y` up, the water plane `y = 0`
(unless your shader declares `// @study up z`, below); matrices act on column vectors and are
uploaded column-major as GL does (`uniform mat4`), clip space is OpenGL's (NDC `z` in
[-1, 1]); colours are linear RGB; a 2D texture's row 0 is `t = 0.5 / H` (GL upload order); the
study's textures have no mip chain (the user's normal map has one).

"""

DETAILS = """
## The planar reflection and its projective texture matrix

`reflection_sampler` is the scene above the water seen by the camera mirrored in the plane
`y = 0`. Its view-projection `o2v_projection_reflection` is `F * viewProjection * F`, `F =
diag(1, -1, 1, 1)`: the camera's own view-projection applied to the mirrored point, its image
flipped vertically (seed 004's mirrored camera). `reflection_texture_matrix` is
`B * o2v_projection_reflection`, `B` the bias matrix (`0.5 x + 0.5` on x, y, z). Three.js's
`Reflector` builds its `textureMatrix` the same way (bias * projection * view of its mirrored
camera), but its mirrored camera keeps the reflected up vector, so its view-projection is
`diag(-1, -1, 1, 1) * o2v_projection_reflection` (its near plane also clipped obliquely at the
water, which changes depth only): its image is the study's turned by 180 degrees, and its
`textureMatrix` is the study's with `s -> q - s`, `t -> q - t`: `textureMatrix =
mat4(-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0, 1, 1, 0, 1) * reflection_texture_matrix` (GLSL's
column order). A shader reads the same colour either way, as long as its texture and
its matrix come from the same camera: wire the engine's pair, or the study's. So

```glsl
uniform mat4 textureMatrix;             // three.js's names bind themselves
uniform sampler2D mirrorSampler;
vec4 uv = textureMatrix * vec4(worldPosition, 1.0);
vec3 mirrored = textureProj(mirrorSampler, uv).rgb;     // or texture(.., uv.xy / uv.w)
```

reads the mirrored image at the point's mirror image (three.js's `Water` offsets `uv.xy` by the
distortion before the lookup; do the same). A shader reading either gets the mirrored camera's
image rendered with the frame.

## Refraction and depth

`refraction_sampler` (= `sceneColor`) is the scene without the water as this camera sees it: the
floor and walls under and around the water, at `(s, t) = gl_FragCoord.xy / screenSize`.
`depth_sampler` (= `sceneDepth`) is its depth buffer as engines store it: window-space depth
`d` in [0, 1], OpenGL's non-linear `d = 0.5 (z_clip / w_clip) + 0.5`, 1 where nothing was hit.
With `camera_near` = n and `camera_far` = f (recovered from the frame's projection: 0.05 and
100 for the study's cameras) the eye distance along the view axis is

```glsl
float z = 2.0 * n * f / (f + n - (2.0 * d - 1.0) * (f - n));
```

and the water's own depth at the pixel is that of `gl_FragCoord.z`, so `z(scene) - z(water)` is
the water's thickness along the view axis (jMonkeyEngine's and Babylon.js's depth-based fog).

## The DuDv map

Engines author a DuDv map as the derivative of the wave offsets: RG in [0, 1] encoding a 2D
distortion, 0.5 = none, read as `(texture(dudv, uv).rg * 2.0 - 1.0) * strength`. The study's
`dudv_map` is derived from its normal map (world normals of the wave height field `h(x, z)`,
`n` proportional to `(-dh/dx, 1, -dh/dz)`) texel for texel:
`RG = clamp(0.5 + 0.5 (n_x / n_y, n_z / n_y), 0, 1)`, that is `0.5 - 0.5 grad h`, B = 0. Its
coordinates are the normal map's (`vTexCoord0` ... `vTexCoord3`, or `(x, z) / normal_tile`
plus the waves' offsets), and it repeats. A slope steeper than 1 is clipped.

## Your own normal-map image

An engine's water comes with its own normal map. Name its file:

```glsl
// @study normal_map waves_normal.png    (relative to the shader file)
uniform sampler2D normalSampler;         // three.js's name binds itself; or bind yours:
// @study bind waterNormals user_normal_map
```

The image (PNG, JPEG, ...: anything Pillow reads; 8 or 16 bits) is read as stored, `value /
255` (no sRGB decoding: a normal map holds data), its top row at `t = 1` (as three.js and
Babylon.js upload it), sampled bilinear with its box-filtered mip chain (trilinear), repeat.
Its tiling and scrolling are your shader's (a constant such as Urho3D's `cNoiseTiling`, declared
as a constant to fit if you like). Whether the reference's waves are those of your image is
another matter: the reference renders the study's waves, unless `waves.source = "shader"`
takes them from your shader.

With no image named, an engine's normal-map sampler (three.js's `normalSampler`, Babylon.js's
`bumpSampler`, jMonkeyEngine's `m_water_normalmap`, three.js's `tNormalMap0`; or any sampler
with `// @study bind NAME waves_normal_map`) reads `waves_normal_map`: the study's own waves,
the reference's, stored as engines store a normal map. Each texel is the tangent-space normal
`RGB = 0.5 + 0.5 (n_x, n_z, n_y)` of the world normal `n` (x along the texture's u = world +x,
y along v = world +z, z up; a flat texel is (0.5, 0.5, 1.0)), the frame jMonkeyEngine's and
three.js's water shaders build from `tangent = (1, 0, 0)`, `binormal = (0, 0, 1)`, `normal =
(0, 1, 0)`; sampled trilinear with its mip chain, repeat, at the texture coordinates of the
study's `normalMap` (`(x, z) / normal_tile` plus the waves' offsets).

## Time, sun, camera

`time` is the animation clock in seconds: on frame `k` of an animated experiment
(`experiments/animated.toml`) `k * animation.time_step`, the time at which the waves'
offsets are `waves.offsets + time * animation.velocities` (`study.scene.animation`); 0 for a
still frame. `sun_direction`
is the unit vector from the centre of the water quad towards `lightpos`. The study's light sits
1000 world units from the origin in the sun's direction, so on the study's pools (centred on
the origin) this is the sun's direction, and within `|centre| / 1000` radians otherwise.
`sun_color` is `lightcolor`: the sun's linear RGB radiance divided by its largest component,
the scale the study's highlight multiplies (its strength is a constant of your shader).
`camera_position` is `viewpos`; `inverse_view_projection` is
`uModelViewProjectionMatrixInverse`.

## A Z-up world

`// @study up z` (or `up = "z"` in the declaration table) gives every world-space input in a
Z-up frame: the right-handed rotation by +90 degrees about x, `(x, y, z) -> (x, -z, y)`, so
the study's `+y` (up) is `+z`, its `+z` is `-y`, and the water plane is `z = 0`. Positions and
directions (`varyingVecWorldPosition`, `varyingVecEye`, `varyingVecLight`, `viewpos`, `lightpos`,
`sun_direction`) are rotated; a matrix taking world points (`uModelViewProjectionMatrix`,
`uTextureMatrix0/1`, `o2v_projection_reflection`, `reflection_texture_matrix`, `uNormalMatrix`)
is multiplied by the inverse rotation on its right; `inverse_view_projection` by the rotation on
its left. Textures stay as they are (the normal map keeps `g` = the study's up; the cube maps
are indexed by Y-up directions: look them up with `vec3(d.x, d.z, -d.y)` of a Z-up `d`). The
study's own frame stays Y-up; the GL check draws the quad in the Z-up frame. With your own
vertex shader (`fit.vertex`) the pragma in the fragment shader holds for the pair: the grid's
positions lie on `z = 0`, its normal is `+z`, its tangent `(1, 0, 0, -1)` and texture
coordinate as in Y-up, and every matrix and camera position it reads is in the Z-up frame
(`experiments/zup_water.toml`: a Z-up GLSL 1.20 pair with `ftransform()` and `gl_TexCoord`).

## The sky cube maps

Both cube maps are GL cube maps: faces in GL order `+X, -X, +Y, -Y, +Z, -Z` (world axes), each
face `F x F` texels in GL upload order, a direction `d` selecting the face of its largest
component and its `(s, t)` as the OpenGL specification's table 8.19 says:

| face | world axis | s grows along | t grows along | row 0 of the face |
|---|---|---|---|---|
| 0 | +x | -z | -y | the top (+y) |
| 1 | -x | +z | -y | the top (+y) |
| 2 | +y (up) | +x | +z | -z |
| 3 | -y | +x | -z | +z |
| 4 | +z | +x | -y | the top (+y) |
| 5 | -z | -x | -y | the top (+y) |

`sky_cube` holds the sky as engines hold a cube map: the texel of direction `d` is the sky in
direction `d`, so `texture(sky_cube, reflect(-eye, n))` is the reflected sky.

`reflectionTexture` is the study's cube map as its seed shaders read it: they look it up with
`normalize(R) * vec3(1, -1, 1)` (the y flip the seed's author marked "probably a bug in my
code"), a quirk the study keeps in the shaders and compensates on the application side, as the
seed's application evidently did: the texel of direction `d` holds the sky in direction
`d * (1, -1, 1)` (`study.scene.user_scene.shader_cubemap`). That is why the worked example's
`my_water.frag` multiplies its reflected ray by `vec3(1.0, -1.0, 1.0)` before the lookup; a
shader that looks `reflectionTexture` up with the reflected ray itself reads the sky of the
ray mirrored in the horizon. The two maps hold the same texels (`sky_cube` is
`reflectionTexture` with the faces +Y and -Y swapped and every face's rows reversed,
`shaders_port.spirv.engine_inputs.sky_cube`). An engine's shader should read `sky_cube`.

## Every input

"""


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def engine_inputs_page() -> str:
    """The Markdown of ``docs/engine-inputs.md``."""
    from shaders_port.spirv.engine_inputs import ENGINE_ALIASES, SAME_AS
    from shaders_port.spirv.translated import STUDY_INPUTS

    missing = sorted(set(STUDY_INPUTS) - set(CONVENTIONS))
    if missing:
        raise KeyError(f"describe the input(s) {missing} in scripts/docs_engine_inputs.py")
    names: dict = {}
    for alias, (inp, engines) in ENGINE_ALIASES.items():
        names.setdefault(inp, []).append(f"`{alias}` ({engines})")
    rows = [
        "| input | GLSL type | what | orientation, units | colour space, encoding | filter, "
        "wrap | engines' names | bind |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, desc in STUDY_INPUTS.items():
        gtype, _, what = desc.partition(": ")
        if name in SAME_AS:
            what = f"{what} (`{SAME_AS[name]}`)" if SAME_AS[name] not in what else what
        orient, colour, filt = CONVENTIONS[name]
        engines = ", ".join(names.get(name, [])) or "-"
        bind = (
            "-" if gtype.startswith(("varying", "built-in")) else f"`// @study bind myName {name}`"
        )
        cells = (f"`{name}`", gtype, what, orient, colour, filt, engines, bind)
        rows.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return HEADER + DETAILS.lstrip("\n") + "\n".join(rows) + "\n"
