"""Plain inputs of the water shaders: textures, matrices, uniforms and tunable constants.

Everything here is NumPy (float32) so that the Dr.Jit port and the GLSL run on
exactly the same data. Conventions (shared by both):

* World space is right-handed, ``+y`` up; the water plane is ``y = 0``.
* Texture arrays are stored in OpenGL upload order: row index ``r`` is the
  texture coordinate ``t = (r + 0.5) / H`` of its texel centre, column ``c`` is
  ``s = (c + 0.5) / W``. Colours are linear RGB.
* Matrices are 4x4 float32 and act on column vectors: ``M @ [x, y, z, 1]``.
* Output images are ``(height, width, C)`` with row 0 at the *top* (image order);
  the GL framebuffer (row 0 at the bottom) is flipped when read back.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

IOR_WATER = 1.333
# ShaderInputs fields that only some shaders read (None when not built)
# the local cube map of reflection = box and its box (optional fields of ShaderInputs)
BOX_INPUTS = ("box_cubemap", "box_min", "box_max", "box_capture")
# the camera's buffers of the dry scene that reflection = ssr reads (the baseline's first two)
SSR_INPUTS = ("scene_color", "scene_depth")
OPTIONAL_INPUTS = (
    "scene_color",
    "scene_depth",
    "reflection_color",
    "reflection_view_proj",
    *BOX_INPUTS,
    "refraction_halves",
)


def _clip(v, limit: int = 80) -> str:
    """``repr(v)`` cut to a readable length for an error message."""
    r = repr(v)
    return r if len(r) <= limit else f"{r[:limit]}... ({len(r) - limit} more characters)"


@dataclass
class ShaderInputs:
    """Everything the application hands the water shaders, for one frame.

    Attributes (all float32 unless noted):
        refraction_texture: (H0, W0, 3) linear RGB of the ground seen from above
            (orthographic); GLSL ``refractionTexture``; bilinear, clamp to edge.
        world_y: (H0, W0) world-space y of the ground seen from above, world units;
            GLSL ``worldYComponent``; nearest, clamp to edge.
        tex_matrix0: (4, 4) world -> (s, t) of the two textures above
            (``gl_TextureMatrix[0]``).
        normal_map: (Hn, Wn, 3) world-space normals encoded ``0.5 * n + 0.5``
            (r = x, g = y, b = z); GLSL ``normalMap``; bilinear, repeat.
        cubemap: (6, F, F, 3) linear RGB sky faces in GL order +X, -X, +Y, -Y, +Z, -Z,
            each face in GL cube-map (s, t) convention; bilinear, clamp to edge.
        fresnel_lut: (N, 2) indexed by cos(theta) in [0, 1] at texel centres
            (i + 0.5) / N; column 0 transmission, column 1 reflection; nearest.
        refl_world_y: (H1, W1) world y of geometry above the water seen from below
            (``worldYComponentReflection``); nearest, clamp to edge. Empty
            geometry is marked with a value below the water plane (e.g. -1e3).
        refl_texture: (H1, W1, 3) linear RGB of that geometry seen from below
            (``reflectionBottom``); bilinear, clamp to edge.
        tex_matrix1: (4, 4) world -> (s, t) of the two reflection textures
            (``gl_TextureMatrix[1]``).
        water_rect: (x0, z0, x1, z1) extent of the water quad on y = 0, world units.
        normal_tile: world units per repeat of the normal map; the quad's texture
            coordinate is ``(x, z) / normal_tile``.
        waves: (4, 2) offsets added to that coordinate for the 4 normal-map layers.
        view_proj: (4, 4) world -> clip space of the camera (OpenGL convention,
            NDC in [-1, 1]^3).
        viewpos: (3,) camera position, world units.
        lightpos: (3,) light position, world units.
        lightcolor: (3,) linear RGB of the specular highlight.
        width, height: output resolution in pixels (int).

    Optional (``None`` unless built; read by the baseline shader ``water_baseline``, the first
    two also by ``water_refraction`` with ``SSR_REFLECTION``, the screen-space reflection):
        scene_color: (Hs, Ws, 3) linear RGB of the scene *without the water* seen by this
            camera (a screen-space buffer, row 0 = bottom of the screen, GL order);
            GLSL ``sceneColor``; bilinear, clamp to edge.
        scene_depth: (Hs, Ws) window-space depth in [0, 1] of that view (GL depth buffer of
            ``view_proj``, 1 where nothing was hit); GLSL ``sceneDepth``; nearest, clamp.
        reflection_color: (Hr, Wr, 3) linear RGB of the scene above the water seen by the
            mirrored camera (clip plane y = 0), rows in GL order of ``reflection_view_proj``'s
            window y; GLSL ``reflection_sampler``; bilinear, clamp to edge.
        reflection_view_proj: (4, 4) world -> clip space of the mirrored camera
            (``o2v_projection_reflection`` of seed 004; :func:`mirrored_view_proj`).

    Optional (``None`` unless built; read by ``water_refraction`` with ``BOX_REFLECTION``, the
    box-projected local cube map of Lagarde and Zanuttini):
        box_cubemap: (6, F, F, 3) linear RGB of the scene without the water (walls, their
            surroundings, the sky without the sun) seen from ``box_capture``, faces and
            ``y`` flip as ``cubemap`` (the texel of direction ``d`` holds the scene in direction
            ``d * (1, -1, 1)``); GLSL ``boxReflectionTexture``; bilinear, clamp to edge.
        box_min, box_max: (3,) corners of the axis-aligned box of the pool's walls, world
            units; ``box_max[1]`` is the walls' top (``boxMin``, ``boxMax``).
        box_capture: (3,) where ``box_cubemap`` was captured, world units
            (``boxCapturePosition``).

    Optional, read by a user's shader only (``spirv.engine_inputs``):
        time: the animation clock, seconds (0.0 for a still frame); GLSL ``time``.

    Optional, read by no shader (the fit's, ``None`` unless built):
        refraction_halves: (2, H0, W0, 3) linear RGB, two independent Monte Carlo estimates of
            ``refraction_texture`` (each from half of its samples, never denoised): the fit's
            decorrelated loss multiplies residuals computed with one by residuals computed
            with the other, so the textures' noise cancels in expectation.
    """

    refraction_texture: np.ndarray
    world_y: np.ndarray
    tex_matrix0: np.ndarray
    normal_map: np.ndarray
    cubemap: np.ndarray
    fresnel_lut: np.ndarray
    refl_world_y: np.ndarray
    refl_texture: np.ndarray
    tex_matrix1: np.ndarray
    water_rect: tuple[float, float, float, float]
    normal_tile: float
    waves: np.ndarray
    view_proj: np.ndarray
    viewpos: np.ndarray
    lightpos: np.ndarray
    lightcolor: np.ndarray
    width: int
    height: int
    scene_color: np.ndarray | None = None
    scene_depth: np.ndarray | None = None
    reflection_color: np.ndarray | None = None
    reflection_view_proj: np.ndarray | None = None
    box_cubemap: np.ndarray | None = None
    box_min: np.ndarray | None = None
    box_max: np.ndarray | None = None
    box_capture: np.ndarray | None = None
    refraction_halves: np.ndarray | None = None
    time: float = 0.0

    def __post_init__(self) -> None:
        shapes = {
            "refraction_texture": (3, 3),
            "world_y": (2, None),
            "tex_matrix0": (2, None),
            "normal_map": (3, 3),
            "cubemap": (4, 3),
            "fresnel_lut": (2, 2),
            "refl_world_y": (2, None),
            "refl_texture": (3, 3),
            "tex_matrix1": (2, None),
            "waves": (2, 2),
            "view_proj": (2, None),
            "viewpos": (1, None),
            "lightpos": (1, None),
            "lightcolor": (1, None),
            "scene_color": (3, 3),
            "scene_depth": (2, None),
            "reflection_color": (3, 3),
            "reflection_view_proj": (2, None),
            "box_cubemap": (4, 3),
            "box_min": (1, 3),
            "box_max": (1, 3),
            "box_capture": (1, 3),
            "refraction_halves": (4, 3),
        }
        for name, (ndim, last) in shapes.items():
            if name in OPTIONAL_INPUTS and getattr(self, name) is None:
                continue
            a = np.ascontiguousarray(getattr(self, name), dtype=np.float32)
            if a.ndim != ndim or (last is not None and a.shape[-1] != last):
                raise ValueError(
                    f"ShaderInputs.{name}: expected {ndim}-d array"
                    + (f" with last axis {last}" if last else "")
                    + f", got shape {a.shape}"
                )
            if not np.all(np.isfinite(a)):
                raise ValueError(
                    f"ShaderInputs.{name} contains non-finite values; "
                    "rebuild the inputs from the scene"
                )
            setattr(self, name, a)
        for name in ("tex_matrix0", "tex_matrix1", "view_proj", "reflection_view_proj"):
            if getattr(self, name) is not None and getattr(self, name).shape != (4, 4):
                raise ValueError(f"ShaderInputs.{name}: expected (4, 4)")
        for name in ("cubemap", "box_cubemap"):
            cube = getattr(self, name)
            if cube is not None and (cube.shape[0] != 6 or cube.shape[1] != cube.shape[2]):
                raise ValueError(f"ShaderInputs.{name}: expected (6, F, F, 3), got {cube.shape}")
        if self.refraction_halves is not None and (
            self.refraction_halves.shape != (2,) + self.refraction_texture.shape
        ):
            raise ValueError(
                f"ShaderInputs.refraction_halves: expected (2,) + the refraction texture's "
                f"shape {self.refraction_texture.shape}, got {self.refraction_halves.shape}"
            )
        if self.waves.shape != (4, 2):
            raise ValueError(f"ShaderInputs.waves: expected (4, 2), got {self.waves.shape}")
        self.water_rect = tuple(float(v) for v in self.water_rect)
        self.normal_tile = float(self.normal_tile)
        self.width, self.height = int(self.width), int(self.height)
        if self.width < 1 or self.height < 1:
            raise ValueError("ShaderInputs: width and height must be positive")

    def require(self, fields, shader: str, builder: str) -> None:
        """Raise ValueError naming the optional ``fields`` this frame lacks (None), the
        ``shader`` that reads them and the ``builder`` function that makes them."""
        missing = [f for f in fields if getattr(self, f) is None]
        if missing:
            raise ValueError(
                f"{shader} needs ShaderInputs.{', '.join(missing)}; build the inputs "
                f"with {builder} (or set them)"
            )

    def with_resolution(self, width: int, height: int) -> "ShaderInputs":
        """Same scene at another output resolution (the projection is unchanged)."""
        return dataclasses.replace(self, width=width, height=height)

    def save(self, path) -> None:
        """Write all fields to one ``.npz`` file (atomic: temp file then rename)."""
        import os
        import tempfile

        path = os.fspath(path)
        d = os.path.dirname(os.path.abspath(path))
        fd, tmp = tempfile.mkstemp(dir=d, suffix=".npz.tmp")
        os.close(fd)
        try:
            with open(tmp, "wb") as f:
                np.savez_compressed(
                    f,
                    **{
                        k: np.asarray(v)
                        for k, v in dataclasses.asdict(self).items()
                        if v is not None
                    },
                )
            os.replace(tmp, path)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)

    @classmethod
    def load(cls, path) -> "ShaderInputs":
        with np.load(path) as z:
            kw = {k: z[k] for k in z.files}
        kw["water_rect"] = tuple(kw["water_rect"].tolist())
        kw["normal_tile"] = float(kw["normal_tile"])
        kw["width"], kw["height"] = int(kw["width"]), int(kw["height"])
        return cls(**kw)


# name in Python -> (GLSL name, kind, default, (lower, upper) valid range)
# kind: "const float", "const int", "uniform float", "uniform vec4"
CONSTANT_SPECS: dict[str, tuple[str, str, object, tuple[float, float]]] = {
    "attenuation_distance": ("ATTENUATION_DISTANCE", "const float", 7.5, (1e-3, 1e4)),
    "steps_grazing": ("STEPS_GRAZING", "const float", 10.0, (0.5, 1e3)),
    "steps_steep": ("STEPS_STEEP", "const float", 3.0, (0.5, 1e3)),
    "loop_cap": ("LOOP_CAP", "const int", 40, (1, 10000)),
    "refl_steps_steep": ("REFL_STEPS_STEEP", "const float", 0.5, (0.05, 1e3)),
    "refl_steps_grazing": ("REFL_STEPS_GRAZING", "const float", 4.0, (0.05, 1e3)),
    "refl_loop_cap": ("REFL_LOOP_CAP", "const int", 60, (1, 10000)),
    "refl_height_cut": ("REFL_HEIGHT_CUT", "const float", 0.8, (0.0, 1e4)),
    "specular_strength": ("SPECULAR_STRENGTH", "const float", 2.0, (0.0, 1e4)),
    "specular_exponent": ("SPECULAR_EXPONENT", "const float", 256.0, (1.0, 1e5)),
    "bumptex_mult": ("BumptexMult", "uniform float", 1.0, (1e-3, 1e3)),
    "refr_coeff": ("refrCoeff", "uniform float", 1.0 / IOR_WATER, (0.1, 1.0)),
    "water_color": ("waterColor", "uniform vec4", (0.05, 0.25, 0.3, 1.0), (0.0, 100.0)),
    "reflect_color": ("reflectColor", "uniform vec4", (1.0, 1.0, 1.0, 1.0), (0.0, 100.0)),
    # read only by the variants of shaders_port.variants (their defaults leave the seed unchanged:
    # the seed's code path never reads them)
    "absorption_r": ("ABSORPTION_R", "const float", 1.0 / 7.5, (1e-4, 100.0)),
    "absorption_g": ("ABSORPTION_G", "const float", 1.0 / 7.5, (1e-4, 100.0)),
    "absorption_b": ("ABSORPTION_B", "const float", 1.0 / 7.5, (1e-4, 100.0)),
    "specular_roughness": ("SPECULAR_ROUGHNESS", "const float", 0.2, (1e-3, 1.0)),
    # the mirrored sun's disc (SUN_DISC_SPECULAR): angular radius at half brightness (degrees;
    # the sun's: 0.27), the softness of its edge (0 hard, 1 a cone from the centre to twice the
    # radius) and its radiance (times lightcolor)
    "sun_disc_radius": ("SUN_DISC_RADIUS", "const float", 0.27, (0.05, 45.0)),
    "sun_disc_softness": ("SUN_DISC_SOFTNESS", "const float", 0.05, (0.01, 1.0)),
    "sun_disc_radiance": ("SUN_DISC_RADIANCE", "const float", 1.0, (0.0, 1e6)),
    "refine_steps": ("REFINE_STEPS", "const int", 3, (0, 64)),
    # the baseline shader (water_baseline: seeds 001-004); defaults are the seeds' where given
    "reflect_distortion": ("REFLECT_DISTORTION", "const float", 0.1, (0.0, 10.0)),  # 002: 0.1
    "refraction_index": ("refractionIndex", "uniform float", 1.0 / IOR_WATER, (0.1, 1.0)),  # 001
    "refraction_strength": (
        "refractionStrength",
        "uniform float",
        0.02,
        (-1.0, 1.0),
    ),  # 003: none given
    "chromatic_dispersion": (
        "chromaticDispersion",
        "uniform float",
        0.002,
        (-0.1, 0.1),
    ),  # 003: none given
}

# GLSL name <-> the study's descriptive name of each constant
GLSL_NAMES = {py: spec[0] for py, spec in CONSTANT_SPECS.items()}
STUDY_NAMES = {glsl: py for py, glsl in GLSL_NAMES.items()}


def _rename(name: str, table: dict) -> str:
    base, sep, rest = name.partition("[")
    return table.get(base, base) + sep + rest


def glsl_scalar(name: str) -> str:
    """A constant or one of its components as the shader's GLSL names it: ``'water_color[1]'``
    -> ``'waterColor[1]'``, ``'bumptex_mult'`` -> ``'BumptexMult'``; a name that is no study
    constant's (a user's shader's own) is returned as it is."""
    return _rename(name, GLSL_NAMES)


def study_scalar(name: str) -> str:
    """The inverse of :func:`glsl_scalar`: ``'waterColor[1]'`` -> ``'water_color[1]'``; a
    study name or a user's shader's own name is returned as it is."""
    return _rename(name, STUDY_NAMES)


def _default(name):
    v = CONSTANT_SPECS[name][2]
    return field(default_factory=lambda: tuple(v)) if isinstance(v, tuple) else field(default=v)


@dataclass
class Constants:
    """The shader's tunable numbers (see ``CONSTANT_SPECS`` for GLSL names and ranges).

    Scalars are Python numbers, or 0-d / size-1 Dr.Jit arrays when a derivative
    is wanted; colours are 4-tuples of linear RGBA.
    """

    attenuation_distance: float = _default("attenuation_distance")
    steps_grazing: float = _default("steps_grazing")
    steps_steep: float = _default("steps_steep")
    loop_cap: int = _default("loop_cap")
    refl_steps_steep: float = _default("refl_steps_steep")
    refl_steps_grazing: float = _default("refl_steps_grazing")
    refl_loop_cap: int = _default("refl_loop_cap")
    refl_height_cut: float = _default("refl_height_cut")
    specular_strength: float = _default("specular_strength")
    specular_exponent: float = _default("specular_exponent")
    bumptex_mult: float = _default("bumptex_mult")
    refr_coeff: float = _default("refr_coeff")
    water_color: tuple = _default("water_color")
    reflect_color: tuple = _default("reflect_color")
    absorption_r: float = _default("absorption_r")
    absorption_g: float = _default("absorption_g")
    absorption_b: float = _default("absorption_b")
    specular_roughness: float = _default("specular_roughness")
    sun_disc_radius: float = _default("sun_disc_radius")
    sun_disc_softness: float = _default("sun_disc_softness")
    sun_disc_radiance: float = _default("sun_disc_radiance")
    refine_steps: int = _default("refine_steps")
    reflect_distortion: float = _default("reflect_distortion")
    refraction_index: float = _default("refraction_index")
    refraction_strength: float = _default("refraction_strength")
    chromatic_dispersion: float = _default("chromatic_dispersion")

    def validate(self) -> "Constants":
        """Raise ValueError naming the constant if a plain value is non-finite or out of range."""
        for name, (glsl, kind, _, (lo, hi)) in CONSTANT_SPECS.items():
            v = getattr(self, name)
            vals = v if isinstance(v, (tuple, list)) else (v,)
            if not kind.endswith("vec4") and isinstance(v, (tuple, list)):
                raise ValueError(f"constant {name} ({glsl}) = {_clip(v)} must be a single number")
            if kind.endswith("vec4") and len(vals) != 4:
                raise ValueError(f"constant {name} ({glsl}) needs 4 components, got {len(vals)}")
            for x in vals:
                if type(x).__module__.startswith("drjit"):
                    continue  # a Dr.Jit array being differentiated (checked by the port)
                if not isinstance(x, (int, float, np.floating, np.integer)):
                    raise ValueError(f"constant {name} ({glsl}) = {_clip(x)} is not a number")
                try:
                    finite = not isinstance(x, bool) and math.isfinite(float(x))
                except OverflowError:  # an integer too large for a float
                    finite = False
                if not finite:
                    raise ValueError(
                        f"constant {name} ({glsl}) = {_clip(x)} is not a finite number"
                    )
                if kind.endswith("int") and float(x) != int(x):
                    raise ValueError(f"constant {name} ({glsl}) = {_clip(x)} must be an integer")
                if not lo <= float(x) <= hi:
                    raise ValueError(
                        f"constant {name} ({glsl}) = {_clip(x)} is outside [{lo}, {hi}]"
                    )
        return self

    def replace(self, **changes) -> "Constants":
        unknown = set(changes) - set(CONSTANT_SPECS)
        if unknown:
            names = ", ".join(_clip(u) for u in sorted(map(str, unknown))[:5])
            more = f" and {len(unknown) - 5} more" if len(unknown) > 5 else ""
            raise ValueError(f"unknown constant(s) {names}{more}; known: {sorted(CONSTANT_SPECS)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        out = {}
        for name in CONSTANT_SPECS:
            v = getattr(self, name)
            out[name] = (
                [float(x) for x in v]
                if isinstance(v, (tuple, list))
                else (int(v) if CONSTANT_SPECS[name][1].endswith("int") else float(v))
            )
        return out

    def to_glsl_dict(self) -> dict:
        """:meth:`to_dict` keyed by the GLSL names (``{'ATTENUATION_DISTANCE': 7.5, ...}``)."""
        return {GLSL_NAMES[k]: v for k, v in self.to_dict().items()}

    @classmethod
    def from_dict(cls, d: dict) -> "Constants":
        """From ``{name: value}``, each name the study's (``attenuation_distance``) or the
        GLSL's (``ATTENUATION_DISTANCE``); ValueError for an unknown name or one given twice."""
        both = [k for k in d if k in STUDY_NAMES and STUDY_NAMES[k] in d]
        if both:
            raise ValueError(
                f"{both[0]} and {STUDY_NAMES[both[0]]} are two names of one constant: give one"
            )
        d = {STUDY_NAMES.get(k, k): v for k, v in d.items()}
        unknown = set(d) - set(CONSTANT_SPECS)
        if unknown:
            names = ", ".join(_clip(u) for u in sorted(map(str, unknown))[:5])
            more = f" and {len(unknown) - 5} more" if len(unknown) > 5 else ""
            raise ValueError(f"unknown constant(s) {names}{more}; known: {sorted(CONSTANT_SPECS)}")
        kw = {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
        return cls(**kw).validate()


def perspective_view_proj(
    eye, target, up=(0.0, 1.0, 0.0), fov_y_deg=45.0, aspect=1.0, near=0.05, far=100.0
) -> np.ndarray:
    """OpenGL ``gluPerspective(fov_y) * gluLookAt(eye, target, up)`` as a (4, 4) float32."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:
        raise ValueError(
            "camera: 'up' is parallel to the viewing direction; choose another up vector"
        )
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = s, u, -f
    view[:3, 3] = -view[:3, :3] @ eye
    g = 1.0 / math.tan(math.radians(fov_y_deg) / 2.0)
    proj = np.zeros((4, 4))
    proj[0, 0], proj[1, 1] = g / aspect, g
    proj[2, 2], proj[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    proj[3, 2] = -1.0
    return (proj @ view).astype(np.float32)


def normal_matrix(view_proj: np.ndarray) -> np.ndarray:
    """(3, 3) float32 ``gl_NormalMatrix`` of the camera (model = identity): the rotation of its
    view matrix, recovered from a ``perspective_view_proj`` product (rows 0 and 1 of the
    projection scale the view's x and y rows, row 3 is minus its z row)."""
    vp = np.asarray(view_proj, np.float64)
    rows = [vp[0, :3], vp[1, :3], -vp[3, :3]]
    R = np.stack([r / np.linalg.norm(r) for r in rows])
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-5):
        raise ValueError(
            "normal_matrix: view_proj is not a symmetric perspective times a rigid view"
        )
    return R.astype(np.float32)


def mirrored_view_proj(view_proj: np.ndarray) -> np.ndarray:
    """(4, 4) float32 view-projection of the camera mirrored in the water plane y = 0, seed 004's
    ``Mprojection * (Mreflection * Mcamera * Mflip)^-1``: ``Mflip`` (y -> -y in camera space)
    commutes with a symmetric perspective, so this is ``diag(1,-1,1,1) @ view_proj @ Mreflection``
    with ``Mreflection = diag(1,-1,1,1)`` (the plane's reflection matrix for N = (0,1,0), D = 0)."""
    F = np.diag([1.0, -1.0, 1.0, 1.0])
    return (F @ np.asarray(view_proj, np.float64) @ F).astype(np.float32)


def ortho_tex_matrix(x0: float, z0: float, x1: float, z1: float) -> np.ndarray:
    """(4, 4) world -> texture matrix of an orthographic top/bottom view of [x0,x1] x [z0,z1]:
    s = (x - x0) / (x1 - x0), t = (z - z0) / (z1 - z0)."""
    m = np.zeros((4, 4), dtype=np.float32)
    m[0, 0], m[0, 3] = 1.0 / (x1 - x0), -x0 / (x1 - x0)
    m[1, 2], m[1, 3] = 1.0 / (z1 - z0), -z0 / (z1 - z0)
    m[3, 3] = 1.0
    return m


def fresnel_unpolarized(cos_i, ior: float = IOR_WATER) -> np.ndarray:
    """Fresnel reflectance of a smooth dielectric seen from the outside (eta = ior)."""
    cos_i = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    sin_t2 = (1.0 - cos_i**2) / ior**2
    cos_t = np.sqrt(np.maximum(0.0, 1.0 - sin_t2))
    rs = (cos_i - ior * cos_t) / (cos_i + ior * cos_t)
    rp = (ior * cos_i - cos_t) / (ior * cos_i + cos_t)
    return 0.5 * (rs**2 + rp**2)


def fresnel_lut(ior: float = IOR_WATER, n: int = 256) -> np.ndarray:
    """(n, 2) float32 LUT indexed by cos(theta) at texel centres: [transmission, reflection]."""
    c = (np.arange(n) + 0.5) / n
    r = fresnel_unpolarized(c, ior)
    return np.stack([1.0 - r, r], axis=1).astype(np.float32)


# ---- texture precision as a game would ship it (the application-side variant) ---------------


def _srgb8(x: np.ndarray) -> np.ndarray:
    """Linear values stored in an 8-bit sRGB texture and read back (decoded to linear)."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    q = np.round(s * 255.0) / 255.0
    return np.where(q <= 0.04045, q / 12.92, np.power((q + 0.055) / 1.055, 2.4)).astype(np.float32)


def _unorm8(x: np.ndarray) -> np.ndarray:
    """Values in [0, 1] stored in an 8-bit UNORM texture and read back."""
    return (np.round(np.clip(np.asarray(x, np.float64), 0.0, 1.0) * 255.0) / 255.0).astype(
        np.float32
    )


def _half(x: np.ndarray) -> np.ndarray:
    """Values stored in a half-float (16-bit) texture and read back."""
    return np.asarray(x, np.float32).astype(np.float16).astype(np.float32)


_GAME_CACHE: dict = {}


def game_precision(inputs: ShaderInputs) -> ShaderInputs:
    """``inputs`` with every texture at the precision a game would ship it, as float32 arrays
    holding exactly the values the GPU would read (so the port and GL upload the same data):

    * colour (``refraction_texture``, ``refl_texture``): 8-bit sRGB (``GL_SRGB8``), values
      clipped to [0, 1];
    * ``normal_map``: 8-bit UNORM (``GL_RGB8``, the usual ``0.5 n + 0.5`` encoding);
    * ``fresnel_lut``: 8-bit UNORM;
    * depths (``world_y``, ``refl_world_y``) and the HDR cube maps (``cubemap``, ``box_cubemap``):
      half float (``GL_R16F``, ``GL_RGB16F``); the camera's HDR colour buffer ``scene_color``
      (read by ``reflection = ssr``): half float; its depth buffer ``scene_depth`` stays float
      (a 32-bit depth buffer: half float cannot hold window depths apart).

    Filtering still runs in float on the dequantised texels on both sides (GL hardware
    filters 8-bit texels at 8-bit sub-texel precision; this is not modelled). One result is
    kept per inputs object (the port's texture cache then hits on repeated renders)."""
    key = id(inputs)
    arrays = tuple(id(v) for v in vars(inputs).values())
    hit = _GAME_CACHE.get(key)
    if hit is not None and hit[0] == arrays and hit[1] is inputs:
        return hit[2]
    out = dataclasses.replace(
        inputs,
        refraction_texture=_srgb8(inputs.refraction_texture),
        refl_texture=_srgb8(inputs.refl_texture),
        normal_map=_unorm8(inputs.normal_map),
        fresnel_lut=_unorm8(inputs.fresnel_lut),
        world_y=_half(inputs.world_y),
        refl_world_y=_half(inputs.refl_world_y),
        cubemap=_half(inputs.cubemap),
        box_cubemap=None if inputs.box_cubemap is None else _half(inputs.box_cubemap),
        scene_color=None if inputs.scene_color is None else _half(inputs.scene_color),
    )
    _GAME_CACHE.clear()
    _GAME_CACHE[key] = (arrays, inputs, out)
    return out
