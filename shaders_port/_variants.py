"""The registry of shader variants: one entry per shader the study can fit, time and chart.

A *variant* is a name, one GLSL fragment shader (a file in ``glsl/`` and its Dr.Jit port module
of the same name) and the preprocessor names it is compiled with. The port reads the same names
through its one table ``DEFINES`` (``shaders_port._switches``), so GL, export and port take the
same code path by construction. Everything above this layer (the fit, the sweeps, the tradeoff
chart, export and the GL check) names a shader by its variant name only, so a new shader joins the
study with one file pair and one :func:`register` call here.

``VARIANTS`` maps names to :class:`Variant`, in registration order (the order of charts and
tables). Shipped: 18 variants, registered below: ``water_refraction`` (the original shader,
section 2), ``water_reflection`` (section 3: reflections raycast too), their ``#define`` variants
(Beer-Lambert attenuation, wall faces, GGX, the crossing refinement, fewer normal-map layers,
game-precision textures, no highlight, and ``water_refraction_noreflection``: ``#define
NOREFLECTION``, the refraction alone -- no sky reflection and so no highlight either) and the
game-water baseline ``water_baseline`` with its two ``#define`` variants.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

from ._glsl import read_source, switches_of, with_define


@dataclass(frozen=True)
class Variant:
    """One shader variant.

    Attributes:
        name: registry key; also the file stem of an exported variant.
        shader: GLSL file stem under ``glsl/`` and port module under ``shaders_port``.
        defines: preprocessor names inserted after ``#version`` (GL and export) and decoded by
            the port's ``DEFINES`` table (``render(..., defines=...)``).
        schedule: names of the integer-valued step-schedule constants the variant reads (swept by
            the tradeoff study, never fitted by a gradient).
        description: one line for reports.
        replaces: seed constant -> the variant's constants that take its role in a fit (e.g. the
            Beer-Lambert variant fits ``absorption_r/g/b`` where the seed fits
            ``attenuation_distance``; ``()``: the variant does not read it). See :meth:`fit_names`.
        textures: 'float' (float32 textures, the study's default) or 'game' (the application
            uploads 8-bit colour and half-float depth, ``shaders_port._inputs.game_precision``;
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
            from ._inputs import game_precision

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
        from ._glsl import constants_read

        return tuple(constants_read(self.source()))

    def port(self):
        """The port module (imports Dr.Jit)."""
        return importlib.import_module(f"shaders_port.{self.shader}")

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
        from ._gl import GLRenderer

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


def get_variant(name: str) -> Variant:
    """The registered variant ``name``; a ValueError lists the known names otherwise."""
    try:
        return VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown shader variant {name!r}; known: {', '.join(VARIANTS)}") from None


_RAYCAST = ("steps_grazing", "steps_steep", "loop_cap")

register(
    Variant(
        "water_refraction",
        "water_refraction",
        schedule=_RAYCAST,
        description=(
            "the original shader (source 000, section 2): raycast refraction, cube-map sky "
            "reflection, Phong highlight"
        ),
    )
)
register(
    Variant(
        "water_refraction_noreflection",
        "water_refraction",
        defines=("NOREFLECTION",),
        schedule=_RAYCAST,
        description=(
            "the original shader with NOREFLECTION: raycast refraction and highlight, no sky"
        ),
    )
)
register(
    Variant(
        "water_reflection",
        "water_reflection",
        schedule=_RAYCAST + ("refl_steps_steep", "refl_steps_grazing", "refl_loop_cap"),
        description="source 000, section 3: refraction and reflection both raycast",
    )
)

# ---- variants of the original refraction shader (one GLSL switch each, or a combination) -------
# Each answers one limitation of the original (see shaders_port/README.md, "Variants").
_BEER = {"attenuation_distance": ("absorption_r", "absorption_g", "absorption_b")}
_GGX = {"specular_exponent": ("specular_roughness",)}
_NOSPEC = {"specular_strength": (), "specular_exponent": ()}
_REFINE = _RAYCAST + ("refine_steps",)


def _seed_variant(name, defines, description, schedule=_RAYCAST, replaces=None, textures="float"):
    register(
        Variant(
            name,
            "water_refraction",
            defines=defines,
            schedule=schedule,
            description=description,
            replaces=replaces or {},
            textures=textures,
        )
    )


_seed_variant(
    "water_refraction_beer",
    ("BEER_ATTENUATION",),
    "original + Beer-Lambert attenuation per colour channel towards waterColor",
    replaces=_BEER,
)
_seed_variant(
    "water_refraction_ggx",
    ("GGX_SPECULAR",),
    "original + GGX microfacet highlight (Smith masking) in place of Phong",
    replaces=_GGX,
)
_seed_variant(
    "water_refraction_beer_ggx",
    ("BEER_ATTENUATION", "GGX_SPECULAR"),
    "original + Beer-Lambert attenuation + GGX highlight",
    replaces={**_BEER, **_GGX},
)
_seed_variant(
    "water_refraction_beer_walls",
    ("BEER_ATTENUATION", "WALL_FACES"),
    "original + Beer-Lambert attenuation + a crossing into a wall above the water shaded as "
    "its submerged face (waterColor), not the wall's top",
    replaces=_BEER,
)
_seed_variant(
    "water_refraction_binary",
    ("BINARY_REFINE",),
    "original + REFINE_STEPS binary-search steps after the linear search (relief mapping)",
    schedule=_REFINE,
)
_seed_variant(
    "water_refraction_secant",
    ("SECANT_REFINE",),
    "original + REFINE_STEPS secant steps after the linear search (parallax occlusion mapping)",
    schedule=_REFINE,
)
_seed_variant(
    "water_refraction_2layers",
    ("TWO_NORMAL_LAYERS",),
    "original with two normal-map layers instead of four",
)
_seed_variant(
    "water_refraction_1layer",
    ("ONE_NORMAL_LAYER",),
    "original with one normal-map layer instead of four",
)
_seed_variant(
    "water_refraction_nospecular",
    ("NO_SPECULAR",),
    "original without the specular highlight",
    replaces=_NOSPEC,
)
_seed_variant(
    "water_refraction_game_textures",
    (),
    "original with 8-bit sRGB colour, 8-bit normal map and Fresnel LUT, half-float depth and sky",
    textures="game",
)
register(
    Variant(
        "water_reflection_beer_ggx",
        "water_reflection",
        defines=("BEER_ATTENUATION", "GGX_SPECULAR"),
        schedule=_RAYCAST + ("refl_steps_steep", "refl_steps_grazing", "refl_loop_cap"),
        description="source 000, section 3 + Beer-Lambert attenuation + GGX highlight",
        replaces={**_BEER, **_GGX},
    )
)
register(
    Variant(
        "water_reflection_beer",
        "water_reflection",
        defines=("BEER_ATTENUATION",),
        schedule=_RAYCAST + ("refl_steps_steep", "refl_steps_grazing", "refl_loop_cap"),
        description="source 000, section 3 + Beer-Lambert attenuation",
        replaces=_BEER,
    )
)

# sources 001-004: the baseline game water shader (no raycast, so no step schedule)
_BASELINE_INPUTS = ("scene_color", "scene_depth", "reflection_color", "reflection_view_proj")
_BASELINE_FIT = (
    "refraction_index",
    "refraction_strength",
    "chromatic_dispersion",
    "reflect_distortion",
)
register(
    Variant(
        "water_baseline",
        "water_baseline",
        inputs=_BASELINE_INPUTS,
        fit_parameters=_BASELINE_FIT,
        description="sources 001-004: planar refraction + normal-map distortion with dispersion "
        "of the screen-space scene, planar reflection distorted by the wave normal",
    )
)
register(
    Variant(
        "water_baseline_flat",
        "water_baseline",
        defines=("FLAT_WATER",),
        inputs=_BASELINE_INPUTS,
        fit_parameters=_BASELINE_FIT,
        description="sources 001 + 004 (FLAT_WATER): planar refraction and planar reflection "
        "of flat water, no waves",
    )
)
register(
    Variant(
        "water_baseline_noplanar",
        "water_baseline",
        defines=("NO_PLANAR_REFRACTION",),
        inputs=_BASELINE_INPUTS,
        fit_parameters=_BASELINE_FIT,
        description="sources 002-004 (NO_PLANAR_REFRACTION): the classic distorted "
        "screen-space refraction and planar reflection, no 001",
    )
)
