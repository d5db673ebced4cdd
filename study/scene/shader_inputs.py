"""The shader's inputs, derived from the same Mitsuba scene as the reference.

As the seed's application prepares them, but from the scene:

* ``refraction_texture``: the ground path-traced from above with an orthographic camera
  under the same sky and sun, like the seed's ``WaterDrawTextureRefractionTop``; the floor
  is diffuse, so its radiance does not depend on the view. By default the floor is lit
  *through the water* (see :func:`top_down_colour`); ``reference.refraction_lighting =
  "dry"`` renders it without water as the seed's application does;
* ``world_y``: world y of the first surface hit from above at each texel centre (ray cast,
  exact, no filtering), like ``WaterDrawTextureDepthRefractionTop``;
* the bottom-up textures of the reflection shader: the geometry above the water is the
  pool walls (and the user's mesh, ``topdown.mesh_reflection_textures``), whose bottom-up view
  (clipped at the water plane, looking up) shows their top at ``wall_height``; so ``refl_world_y``
  is the top-down ``world_y`` where it is above the water and a sentinel -1e3 elsewhere, and
  ``refl_texture`` is the top-down colour there;
* the normal map of the waves (``_geometry.Waves``) with its four offsets;
* the sky cube map from the same sky function without the sun disc (the sun is the
  shader's light and specular highlight). The shader looks the cube map up with ``y``
  flipped (the seed's "probably a bug in my code"); the quirk is kept in the shader and the
  application side compensates, as the seed's application evidently did: texel of
  direction ``d`` stores the sky in direction ``d * (1, -1, 1)``;
* the Fresnel LUT for the experiment's IOR (see :func:`shader_fresnel_lut`); the light at the sun's
  direction, 1000 world units away, coloured as the normalised sun radiance; the camera of the
  experiment;
* for the fit alone, with ``reference.texture_method = "lighting"``: ``refraction_halves``, the
  refraction texture's two independent halves (:func:`half_inputs`, ``fit.input_noise``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from shaders_port import ShaderInputs, fresnel_lut, ortho_tex_matrix

from .._io import disk_full, file_lock
from .._progress import Stages
from ..config.errors import ExperimentError
from ..config.experiment import Experiment
from .cache import SCENE_VERSION, cache_dir, versions
from .animation import shared_part
from .lighting import lighting_colour
from .mitsuba_scene import camera_view_proj, study_waves
from .topdown import (
    MAX_OPTICAL_DEPTH,
    NO_GEOMETRY,
    camera_ray_optical_depth,
    mesh_reflection_textures,
    render_top_down,
    texture_extent,
    top_down_world_y,
    underwater_camera_height,
)
from .user_scene import dry_camera_height, shader_cubemap, sun_of

INPUTS_VERSION = 12  # bump whenever the construction of the inputs below changes
CUBEMAP_SIZE = 64
FRESNEL_SIZE = 256
LIGHT_DISTANCE = 1000.0


def top_down_colour(
    exp: Experiment, extent, size: int, spp: int, seed: int = 0, world_y=None, stages=None
) -> np.ndarray:
    """(size, size, 3) float32 linear RGB of the ground seen from above (GL order).

    ``reference.refraction_lighting``:

    * ``"dry"``: the scene without water, as the seed's application renders it;
    * ``"underwater"`` (default): inside the pool, the floor's own radiance as lit *through
      the water* (sky and sun refracted by the wave surface, light absorbed on its way down),
      seen by an orthographic camera placed inside the water just below the wave troughs;
      the absorption of the camera's own vertical ray (:func:`camera_ray_optical_depth`, from
      where its rays start: its near clip plane, 1 cm below it) is divided out (exact for
      purely absorbing water, ``water.albedo = 0``; where its optical depth exceeds
      ``MAX_OPTICAL_DEPTH`` nothing is left to recover and the dry render is used). Outside the
      pool (the walls) the dry render is used. With it the shader's attenuation stands for
      absorption along the view path only.
    """
    import mitsuba as mi

    st = stages or Stages(quiet=True)
    label = f"shader inputs: top-down render without water ({size}x{size}, {spp} spp)"
    with st.stage("inputs.dry_render_s", label):
        dry = render_top_down(
            mi,
            exp,
            extent,
            size,
            spp,
            seed,
            water=False,
            y_cam=dry_camera_height(mi, exp, extent),
            progress=st.counter("  passes"),
        )
    if exp.reference.refraction_lighting == "dry":
        return dry
    y_cam = underwater_camera_height(exp)
    label = f"shader inputs: top-down render through the water ({size}x{size}, {spp} spp)"
    with st.stage("inputs.wet_render_s", label):
        wet = render_top_down(
            mi,
            exp,
            extent,
            size,
            spp,
            seed,
            water=True,
            y_cam=y_cam,
            progress=st.counter("  passes"),
        )
    if world_y is None:
        world_y = top_down_world_y(exp, extent, size)
    optical = camera_ray_optical_depth(exp, y_cam, world_y)
    # beyond an optical depth of MAX_OPTICAL_DEPTH the floor's light through the water is lost
    # in float precision (very murky water): the dry render stands in for those texels
    lost = optical > MAX_OPTICAL_DEPTH
    wet = np.where(
        lost, dry, wet.astype(np.float64) * np.exp(np.minimum(optical, MAX_OPTICAL_DEPTH))
    )
    x0, z0, x1, z1 = extent
    c = (np.arange(size) + 0.5) / size
    X, Z = np.meshgrid(x0 + c * (x1 - x0), z0 + c * (z1 - z0))
    hx, hz = exp.pool.half_extent
    inside = (np.abs(X) < hx) & (np.abs(Z) < hz) & (world_y < y_cam)
    return np.where(inside[..., None], wet, dry).astype(np.float32)


def sky_cubemap(exp: Experiment, size: int = CUBEMAP_SIZE) -> np.ndarray:
    """(6, size, size, 3) float32 cube map of the sky without the sun, stored y-flipped
    to compensate the shader's ``* vec3(1, -1, 1)`` lookup."""
    return shader_cubemap(exp, size)


