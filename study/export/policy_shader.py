"""A level-of-detail policy as one fragment shader: each water pixel shaded by the
configuration of its band, the bands blended over a margin (GLSL 330 core).

A policy (``study.studies.lod``) splits the water by a measure of what a pixel needs and gives
each band one configuration of the shader space: a variant of the study's files with its
constants and step schedule. :func:`compose` writes them as one file:

* each band's shader (the variant's file with its defines and its constants written) is
  preprocessed by glslang (``glslangValidator -E``), so its ``#define`` switches are resolved;
* every name the band declares at global scope (functions, ``const`` globals, its ``main``, and
  the tunable constants that are uniforms with initialisers, such as ``waterColor``, which
  become constants of the band) gets the band's prefix ``b<k>_``; its interface (the uniforms
  the application binds, the varyings) is declared once for all bands, and a declaration two
  bands give differently is refused;
* the bands write ``policyColour`` in place of the output, and ``main`` shades a pixel with the
  bands whose weight (:func:`band_weights`) is not zero: one band inside a band, two in a
  margin, where their colours are mixed.

The measures, as ``study.studies.lod.band_measures`` computes them at the image's resolution
(:data:`SHADER_MEASURES`):

* ``distance``: the length of the eye vector ``varyingVecEye`` (world units);
* ``footprint``: the world area of the water plane ``y = 0`` that the pixel covers, in closed
  form from the pixel's ray (``uModelViewProjectionMatrixInverse``, ``screenSize``,
  ``viewpos``: ``study.studies.lod.footprint``), times the pixels of the image
  (``screenSize.x * screenSize.y``), so that one bound holds at every resolution (square world
  units per image).

The margin is a half-width in the natural logarithm of the measure: bands ``k`` and ``k + 1``
mix by ``smoothstep(-margin, margin, log(measure / bound_k))``.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass

import numpy as np

from shaders_port import CONSTANT_SPECS
from shaders_port.glsl_text import write_constants
from shaders_port.inputs import Constants
from shaders_port.variants import get_variant

#: measure -> what the shader computes (its unit)
SHADER_MEASURES = {
    "distance": "length(varyingVecEye): distance from the camera (world units)",
    "footprint": "world area of the water plane the pixel covers times the image's pixels "
    "(square world units per image)",
}
#: the tunable constants that are uniforms with an initialiser: each band keeps its own
BAND_UNIFORMS = frozenset(s[0] for s in CONSTANT_SPECS.values() if s[1].startswith("uniform"))
#: what the policy's own code reads, declared once with the bands' interface
POLICY_INTERFACE = (
    "uniform mat4 uModelViewProjectionMatrixInverse;",
    "uniform vec2 screenSize;",
    "uniform vec3 viewpos;",
    "in vec3 varyingVecEye;",
)
OUTPUT = "policyColour"  # what each band writes in place of the shader's output

_TOKEN = re.compile(
    r"(?P<space>\s+)|(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?[fFuU]?)"
    r"|(?P<name>[A-Za-z_]\w*)|(?P<other>.)",
    re.S,
)


@dataclass(frozen=True)
class Band:
    """One band of a policy: ``variant`` (a name of ``shaders_port.variants``), its
    ``constants`` (``Constants``, the step schedule included) and ``label`` (how reports name
    the configuration)."""

    variant: str
    constants: Constants
    label: str = ""


def preprocess(text: str, label: str) -> str:
    """``text`` (a fragment shader) preprocessed by glslang: switches resolved, comments gone.
    RuntimeError with glslang's log when it fails."""
    exe = shutil.which("glslangValidator")
    if exe is None:
        raise RuntimeError("glslangValidator not found on PATH; run `bash scripts/setup.sh`")
    res = subprocess.run([exe, "-E", "--stdin", "-S", "frag"], input=text, capture_output=True,
                         text=True, timeout=60)  # fmt: skip
    if res.returncode != 0:
        raise RuntimeError(f"glslang could not preprocess {label}:\n{res.stdout}{res.stderr}")
    return res.stdout


def top_level(text: str) -> list[str]:
    """The global-scope statements of preprocessed GLSL ``text`` in order (declarations ending
    in ``;``, function definitions ending in their closing brace), without ``#`` lines."""
    body = "\n".join(ln for ln in text.split("\n") if not ln.lstrip().startswith("#"))
    out, start, depth, i = [], 0, 0, 0
    while i < len(body):
        c = body[i]
        if c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
            head = body[start:i]
            if depth == 0 and "struct" not in head.split("{")[0].split():
                out.append(body[start : i + 1].strip())
                start = i + 1
        elif c == ";" and depth == 0:
            out.append(body[start : i + 1].strip())
            start = i + 1
        i += 1
    if body[start:].strip():
        raise ValueError(f"unterminated statement at the end of the shader: {body[start:][:80]!r}")
    return [s for s in out if s and s != ";"]


