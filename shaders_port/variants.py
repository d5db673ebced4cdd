"""The registry of shader variants: one entry per shader the study can fit, time and chart.

A *variant* is a name, one GLSL fragment shader (a file in ``glsl/`` and its Dr.Jit port module of
the same name in ``ports/``) and the preprocessor names it is compiled with. The port reads the same
names through its one table ``DEFINES`` (``shaders_port.ports.switches``), so GL, export and port
take the same code path by construction. Everything above this layer (the fit, the sweeps, the
tradeoff chart, export and the GL check) names a shader by its variant name only, so a new shader
joins the study with one file pair and one :func:`register` call here.

``VARIANTS`` maps names to :class:`Variant`, in registration order (the order of charts and
tables): the shipped ones (``SHIPPED``) and any other shader of the space used so
far. Shipped: 18 variants, registered below: ``water_refraction`` (the original shader,
section 2), ``water_reflection`` (section 3: reflections raycast too), their ``#define`` variants
(Beer-Lambert attenuation, wall faces, GGX, the crossing refinement, fewer normal-map layers,
game-precision textures, no highlight, and ``water_refraction_noreflection``: ``#define
NOREFLECTION``, the refraction alone -- no sky reflection and so no highlight either) and the
game-water baseline ``water_baseline`` with its two ``#define`` variants.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

from . import space as _space
from .gl.renderer import GLRenderer
from .glsl_text import constants_read, read_source, switches_of, with_define
from .inputs import BOX_INPUTS, SSR_INPUTS, game_precision


@dataclass(frozen=True)
class Variant:
    """One shader variant.

    Attributes:
        name: registry key; also the file stem of an exported variant.
        shader: GLSL file stem under ``glsl/`` and port module under ``shaders_port.ports``.
        defines: preprocessor names inserted after ``#version`` (GL and export) and decoded by
            the port's ``DEFINES`` table (``render(..., defines=...)``).
        schedule: names of the integer-valued step-schedule constants the variant reads (swept by
            the tradeoff study, never fitted by a gradient).
        description: one line for reports.
        replaces: seed constant -> the variant's constants that take its role in a fit (e.g. the
            Beer-Lambert variant fits ``absorption_r/g/b`` where the seed fits
            ``attenuation_distance``; ``()``: the variant does not read it). See :meth:`fit_names`.
        textures: 'float' (float32 textures, the study's default) or 'game' (the application
            uploads 8-bit colour and half-float depth, ``shaders_port.inputs.game_precision``;
            the port and GL both get the quantised arrays, the GLSL is unchanged).
        inputs: optional ``ShaderInputs`` fields the variant reads (built on demand by the
            study, e.g. the baseline's screen-space buffers).
        fit_parameters: constants of its own that studies fitting several variants (``study
            tradeoff``) fit besides the experiment's ``fit.parameters`` (those it reads).
    """

    name: str
    shader: str
    defines: tuple[str, ...] = ()
    schedule: tuple[str, ...] = ()
    description: str = ""
    replaces: dict = field(default_factory=dict)
    textures: str = "float"
    inputs: tuple[str, ...] = ()
    fit_parameters: tuple[str, ...] = ()

    def prepare_inputs(self, inputs):
        """The inputs as this variant's application uploads them (see ``textures``)."""
        if self.textures == "game":
            return game_precision(inputs)
        return inputs

    def fit_names(self, requested) -> list[str]:
        """The constants to fit for the experiment's ``fit.parameters`` ``requested``: each name
        the variant replaces becomes its replacements (order kept, no duplicates); names the
        variant's GLSL does not read are dropped (the schema refuses them for ``fit.shader``)."""
        out = []
        for n in requested:
            for r in self.replaces.get(n, (n,)):
                if r not in out:
                    out.append(r)
        reads = set(self.reads())
        return [n for n in out if n in reads]

    def reads(self) -> tuple[str, ...]:
        """``CONSTANT_SPECS`` names the variant's GLSL declares and uses with its defines (the only
        constants a fit of it may name)."""

        return tuple(constants_read(self.source()))

    def port(self):
        """The port module (imports Dr.Jit)."""
        return importlib.import_module(f"shaders_port.ports.{self.shader}")

    def render(self, inputs, constants=None, **kw):
        """``port.render`` compiled with this variant's defines: a ``ShaderOutput``."""
        return self.port().render(
            self.prepare_inputs(inputs), constants, defines=self.defines, **kw
        )

    def render_with_jacobian(self, inputs, constants, names, **kw):
        """``port.render_with_jacobian`` with this variant's defines: ``(ShaderOutput, J)``."""
        return self.port().render_with_jacobian(
            self.prepare_inputs(inputs), constants, names, defines=self.defines, **kw
        )

    def source(self, dialect: str = "core", text: str | None = None) -> str:
        """Fragment shader text of the variant: ``text`` (e.g. an export) or the shipped file,
        with the variant's defines inserted."""
        src = text if text is not None else read_source(self.shader, "frag", dialect)
        for d in self.defines:
            src = with_define(src, d)
        return src

    def gl_renderer(self, inputs, source: str | None = None, dialect: str = "core"):
        """A ``GLRenderer`` drawing this variant (``source``: the shader file's text without the
        variant's defines, e.g. an export; the renderer adds them)."""

        return GLRenderer(
            self.shader,
            self.prepare_inputs(inputs),
            dialect=dialect,
            source=source,
            defines=self.defines,
        )


VARIANTS: dict[str, Variant] = {}


def register(variant: Variant) -> Variant:
    """Add a variant; its name must be new and its shader a shipped file."""
    if variant.textures not in ("float", "game"):
        raise ValueError(
            f"variant {variant.name!r}: textures must be 'float' or 'game', got "
            f"{variant.textures!r}"
        )
    if variant.name in VARIANTS:
        raise ValueError(f"shader variant {variant.name!r} is already registered")
    src = read_source(variant.shader, "frag", "core")  # raises naming the missing file
    unknown = [d for d in variant.defines if d not in switches_of(src)]
    if unknown:
        raise ValueError(
            f"variant {variant.name!r}: {variant.shader}.frag tests no #define {unknown}; "
            f"it tests: {', '.join(switches_of(src))}"
        )
    VARIANTS[variant.name] = variant
    return variant


# the longest name a shader of the space can have, quoted (its longest is 74 characters today)
MAX_NAME = 120


def get_variant(name: str) -> Variant:
    """The variant ``name``: a registered one, or any configuration of the shader space named
    as :func:`shaders_port.space.name_of` names it (built and registered on first use, in
    every process alike, so a sweep's workers resolve the names the driver planned). A
    ValueError says why otherwise (unknown token, or a configuration no file realises)."""
    if name in VARIANTS:
        return VARIANTS[name]
    if str(name).endswith(".frag"):
        raise ValueError(
            f"{name}: your own GLSL shader is calibrated by `study calibrate` (through SPIR-V, "
            "docs/user-shader.md); this command takes the study's shaders"
        )
    shown = repr(name)
    if len(shown) > MAX_NAME:  # no name of the space is this long: not echoed whole (nor twice)
        raise ValueError(
            f"unknown shader variant {shown[:60]}... ({len(str(name))} characters: no name of the "
            "shader space is that long; the names: docs/shader-space.md)"
        )
    try:
        return register(from_space(_space.choices_of(name)))
    except ValueError as exc:
        raise ValueError(
            f"unknown shader variant {name!r}: {exc} (the names: docs/shader-space.md)"
        ) from None


_RAYCAST = ("steps_grazing", "steps_steep", "loop_cap")
_REFLECTION_SCHEDULE = ("refl_steps_steep", "refl_steps_grazing", "refl_loop_cap")
# constants a choice fits in place of the original's (Variant.replaces)
_BEER = {"attenuation_distance": ("absorption_r", "absorption_g", "absorption_b")}
_GGX = {"specular_exponent": ("specular_roughness",)}
# the sun's disc is the scene's sun (its start constants: study.fit.model.constants_from_experiment)
_DISC = {"specular_strength": (), "specular_exponent": ()}
_NOSPEC = {"specular_strength": (), "specular_exponent": ()}
_BASELINE_INPUTS = ("scene_color", "scene_depth", "reflection_color", "reflection_view_proj")
_BASELINE_FIT = (
    "refraction_index",
    "refraction_strength",
    "chromatic_dispersion",
    "reflect_distortion",
)


def from_space(choices: dict, description: str | None = None) -> Variant:
    """The :class:`Variant` of a configuration of the shader space (``space.AXES`` choices):
    its file and defines (``space.realise``), its step schedule, the constants its choices
    fit in place of the original's, and the inputs beyond the study's it reads (the screen-space
    buffers of the baseline shader and the mirror, the local cube map of ``reflection = box``,
    the camera's buffers of ``reflection = ssr``)."""
    c = _space.checked(choices)
    shader, defines, textures = _space.realise(c)
    name = _space.name_of(c)
    if shader == "water_baseline":
        return Variant(
            name,
            shader,
            defines=defines,
            inputs=_BASELINE_INPUTS,
            fit_parameters=_BASELINE_FIT,
            description=description or _space.describe(c),
        )
    schedule = _RAYCAST + (("refine_steps",) if c["refine"] != "linear" else ())
    if c["reflection"] == "raycast":
        schedule += _REFLECTION_SCHEDULE
    replaces = {}
    if c["attenuation"] == "beer":
        replaces.update(_BEER)
    if c["specular"] == "ggx":
        replaces.update(_GGX)
    elif c["specular"] == "disc":
        replaces.update(_DISC)
    elif c["specular"] == "none" and c["reflection"] != "none":
        replaces.update(_NOSPEC)
    mirror = c["reflection"] == "planar_distorted"  # 004's mirrored camera, 002's offset
    extra = {"planar_distorted": _BASELINE_INPUTS, "box": BOX_INPUTS, "ssr": SSR_INPUTS}
    return Variant(
        name,
        shader,
        defines=defines,
        schedule=schedule,
        description=description or _space.describe(c),
        replaces=replaces,
        textures=textures,
        inputs=extra.get(c["reflection"], ()),
        fit_parameters=("reflect_distortion",) if mirror else (),
    )


SHIPPED: list[str] = []  # the variants registered below, in chart order (VARIANTS grows on use)


def _shipped(name: str, description: str) -> None:
    register(from_space(_space.choices_of(name), description))
    SHIPPED.append(name)


# the shipped variants, in chart order: the original two shaders (source 000), the study's
# variants of the original (each answers one limitation; shaders_port/README.md, "Variants")
# and the game-water baselines (sources 001-004); any other configuration of the space is
# built on demand by get_variant
_shipped(
    "water_refraction",
    "the original shader (source 000, section 2): raycast refraction, cube-map sky "
    "reflection, Phong highlight",
)
_shipped(
    "water_refraction_noreflection",
    "the original shader with NOREFLECTION: raycast refraction alone, no sky, no highlight",
)
_shipped("water_reflection", "source 000, section 3: refraction and reflection both raycast")
_shipped(
    "water_refraction_beer",
    "original + Beer-Lambert attenuation per colour channel towards waterColor",
)
_shipped(
    "water_refraction_ggx",
    "original + GGX microfacet highlight (Smith masking) in place of Phong",
)
_shipped("water_refraction_beer_ggx", "original + Beer-Lambert attenuation + GGX highlight")
_shipped(
    "water_refraction_beer_walls",
    "original + Beer-Lambert attenuation + a crossing into a wall above the water shaded as "
    "its submerged face (waterColor), not the wall's top",
)
_shipped(
    "water_refraction_beer_disc_walls",
    "beer_walls with the sun's disc seen in the mirror of the normal in place of Phong (its "
    "angular radius and radiance the scene's sun's)",
)
_shipped(
    "water_refraction_binary",
    "original + REFINE_STEPS binary-search steps after the linear search (relief mapping)",
)
_shipped(
    "water_refraction_secant",
    "original + REFINE_STEPS secant steps after the linear search (parallax occlusion mapping)",
)
_shipped("water_refraction_2layers", "original with two normal-map layers instead of four")
_shipped("water_refraction_1layer", "original with one normal-map layer instead of four")
_shipped("water_refraction_nospecular", "original without the specular highlight")
_shipped(
    "water_refraction_game_textures",
    "original with 8-bit sRGB colour, 8-bit normal map and Fresnel LUT, half-float depth and sky",
)
_shipped(
    "water_reflection_beer_ggx",
    "source 000, section 3 + Beer-Lambert attenuation + GGX highlight",
)
_shipped("water_reflection_beer", "source 000, section 3 + Beer-Lambert attenuation")
_shipped(
    "water_baseline",
    "sources 001-004: planar refraction + normal-map distortion with dispersion of the "
    "screen-space scene, planar reflection distorted by the wave normal",
)
_shipped(
    "water_baseline_flat",
    "sources 001 + 004 (FLAT_WATER): planar refraction and planar reflection of flat water, "
    "no waves",
)
_shipped(
    "water_baseline_noplanar",
    "sources 002-004 (NO_PLANAR_REFRACTION): the classic distorted screen-space refraction "
    "and planar reflection, no 001",
)