def shader_fresnel_lut(exp: Experiment) -> np.ndarray:
    """(N, 2) Fresnel LUT [transmission, reflection] for the experiment's IOR. With
    ``reference.fresnel_transmission = "radiance"`` the transmission is divided by ior^2:
    radiance crossing from water (n) into air (1) scales by T / n^2 (the n^2 law of radiance),
    which the shader's ``vRefraction * FresnelCoeffs.r`` otherwise leaves out."""
    lut = fresnel_lut(exp.water.ior, FRESNEL_SIZE)
    if exp.reference.fresnel_transmission == "radiance":
        lut[:, 0] /= exp.water.ior**2
    return lut


def light_of(exp: Experiment) -> tuple[np.ndarray, np.ndarray]:
    """(lightpos (3,), lightcolor (3,)): the sun far away, colour = sun radiance / its max."""
    sun_dir, rad = sun_of(exp)
    colour = rad / rad.max() if rad.max() > 0 else np.zeros(3)
    return LIGHT_DISTANCE * sun_dir, colour


def build_shader_inputs(
    exp: Experiment,
    width: int | None = None,
    height: int | None = None,
    progress=None,
    info: dict | None = None,
    shared=None,
) -> ShaderInputs:
    """All shader inputs of ``exp`` at output resolution (width, height) (default: the
    experiment's). ``progress``: a ``study._progress.Stages`` that times and reports each stage
    (default: quiet). ``info``, if given, receives how the refraction texture was made (``texture``:
    method, settings and, for ``lighting``, its measured noise). ``shared``: a
    :class:`~.animation.FrameShared` of an animation's frames: what does not depend on the wave
    offsets (world y, the dry render and albedo, the lighting scene, the lighting grid's world y,
    the skylight's sample patterns, the reflection textures of a mesh, the normal map, the cube
    map, the LUT) is then built once for all frames."""
    st = progress or Stages(quiet=True)
    width = width or exp.resolution[0]
    height = height or exp.resolution[1]
    extent = texture_extent(exp)
    size = exp.reference.texture_size
    with st.stage("inputs.world_y_s", f"shader inputs: world-y ray cast ({size}x{size})"):
        world_y = shared_part(shared, exp, "world_y", lambda: top_down_world_y(exp, extent, size))
    if exp.reference.texture_method == "lighting":
        with st.stage(
            "inputs.lighting_s", f"shader inputs: lighting x albedo texture ({size}x{size})"
        ):
            colour, tex_info, halves = lighting_colour(
                exp,
                extent,
                size,
                exp.reference.seed,
                world_y=world_y,
                progress=st.counter("  passes"),
                shared=shared,
            )
    else:
        colour = top_down_colour(
            exp,
            extent,
            size,
            exp.reference.texture_spp,
            exp.reference.seed,
            world_y=world_y,
            stages=st,
        )
        tex_info = {"method": "colour", "spp": exp.reference.texture_spp, "noise": None}
        halves = None
    if info is not None:
        info["texture"] = tex_info
    tm = ortho_tex_matrix(*extent)
    refl_y, refl_col, tm1 = _reflection_textures(exp, extent, size, world_y, colour, st, shared)
    hx, hz = exp.pool.half_extent
    waves = study_waves(exp)
    lightpos, lightcolor = light_of(exp)
    c = exp.section("camera")
    with st.stage("inputs.maps_s", "shader inputs: normal map, sky cube map, Fresnel LUT"):
        normal_map, cubemap, lut = shared_part(
            shared,
            exp,
            "maps",
            lambda: (
                waves.normal_map(exp.waves.normal_map_size),
                sky_cubemap(exp),
                shader_fresnel_lut(exp),
            ),
        )
    return ShaderInputs(
        refraction_texture=colour,
        world_y=world_y,
        tex_matrix0=tm,
        normal_map=normal_map,
        cubemap=cubemap,
        fresnel_lut=lut,
        refl_world_y=refl_y,
        refl_texture=refl_col,
        tex_matrix1=tm1,
        water_rect=(-hx, -hz, hx, hz),
        normal_tile=exp.waves.normal_tile,
        waves=np.asarray(exp.waves.offsets),
        view_proj=camera_view_proj(exp, width, height),
        viewpos=np.asarray(c["position"]),
        lightpos=lightpos,
        lightcolor=lightcolor,
        width=width,
        height=height,
        refraction_halves=halves,
    )