def _words(statement: str) -> list[str]:
    return [m.group("name") for m in _TOKEN.finditer(statement) if m.group("name")]


def declared_name(statement: str) -> str:
    """The name a global statement declares: a function's, a struct's, or a variable's (the
    last name before its initialiser or array size)."""
    words = _words(statement)
    if words and words[0] == "struct":
        return words[1]
    head = statement.split("=")[0].rstrip().rstrip(";").rstrip()
    if ("(" in head and "{" in statement) or head.endswith(")"):
        return _words(statement.split("(")[0])[-1]
    return _words(head.split("[")[0].rstrip(";"))[-1]


def is_interface(statement: str) -> bool:
    """Whether a global statement is the shader's interface (a uniform the application binds,
    an ``in`` or ``out`` variable) rather than the band's own code."""
    words = _words(statement.split("=")[0])
    if "uniform" in words:
        return declared_name(statement) not in BAND_UNIFORMS
    return bool(words) and words[0] in ("in", "out", "layout", "flat", "smooth")


def _normalised(statement: str) -> str:
    return " ".join(statement.split("=")[0].replace(";", " ").split())


def renamed(statement: str, names: set, prefix: str, output: str) -> str:
    """``statement`` with each name of ``names`` prefixed by ``prefix`` and the output
    ``output`` written as :data:`OUTPUT`; a name after ``.`` (a field or swizzle) and a
    struct's member declarations are kept."""
    parts, prev, depth = [], "", 0
    members = _words(statement)[:1] == ["struct"]
    for m in _TOKEN.finditer(statement):
        tok = m.group(0)
        depth += (tok == "{") - (tok == "}")
        if m.group("name") and prev != "." and not (members and depth > 0):
            if tok == output:
                tok = OUTPUT
            elif tok in names:
                tok = prefix + tok
        parts.append(tok)
        if not m.group("space"):
            prev = tok
    return "".join(parts)


def band_source(band: Band) -> str:
    """The band's shader as its export writes it: the variant's file with the band's constants
    and the variant's defines."""
    return write_constants(get_variant(band.variant).source(), band.constants)


def compose(bands: list[Band], measure: str, bounds: list[float], margin: float) -> str:
    """The policy's fragment shader (GLSL 330 core, module docstring): ``bands`` (one per band,
    in the measure's order), ``bounds`` (len(bands) - 1 increasing values of ``measure``, a
    name of :data:`SHADER_MEASURES`, in the shader's unit) and ``margin`` (the blend's
    half-width in the log of the measure, > 0 and below half the log of the ratio of adjacent
    bounds). ValueError names what does not fit."""
    check_policy(measure, bounds, margin, len(bands))
    shared: dict[str, str] = {}  # name -> declaration
    for line in POLICY_INTERFACE:
        shared[declared_name(line)] = line
    sections, output = [], None
    for k, band in enumerate(bands):
        text = preprocess(band_source(band), f"band {k} ({band.variant})")
        own, names = [], set()
        for st in top_level(text):
            if is_interface(st):
                name = declared_name(st)
                if _words(st)[0] == "out":
                    output = output or name
                    if name != output:
                        raise ValueError(f"band {k} writes {name!r}, an earlier band {output!r}")
                old = shared.setdefault(name, st)
                if _normalised(old) != _normalised(st):
                    raise ValueError(
                        f"band {k} ({band.variant}) declares {name!r} as {st!r}, another band "
                        f"as {old!r}: the bands must share their interface"
                    )
            else:  # a tunable uniform becomes a constant of its band (GLSL ES has no
                # uniform initialisers)
                own.append(re.sub(r"^\s*uniform\b", "const", st))
                names.add(declared_name(st))
        body = "\n".join(renamed(st, names, f"b{k}_", output or "fragColor") for st in own)
        sections.append(f"// ---- band {k}: {band.label or band.variant} ----\n{body}\n")
    return "\n".join(
        [
            "#version 330 core",
            f"// A level-of-detail policy of {len(bands)} bands by {measure} "
            "(study.export.policy_shader); band k's names carry the prefix b<k>_.",
            *shared.values(),
            f"vec4 {OUTPUT};",
            *sections,
            _policy_main(len(bands), measure, bounds, margin, output or "fragColor"),
        ]
    )


def check_policy(measure: str, bounds, margin: float, n_bands: int) -> None:
    """ValueError when the measure is unknown, the bounds are not ``n_bands - 1`` increasing
    positive values, or the margin is not positive or makes two margins overlap."""
    if measure not in SHADER_MEASURES:
        raise ValueError(f"unknown measure {measure!r}; known: {sorted(SHADER_MEASURES)}")
    b = np.asarray(bounds, np.float64)
    if n_bands < 1 or len(b) != n_bands - 1:
        raise ValueError(f"{n_bands} band(s) need {n_bands - 1} bound(s), got {len(b)}")
    if len(b) and (not np.all(b > 0) or not np.all(np.isfinite(b))):
        raise ValueError(f"the bounds must be positive and finite, got {list(b)}")
    if not margin > 0:
        raise ValueError(f"the margin must be positive, got {margin}")
    gaps = np.diff(np.log(b)) if len(b) > 1 else np.array([np.inf])
    if not np.all(gaps > 2 * margin):
        raise ValueError(
            f"margins of +-{margin:g} (log of the measure) overlap between bounds {list(b)}: "
            "use a smaller margin (study.studies.lod_export.margin_for)"
        )


def _policy_main(n: int, measure: str, bounds, margin: float, output: str) -> str:
    """The policy's measure, weights and ``main`` (which writes ``output``)."""
    lines = ["// ---- the policy ----"]
    lines += [f"const float POLICY_BOUND_{j} = {float(v)!r};" for j, v in enumerate(bounds)]
    lines += [f"const float POLICY_MARGIN = {float(margin)!r};", "float policyMeasure()", "{"]
    if measure == "distance":
        lines.append("    return length(varyingVecEye);")
    else:  # the closed form of study.studies.lod.footprint
        lines += [
            "    mat4 inv = uModelViewProjectionMatrixInverse;",
            "    vec4 h = inv * vec4(2.0 * gl_FragCoord.xy / screenSize - 1.0, 1.0, 1.0);",
            "    vec4 hx = inv[0] * (2.0 / screenSize.x);",
            "    vec4 hy = inv[1] * (2.0 / screenSize.y);",
            "    vec3 ray = h.xyz - h.w * viewpos;",
            "    vec3 rx = hx.xyz - hx.w * viewpos;",
            "    vec3 ry = hy.xyz - hy.w * viewpos;",
            "    float t = -viewpos.y / ray.y;",
            "    vec3 px = t * (rx - (rx.y / ray.y) * ray);",
            "    vec3 py = t * (ry - (ry.y / ray.y) * ray);",
            "    return length(cross(px, py)) * screenSize.x * screenSize.y;",
        ]
    lines += ["}", "void main(void)", "{", "    float lm = log(policyMeasure());"]
    for j in range(n - 1):
        blend = f"smoothstep(-POLICY_MARGIN, POLICY_MARGIN, lm - log(POLICY_BOUND_{j}))"
        lines.append(f"    float t{j} = {blend};")
    lines += ["    vec4 acc = vec4(0.0);", "    float w;"]
    for k in range(n):
        lo = "1.0" if k == 0 else f"t{k - 1}"
        hi = "" if k == n - 1 else f" - t{k}"
        lines += [f"    w = {lo}{hi};", f"    if (w > 0.0) {{ b{k}_main(); acc += w * {OUTPUT}; }}"]
    lines += [f"    {output} = acc;", "}", ""]
    return "\n".join(lines)


def band_weights(measure: np.ndarray, bounds, margin: float) -> np.ndarray:
    """(K, ...) float64 weights of K = len(bounds) + 1 bands at ``measure`` (any shape; NaN
    gives NaN), as the shader computes them: band k's weight is ``t_{k-1} - t_k`` with
    ``t_j = smoothstep(-margin, margin, log(measure / bound_j))`` (``t_{-1} = 1``,
    ``t_{K-1} = 0``). The weights sum to 1 and are zero outside a band and its margins."""
    lm = np.log(np.asarray(measure, np.float64))
    ts = []
    for b in bounds:
        x = np.clip((lm - np.log(b) + margin) / (2 * margin), 0.0, 1.0)
        ts.append(x * x * (3 - 2 * x))
    ones = np.ones_like(lm)
    t = [ones, *ts, np.zeros_like(lm)]
    return np.stack([t[k] - t[k + 1] for k in range(len(bounds) + 1)])