def _reflection_textures(exp, extent, size: int, world_y, colour, st, shared):
    """The reflection shader's top-down textures: (world y (size, size) float32, colour
    (size, size, 3) float32 linear RGB, their 4x4 texture matrix), from the mesh when there is
    one (built once for an animation's frames), else from the refraction textures."""
    if not exp.mesh.file:
        refl_y = np.where(world_y > 0.0, world_y, NO_GEOMETRY).astype(np.float32)
        return refl_y, reflection_colour(world_y, colour), ortho_tex_matrix(*extent)

    with st.stage("inputs.mesh_reflection_s", "shader inputs: reflection textures with the mesh"):
        refl_y, refl_col, refl_extent = shared_part(
            shared,
            exp,
            "mesh_reflection",
            lambda: mesh_reflection_textures(exp, extent, size, progress=st.counter("  passes")),
        )
    return refl_y, refl_col, ortho_tex_matrix(*refl_extent)


def reflection_colour(world_y: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """The reflection shader's bottom-up colour without a user mesh: the top-down ``colour``
    (H, W, 3) where the geometry (``world_y`` (H, W)) rises above the water, 0 elsewhere;
    float32."""
    return np.where((world_y > 0.0)[..., None], colour, 0.0).astype(np.float32)


def half_inputs(exp: Experiment, inputs: ShaderInputs) -> tuple[ShaderInputs, ShaderInputs]:
    """The inputs with their refraction texture replaced by each of its two independent halves
    (``ShaderInputs.refraction_halves``), the reflection texture too where it is cut from the
    refraction texture (no ``mesh.file``). Raises ExperimentError when the inputs have no halves
    (``reference.texture_method = "colour"``)."""
    if inputs.refraction_halves is None:
        raise ExperimentError(
            'fit.input_noise = "decorrelate" needs two independent halves of the '
            'refraction texture, which only reference.texture_method = "lighting" '
            'renders; use that method or fit.input_noise = "ignore"'
        )
    out = []
    for half in inputs.refraction_halves:
        refl = inputs.refl_texture if exp.mesh.file else reflection_colour(inputs.world_y, half)
        out.append(
            dataclasses.replace(
                inputs, refraction_texture=half, refl_texture=refl, refraction_halves=None
            )
        )
    return out[0], out[1]


def load_or_build_shader_inputs(
    exp: Experiment, variant: str, cache=None, log=print, progress=None, shared=None
) -> ShaderInputs:
    """:func:`cached_shader_inputs` with ``time`` = ``waves.time`` (the clock of the waves the
    reference has, 0 unless set)."""
    inputs = cached_shader_inputs(exp, variant, cache, log, progress, shared)
    t = float(exp.waves.time)
    return inputs if t == inputs.time else dataclasses.replace(inputs, time=t)


def cached_shader_inputs(
    exp: Experiment, variant: str, cache=None, log=print, progress=None, shared=None
) -> ShaderInputs:
    """The shader inputs of ``exp`` from ``<cache>/inputs/<key>.npz`` if present, else built
    and written there atomically. The key hashes every experiment value that affects them
    (``Experiment.inputs_hash``), the variant, ``SCENE_VERSION``, ``INPUTS_VERSION``, this
    module's sizes and the package versions. The file name is the key, and files are written
    atomically, so a file under a key holds exactly what was built for it. ``shared``: see
    :func:`build_shader_inputs` (the parts it shares are built the same way, so the file is the
    same)."""
    import hashlib
    import json

    key = hashlib.sha256(
        json.dumps(
            {
                "inputs": exp.inputs_hash(),
                "variant": variant,
                "scene_version": SCENE_VERSION,
                "inputs_version": INPUTS_VERSION,
                "sizes": [CUBEMAP_SIZE, FRESNEL_SIZE, LIGHT_DISTANCE, NO_GEOMETRY],
                "versions": versions(),
            },
            sort_keys=True,
        ).encode()
    ).hexdigest()[:32]
    path = (cache or cache_dir()) / "inputs" / f"{key}.npz"
    inputs = _cached_inputs(path, log)
    if inputs is not None:
        return inputs

    with file_lock(path.with_suffix(".lock"), "shader inputs", log):
        inputs = _cached_inputs(path, log)  # another process may have built them meanwhile
        if inputs is not None:
            return inputs
        info: dict = {}
        inputs = build_shader_inputs(exp, progress=progress, info=info, shared=shared)
        path.parent.mkdir(parents=True, exist_ok=True)
        with disk_full(path.parent):
            inputs.save(path)
    tex = info["texture"]
    noise = (
        f", texture noise {tex['noise']:.2e} (RMS standard error on the pool)"
        if tex.get("noise")
        else ""
    )
    if tex.get("denoise_gain"):
        noise += (
            ", denoised / raw texture mean on the pool R / G / B "
            + " / ".join(f"{g:.3f}" for g in tex["denoise_gain"])
            + " (+- "
            + " / ".join(f"{e:.3f}" for e in tex["denoise_gain_se"])
            + ")"
            + (", matched to the raw mean" if tex.get("denoise_matched") else "")
        )
    if tex.get("direct") == "traced":
        noise += (
            f"; direct light traced: sky {tex['sky_directions']} directions per texel"
            + (
                ", denoised / raw " + " / ".join(f"{g:.3f}" for g in tex["sky_denoise_gain"])
                if tex.get("sky_denoise_gain")
                else ""
            )
            + (
                f", sun {tex['sun_photons'] / 1e6:.2f} M photons "
                f"({tex['sun_photons_landed'] / 1e6:.2f} M landed)"
                if tex.get("sun_photons")
                else ""
            )
        )
    if tex.get("wall_denoise_gain"):
        noise += (
            "; outside the pool the dry render denoised, denoised / raw "
            + " / ".join(f"{g:.3f}" for g in tex["wall_denoise_gain"])
            + ", matched"
        )
    what = "bounced light, " if tex.get("direct") == "traced" else ""
    log(
        f"shader inputs: built ({tex['method']} texture, {what}{tex['spp']} spp{noise}) "
        f"and cached at {path}"
    )
    return inputs


def _cached_inputs(path, log) -> ShaderInputs | None:
    if not path.exists():
        return None
    try:
        inputs = ShaderInputs.load(path)
        log(f"shader inputs: cached {path}")
        return inputs
    except (OSError, ValueError, KeyError) as exc:
        log(f"shader inputs: unreadable cache file {path} ({exc}); rebuilding")
    return None
