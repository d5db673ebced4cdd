"""A user's shader in the dialect it was written in, made the core GLSL glslang compiles.

glslang makes SPIR-V for OpenGL only from desktop GLSL 330 and GLSL ES 310. A shader written
for an older OpenGL, for WebGL 1 or WebGL 2 is translated first, as text, into ``#version 330
core`` (:func:`front_end`); every message quotes the user's own file and line numbers.

Dialects, from the ``#version`` directive (:func:`detect`):

* none: GLSL ES 1.00 (WebGL 1) when the file has a ``precision`` statement or names
  ``GL_ES`` (a WebGL 1 fragment shader must declare the precision of ``float``); otherwise
  desktop GLSL 1.10, the version the GLSL specification gives a file without ``#version``;
* ``#version 110`` ... ``150`` (any profile), ``#version 100`` (GLSL ES 1.00) and
  ``#version 300 es`` (WebGL 2), and ``#version 330`` ... ``460 compatibility``: translated;
* ``#version 330`` ... ``460`` (``core`` or no profile): compiled as written;
* ``#version 310 es`` / ``320 es``: compiled as written (glslang makes their SPIR-V); they
  have no translation (the GL check runs them on an OpenGL ES context, ``spirv.gl_run``).

Anything else (``#version 200``, ``#version 130 es``, a ``#version`` after other code, ...)
is refused with a :class:`ShaderError` naming the line.

A translated file is first compiled by glslang in its own dialect (no SPIR-V: glslang checks
every dialect), so a mistake is reported as the dialect's compiler reports it. The
translation then:

* replaces the ``#version`` line by ``#version 330 core`` and puts after it the declarations
  the file needs (an ``out vec4`` for ``gl_FragColor``, the study's varyings and matrices the
  compatibility built-ins become), then a ``#line`` directive, so that every following line
  keeps its number;
* runs glslang's preprocessor (``glslangValidator -E``: the experiment's ``#define`` s and
  ``#include`` files expanded, comments removed) and on its tokens:
  ``varying`` -> ``in``; ``gl_FragColor`` and ``gl_FragData[0]`` -> the ``out vec4``;
  ``texture2D``, ``textureCube``, ``texture3D`` -> ``texture``; ``texture2DProj`` ->
  ``textureProj``; ``texture2DLod``, ``textureCubeLod`` (and their ``EXT`` forms) ->
  ``textureLod``; ``texture2DGradEXT`` -> ``textureGrad``; ``gl_FragDepthEXT`` ->
  ``gl_FragDepth``; ``gl_TexCoord[i]`` (i = 0..3) -> the study's ``vTexCoord<i>`` (the
  texture coordinates ``water.vert`` writes); ``gl_ModelViewProjectionMatrix`` (and its
  ``Inverse``) -> ``uModelViewProjectionMatrix`` (the study's world -> clip matrix: the
  water's model matrix is the identity); ``gl_NormalMatrix`` -> ``uNormalMatrix``;
  in GLSL ES 1.00 and GLSL 1.10/1.20, user names that are keywords or built-in functions of
  GLSL 330 (``texture``, ``layout``, ``flat``, ``smooth``, ``uint``, ...) get a ``_u_``
  prefix; the WebGL extensions that
  GLSL 330 has built in (``GL_OES_standard_derivatives``, ``GL_EXT_shader_texture_lod``,
  ``GL_EXT_frag_depth``) lose their ``#extension`` line. ``precision`` statements and
  qualifiers stay: GLSL 330 accepts and ignores them.

Refused, with the reason: ``gl_FragData[i]`` for i > 0 (the study compares one colour),
``ftransform()`` and ``attribute`` (vertex shader only), ``shadow2D`` and the other
compatibility built-ins (``gl_ModelViewMatrix``, ``gl_LightSource``, ``gl_Color``, ...: the
study's vertex shader gives no such value; declare a uniform and bind it to a study input).

A vertex shader (``front_end(..., stage="vert")``) is translated alike, with ``attribute``
-> ``in``, ``varying`` -> ``out``, ``gl_TexCoord[i]`` -> ``out vec4 vTexCoord<i>`` and its
compatibility attributes and matrices -> names of ``spirv.engine_names`` that bind themselves
(:data:`_VERTEX_BUILTINS`; ``ftransform()`` -> ``gl_ModelViewProjectionMatrix * gl_Vertex``
in them); any other compatibility built-in is refused at its line.

A file without ``#version`` takes the version line its engine puts before it from a define
``"#version N"`` (:func:`version_define`); a define ``"!NAME"`` leaves the function ``NAME``
out (:func:`omit_functions`: the other stage's entry point of a file compiled for both).

The file is preprocessed in its own version: ``__VERSION__`` reads the version the file was
written for (an engine's ``#if __VERSION__ >= 130`` takes the branch it takes in the engine)
and ``GL_ES`` is defined for the GLSL ES dialects, as their compilers define it.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "Dialect",
    "ShaderError",
    "at_highp",
    "detect",
    "for_opengl",
    "without_file_lines",
    "front_end",
    "glslang_errors",
    "has_includes",
]

TARGET = "#version 330 core"
DESKTOP = (110, 120, 130, 140, 150, 330, 400, 410, 420, 430, 440, 450, 460)
INCLUDE_EXT = "#extension GL_GOOGLE_include_directive : require"
MAX_ERRORS = 8  # glslang error lines kept in a message
_VERSION = re.compile(r"^[ \t]*#[ \t]*version\b[ \t]*(?P<rest>[^\n]*)$", re.M)
COMMENTS = re.compile(r"//[^\n]*|/\*.*?\*/", re.S)
_INCLUDE_LINE = re.compile(r"^[ \t]*#[ \t]*(?:include|import)\b", re.M)
_RENAMES = {
    "texture2D": "texture",
    "textureCube": "texture",
    "texture3D": "texture",
    "texture1D": "texture",
    "texture2DProj": "textureProj",
    "texture2DLod": "textureLod",
    "textureCubeLod": "textureLod",
    "texture2DLodEXT": "textureLod",
    "textureCubeLodEXT": "textureLod",
    "texture2DProjLodEXT": "textureProjLod",
    "texture2DGradEXT": "textureGrad",
    "textureCubeGradEXT": "textureGrad",
    "gl_FragDepthEXT": "gl_FragDepth",
    "varying": "in",
}
# names a legacy file may use that GLSL 330 takes as a keyword or built-in function
_RESERVED = ("texture", "layout", "flat", "smooth", "noperspective", "centroid", "uint", "uvec2",
             "uvec3", "uvec4", "textureProj", "textureLod", "textureGrad", "sample")  # fmt: skip
# compatibility built-ins -> (study name, declaration)
_BUILTINS = {
    "gl_ModelViewProjectionMatrixInverse": ("uModelViewProjectionMatrixInverse", "uniform mat4"),
    "gl_ModelViewProjectionMatrix": ("uModelViewProjectionMatrix", "uniform mat4"),
    "gl_NormalMatrix": ("uNormalMatrix", "uniform mat3"),
}
_CORE_BUILTINS = {"gl_FragCoord", "gl_FrontFacing", "gl_PointCoord", "gl_FragDepth"}
# a vertex shader's compatibility built-ins -> (a name that binds itself to the grid's value
# or the frame's matrix, ``spirv.engine_names``; its declaration)
_VERTEX_BUILTINS = {
    "gl_Vertex": ("aVertex", "in vec4"),
    "gl_MultiTexCoord0": ("aMultiTexCoord0", "in vec4"),
    "gl_Normal": ("inNormal", "in vec3"),
    "gl_ModelViewProjectionMatrix": ("uModelViewProjectionMatrix", "uniform mat4"),
    "gl_ModelViewMatrix": ("g_WorldViewMatrix", "uniform mat4"),
    "gl_ProjectionMatrix": ("g_ProjectionMatrix", "uniform mat4"),
    "gl_NormalMatrix": ("g_NormalMatrix", "uniform mat3"),
}
# the translation's attribute name -> the compatibility built-in attribute it stands for
BUILTIN_ATTRIBUTES = {new: old for old, (new, d) in _VERTEX_BUILTINS.items() if d.startswith("in ")}
_FTRANSFORM = re.compile(r"\bftransform\s*\(\s*\)")
_VERTEX_CORE = {"gl_Position", "gl_PointSize", "gl_VertexID", "gl_InstanceID", "gl_ClipDistance"}
_CORE_EXTENSIONS = ("GL_OES_standard_derivatives", "GL_EXT_shader_texture_lod", "GL_EXT_frag_depth")
OUT = "_study_FragColor"


class ShaderError(ValueError):
    """A user's shader that cannot be compiled or run as written; the message names its file
    and line and what to change."""


@dataclass(frozen=True)
class Dialect:
    """The language of a fragment shader: ``version`` (100, 110, ..., 460), ``es`` (GLSL ES),
    ``profile`` ('core', 'compatibility', 'es'), ``line``: the line of its ``#version``
    directive (0: none)."""

    version: int
    es: bool
    profile: str
    line: int

    @property
    def name(self) -> str:
        if self.es:
            return f"GLSL ES {self.version // 100}.{self.version % 100:02d}"
        if self.version < 330:
            return f"GLSL {self.version // 100}.{self.version % 100:02d}"
        return f"GLSL {self.version} {self.profile}"

    def _replace_line(self, line: int) -> "Dialect":
        return Dialect(self.version, self.es, self.profile, line)

    @property
    def translated(self) -> bool:
        """Whether the file is translated to GLSL 330 core (else compiled as written)."""
        if self.es:
            return self.version in (100, 300)
        return self.version < 330 or self.profile == "compatibility"

    @property
    def runs_on_desktop_gl(self) -> bool:
        """Whether the text compiled (as written or translated) runs on a desktop OpenGL."""
        return not (self.es and self.version >= 310)


def has_includes(text: str) -> bool:
    """Whether ``text`` has an ``#include`` (or jMonkeyEngine's ``#import``) line."""
    return _INCLUDE_LINE.search(text) is not None


def detect(source: str, label: str, version: str | None = None) -> Dialect:
    """The dialect of ``source`` (module doc); ShaderError for a ``#version`` glslang's
    compilers do not know or one that is not the file's first directive. ``version``: the
    ``#version`` line an engine puts before the file (:func:`version_define`; the file then has
    none of its own)."""
    m = _VERSION.search(source)
    if version is not None:
        if m is not None:
            raise ShaderError(
                f"{label}: the file has its own #version; remove the define `{version}`"
            )
        return detect(version, label)._replace_line(0)
    if m is None:
        code = COMMENTS.sub(" ", source)
        es = bool(re.search(r"\bprecision\s+(lowp|mediump|highp)\b|\bGL_ES\b", code))
        return Dialect(100, True, "es", 0) if es else Dialect(110, False, "compatibility", 0)
    line = source.count("\n", 0, m.start()) + 1
    before = COMMENTS.sub(" ", source[: m.start()])
    where = f"{label}:{line}"
    if before.strip():
        raise ShaderError(f"{where}: #version must come before anything else in the file")
    parts = COMMENTS.sub(" ", m["rest"]).split()
    ok = parts and parts[0].isdigit() and len(parts) <= 2
    version = int(parts[0]) if ok else -1
    profile = parts[1] if ok and len(parts) == 2 else None
    if version in (100, 300, 310, 320) and (profile == "es" or version == 100) and profile in (
        None, "es"):  # fmt: skip
        return Dialect(version, True, "es", line)
    if version in DESKTOP and profile in (None, "core", "compatibility"):
        default = "core" if version >= 150 else "compatibility"
        return Dialect(version, False, profile or default, line)
    raise ShaderError(
        f"{where}: '#version {m['rest'].strip()}' is no version of GLSL this tool compiles; use "
        "100 or 300 es (WebGL), 310 es or 320 es, 110-150, or 330-460 (core or compatibility)"
    )


def _tool() -> str:
    exe = shutil.which("glslangValidator")
    if exe is None:
        raise RuntimeError(
            "glslangValidator not found on PATH; install it with `apt-get install "
            "glslang-tools` (scripts/setup.sh does)"
        )
    return exe


def glslang_errors(log: str, label: str, include_paths=()) -> str:
    """The error lines of a glslang log, at most :data:`MAX_ERRORS` (the file name line, the
    summary and the linker's lines left out); an include that was not found gets the folders
    searched."""
    lines = [ln.strip() for ln in log.splitlines()]
    errs = [ln for ln in lines if re.match(r"ERROR: [^:]+:\d+:", ln)]
    other = [ln for ln in lines if ln.startswith("ERROR:") and "compilation errors" not in ln]
    errs = errs or [ln for ln in other if "Linking" not in ln] or [ln for ln in lines if ln]
    out = []
    for e in errs[:MAX_ERRORS]:
        e = e.removeprefix("ERROR: ")
        if "Could not process include directive" in e:
            searched = ", ".join(str(p) for p in include_paths) or "no folder"
            e += f" (searched {searched}; add the folder that holds it to fit.include_paths)"
        out.append(e)
    more = len(errs) - MAX_ERRORS
    return "\n".join(out) + (f"\n... and {more} more errors" if more > 0 else "")


def _glslang(
    text: str, label: str, args: list[str], include_paths, what: str, stage: str = "frag"
) -> str:
    """Run glslangValidator on ``text`` saved as ``label``'s file name in a temporary folder
    (the working directory), as a shader of ``stage`` ('frag' or 'vert'): its stdout;
    ShaderError with the errors (:func:`glslang_errors`)."""
    name = Path(label).name
    name = name if name.endswith(f".{stage}") else f"{name}.{stage}"
    with tempfile.TemporaryDirectory(prefix="spirv-front.") as d:
        (Path(d) / name).write_text(text, encoding="utf-8")
        incs = [f"-I{Path(p).resolve()}" for p in include_paths]
        res = subprocess.run([_tool(), *args, *incs, "-S", stage, name], cwd=d,
                             capture_output=True, text=True, timeout=120, check=False)  # fmt: skip
        if res.returncode != 0:
            log = (res.stdout + res.stderr).replace(name, Path(label).name)
            raise ShaderError(
                f"{label} does not compile ({what}):\n" + glslang_errors(log, label, include_paths)
            )
        return res.stdout.replace(f'"{name}"', f'"{Path(label).name}"')


def _line_directive(next_line: int, version: int, es: bool) -> str:
    """A ``#line`` after which the next line is ``next_line`` (glslang: desktop GLSL before
    330 numbers the directive's own line)."""
    sets_next = es or version >= 330
    return f"#line {next_line if sets_next else next_line - 1}"


def _with_head(source: str, d: Dialect, version_line: str, head: list[str]) -> str:
    """``source`` with its ``#version`` line replaced by ``version_line`` (or that line put
    first), ``head`` after it, then a ``#line`` so that the file's lines keep their numbers
    (in the numbering of ``version_line``'s version)."""
    v = int(version_line.split()[1])
    es = version_line.endswith(" es") or v == 100
    lines = source.split("\n")
    if d.line:
        pre, rest, nxt = lines[: d.line - 1], lines[d.line :], d.line + 1
        pre = ["" for _ in pre]  # comments before #version: blank (their lines are kept)
    else:
        pre, rest, nxt = [], lines, 1
    return "\n".join([version_line, *head, _line_directive(nxt, v, es), *pre, *rest])


def _own_version_line(d: Dialect) -> str:
    if d.es:
        return "#version 100" if d.version == 100 else f"#version {d.version} es"
    return f"#version {d.version}" + (f" {d.profile}" if d.version >= 150 else "")


def split_defines(defines) -> tuple[tuple, tuple]:
    """``(preprocessor names, functions to leave out)`` of a stage's defines: an entry
    ``"!NAME"`` leaves the function ``NAME`` out of the stage (as Urho3D's loader comments out
    the other stage's entry point of a file compiled for both), an entry ``"#version ..."`` is
    the version line (:func:`detect`), any other is a ``#define``."""
    names = tuple(str(d) for d in defines if not str(d).startswith("#"))
    return (tuple(d for d in names if not d.startswith("!")),
            tuple(d[1:] for d in names if d.startswith("!")))  # fmt: skip


def version_define(defines) -> str | None:
    """The ``"#version ..."`` entry of a stage's defines (the line an engine puts before a file
    that has none: Urho3D's ``#version 150`` on its GL3 path), or None."""
    lines = [str(d) for d in defines if str(d).startswith("#")]
    if len(lines) > 1 or (lines and not re.fullmatch(r"#version[ \t]+\d+([ \t]+\w+)?", lines[0])):
        raise ShaderError(f"{lines}: give one define `#version N` or `#version N es|core|...`")
    return lines[0] if lines else None


def omit_functions(source: str, names) -> str:
    """``source`` with the definition of each function of ``names`` (``TYPE NAME(...) {...}``
    at file scope) blanked out, its newlines kept (every other line keeps its number)."""
    for name in names:
        code = COMMENTS.sub(lambda m: re.sub(r"[^\n]", " ", m[0]), source)
        m = re.search(rf"^[ \t]*\w+[ \t]+{re.escape(name)}[ \t]*\([^)]*\)\s*\{{", code, re.M)
        if m is None:
            raise ShaderError(f"!{name}: the file defines no function {name}() to leave out")
        depth, k = 1, m.end()
        while depth and k < len(code):
            depth += {"{": 1, "}": -1}.get(code[k], 0)
            k += 1
        body = re.sub(r"[^\n]", " ", source[m.start() : k])
        source = source[: m.start()] + body + source[k:]
    return source


def front_end(
    source: str,
    label: str,
    defines=(),
    include_paths=(),
    preprocess=False,
    stage: str = "frag",
    translate: bool = True,
) -> str:
    """The GLSL glslang compiles to SPIR-V for ``source`` (a shader of ``stage`` 'frag' or
    'vert' in any dialect of the module doc, file name ``label``), with the preprocessor names
    ``defines`` (``NAME`` or ``NAME=VALUE``; ``!NAME`` leaves function ``NAME`` out,
    :func:`split_defines`) and ``#include`` files searched in
    ``include_paths`` (after the including file's folder). A GLSL 330+ core or GLSL ES 310+
    file without ``#include`` is returned as it is (its defines are given to glslang when it
    is compiled) unless ``preprocess`` (for an OpenGL driver, which takes no defines); any
    other is preprocessed by glslang (``#include`` s expanded, defines applied, comments
    removed) with ``#line`` directives keeping the file's line numbers, and translated to GLSL
    330 core if its dialect needs it and ``translate`` (False: the file in its own dialect, for
    a context that runs that dialect: ``gl.contexts``). ShaderError for a file that does not
    compile in its own dialect or uses what the translation refuses, naming the file and
    line."""
    version = version_define(defines)
    defines, omitted = split_defines(defines)
    source = omit_functions(source, omitted)
    # jMonkeyEngine's `#import "Common/ShaderLib/X.glsllib"` is its loader's #include
    source = re.sub(r'^([ \t]*#[ \t]*)import([ \t]+")', r"\1include\2", source, flags=re.M)
    # `#include <name>` (three.js's chunks): glslang's includer searches only quoted names
    source = re.sub(r"^([ \t]*#[ \t]*include[ \t]*)<([^>\n]+)>", r'\1"\2"', source, flags=re.M)
    d = detect(source, label, version)
    includes = has_includes(source)  # after #import is written #include
    dargs = [f"-D{x}" for x in defines]
    clean = _unshadowed if d.es else (lambda text: text)
    if not (d.translated and translate):
        if not (includes or preprocess):
            own = source if version is None else _with_head(source, d, _own_version_line(d), [])
            return clean(own)
        head = [INCLUDE_EXT] if includes else []
        text = _with_head(source, d, _own_version_line(d), head)
        return clean(_glslang(text, label, ["-E", *dargs], include_paths, "preprocessing", stage))
    own = _with_head(source, d, _own_version_line(d), [INCLUDE_EXT] if includes else [])
    if d.es:  # the dialect's verdict on the text with the user's functions kept apart
        own = clean(_glslang(own, label, ["-E", *dargs], include_paths, "preprocessing", stage))
        _glslang(own, label, ["-l"], (), d.name, stage)
    else:
        _glslang(own, label, ["-l", *dargs], include_paths, d.name, stage)
    code = COMMENTS.sub(lambda m: re.sub(r"[^\n]", " ", m[0]), source)
    decls = _declarations(code, stage)
    head = [INCLUDE_EXT] if includes else []
    text = _with_head(source, d, _own_version_line(d), head + decls)
    pre = _glslang(text, label, ["-E", *dargs], include_paths, "preprocessing", stage)
    pre = _as_target(clean(pre), d)
    legacy = d.version == 100 if d.es else d.version < 130  # before texture() and layout
    return _translate_tokens(pre, label, len(head) + len(decls), legacy, stage)


# functions glslang declares in its GLSL ES 3.x tables without their extension
# (GL_INTEL_shader_integer_functions2) being enabled: a user's function of one of these names
# (three.js's `average` in its `common` chunk) is refused as a redeclaration there, though the
# ES specification reserves none of them
_GLSLANG_EXTENSION_FUNCTIONS = ("absoluteDifference", "addSaturate", "average", "averageRounded",
                                "countLeadingZeros", "countTrailingZeros", "multiply32x16",
                                "subtractSaturate")  # fmt: skip


def _unshadowed(text: str) -> str:
    """GLSL ES ``text`` with each function of :data:`_GLSLANG_EXTENSION_FUNCTIONS` it defines
    itself named ``_u_NAME`` (every use too), so that glslang compiles it as the ES
    specification and the drivers do."""
    for name in _GLSLANG_EXTENSION_FUNCTIONS:
        if re.search(rf"\b\w+\s+{name}\s*\([^;{{}}]*\)\s*\{{", text):
            text = re.sub(rf"\b{name}\b", f"_u_{name}", text)
    return text


def _as_target(pre: str, d: Dialect) -> str:
    """glslang's preprocessed text ``pre`` of a file of dialect ``d`` (preprocessed in its own
    version, so ``__VERSION__`` and ``GL_ES`` read what its compiler gives: an engine's
    ``#if __VERSION__ >= 130`` takes the branch it takes in the engine) with its ``#version``
    line made :data:`TARGET` and its ``#line`` directives in GLSL 330's numbering."""
    lines = pre.split("\n")
    lines[0] = TARGET
    if not (d.es or d.version >= 330):  # `#line N` numbered the directive's own line
        for k, ln in enumerate(lines):
            m = re.match(r"(\s*#\s*line\s+)(\d+)(.*)", ln)
            if m:
                lines[k] = f"{m[1]}{int(m[2]) + 1}{m[3]}"
    return "\n".join(lines)


def _declarations(code: str, stage: str) -> list[str]:
    """The declarations a translated file of ``stage`` needs for the compatibility names its
    ``code`` (comments blanked) uses: the colour output, the texture coordinates, the
    matrices and attributes they become (a name the file declares itself is left to it)."""
    frag = stage == "frag"
    decls = [f"out vec4 {OUT};"] if frag and re.search(r"\bgl_Frag(Color|Data)\b", code) else []
    for i in range(4):
        if re.search(rf"\bgl_TexCoord\s*\[\s*{i}\s*\]", code) and not re.search(
            rf"\bvTexCoord{i}\b", code
        ):
            decls.append(f"{'in' if frag else 'out'} vec4 vTexCoord{i};")
    if not frag and _FTRANSFORM.search(code):
        code += " gl_Vertex gl_ModelViewProjectionMatrix"
    for old, (new, decl) in (_BUILTINS if frag else _VERTEX_BUILTINS).items():
        if re.search(rf"\b{old}\b", code) and not re.search(rf"\b{new}\b", code):
            decls.append(f"{decl} {new};")
    return decls


def _translate_tokens(pre: str, label: str, n_head: int, legacy: bool, stage: str) -> str:
    """The preprocessed text ``pre`` (``#version 330 core``, the head of ``n_head`` lines, then
    the file) with the legacy names of the module doc rewritten; ShaderError for a refused
    one, at its file and line."""
    lines = pre.split("\n")
    where = _line_map(lines, label)
    out = lines[: 1 + n_head]
    for k in range(1 + n_head, len(lines)):
        ln = lines[k]
        if re.match(r"\s*#\s*extension\s+(" + "|".join(_CORE_EXTENSIONS) + r")\b", ln):
            out.append("")
            continue
        if ln.lstrip().startswith("#"):
            out.append(ln)
            continue
        rewrite = _rewrite_line if stage == "frag" else _rewrite_vertex_line
        out.append(rewrite(ln, where[k], legacy))
    if not re.search(rf"\b{OUT}\b", "\n".join(out[1 + n_head :])):
        # gl_FragColor a macro of the file's own output (Urho3D's `fragData[0]`): the colour
        # output declared for it is never written, and is left out (its line kept, blank)
        out[: 1 + n_head] = ["" if h == f"out vec4 {OUT};" else h for h in out[: 1 + n_head]]
    return "\n".join(out)


def _rewrite_line(ln: str, where: str, legacy: bool) -> str:
    def refuse(msg):
        raise ShaderError(f"{where}: {msg}")

    m = re.search(r"\bgl_FragData\s*\[\s*([^\]]*)\]", ln)
    while m is not None:
        if m[1].strip() not in ("0", "0u"):
            refuse(
                f"gl_FragData[{m[1].strip()}]: the study compares one colour; write it to "
                "gl_FragData[0] or gl_FragColor"
            )
        ln = ln[: m.start()] + OUT + ln[m.end() :]
        m = re.search(r"\bgl_FragData\s*\[\s*([^\]]*)\]", ln)
    ln = re.sub(r"\bgl_FragColor\b", OUT, ln)
    ln = re.sub(r"\bgl_TexCoord\s*\[\s*([0-3])\s*\]", r"vTexCoord\1", ln)
    if re.search(r"\bgl_TexCoord\b", ln):
        refuse("gl_TexCoord: only gl_TexCoord[0] ... gl_TexCoord[3] with a constant index")
    if re.search(r"\bftransform\b", ln):
        refuse("ftransform() is a vertex shader function; a fragment shader cannot call it")
    if re.search(r"\bshadow(1D|2D)\w*\b", ln):
        refuse("shadow samplers: the study has no depth texture to compare against")
    for old, (new, _) in _BUILTINS.items():
        ln = re.sub(rf"\b{old}\b", new, ln)
    for name in re.findall(r"\bgl_\w+", ln):
        if name not in _CORE_BUILTINS and not name.startswith("gl_Max"):
            refuse(
                f"{name}: a compatibility built-in the study's vertex shader gives no value of; "
                "declare a uniform or varying of your own and bind it to a study input "
                "(`// @study bind NAME INPUT`)"
            )
    for name in _RESERVED if legacy else ():
        ln = re.sub(rf"\b{name}\b", f"_u_{name}", ln)
    for old, new in _RENAMES.items():
        ln = re.sub(rf"\b{old}\b", new, ln)
    return ln


def _rewrite_vertex_line(ln: str, where: str, legacy: bool) -> str:
    """A line of a vertex shader: ``attribute`` -> ``in``, ``varying`` -> ``out``,
    ``ftransform()`` -> ``(uModelViewProjectionMatrix * aVertex)``, ``gl_TexCoord[i]`` ->
    ``vTexCoord<i>``, the compatibility attributes and matrices -> the names of
    :data:`_VERTEX_BUILTINS` (which bind themselves); ShaderError for another one."""
    ln = _FTRANSFORM.sub("(gl_ModelViewProjectionMatrix * gl_Vertex)", ln)
    ln = re.sub(r"\bgl_TexCoord\s*\[\s*([0-3])\s*\]", r"vTexCoord\1", ln)
    for old, (new, _) in _VERTEX_BUILTINS.items():
        ln = re.sub(rf"\b{old}\b", new, ln)
    for name in re.findall(r"\bgl_\w+", ln):
        if name not in _VERTEX_CORE and not name.startswith("gl_Max"):
            raise ShaderError(
                f"{where}: {name}: a compatibility built-in the water grid gives no value of "
                f"(it gives {', '.join(_VERTEX_BUILTINS)}, ftransform() and gl_TexCoord[0..3]); "
                "declare an attribute or uniform of your own and bind it "
                "(`// @study bind NAME MEANING`)"
            )
    for name in _RESERVED if legacy else ():
        ln = re.sub(rf"\b{name}\b", f"_u_{name}", ln)
    ln = re.sub(r"\battribute\b", "in", ln)
    ln = re.sub(r"\bvarying\b", "out", ln)
    for old, new in _RENAMES.items():
        ln = re.sub(rf"\b{old}\b", new, ln)
    return ln


def _line_map(lines: list[str], label: str) -> list[str]:
    """``file:line`` of each line of preprocessed GLSL 330 text (``#line N ["file"]``
    directives: the next line is N)."""
    out, file, cur = [], label, 1
    for ln in lines:
        m = re.match(r'\s*#\s*line\s+(\d+)(?:\s+"([^"]*)")?', ln)
        out.append(f"{file}:{cur}")
        if m:
            cur, file = int(m[1]), (m[2] or file)
            continue
        cur += 1
    return out


# read every precision qualifier of a GLSL ES text as highp, and make highp the default of
# every type that has one (GLSL ES samplers default to lowp)
_HIGHP = [
    "#define lowp highp",
    "#define mediump highp",
    *(f"precision highp {t};" for t in ("float", "int", "sampler2D", "samplerCube")),
]


def at_highp(text: str, label: str) -> str:
    """A GLSL ES ``text`` (of the file ``label``) with every value at ``highp``: ``lowp`` and
    ``mediump`` defined as ``highp`` after ``#version``, and highp the default precision of
    floats, ints and the samplers after the file's last ``#extension`` line (GLSL ES takes no
    ``#extension`` after a statement), each insertion followed by a ``#line`` (every line of the
    file keeps its number); a desktop GLSL text as it is (desktop GLSL ignores precision)."""
    d = detect(text, label)
    if not d.es:
        return text
    lines = text.split("\n")
    ext = [i for i, ln in enumerate(lines) if re.match(r"\s*#\s*extension\b", ln)]
    if not ext:
        return _with_head(text, d, _own_version_line(d), _HIGHP)
    k = ext[-1] + 1  # the file's lines 1..k end with its last #extension
    precision = [*_HIGHP[2:], _line_directive(k + 1, d.version, True)]
    text = "\n".join([*lines[:k], *precision, *lines[k:]])
    return _with_head(text, d, _own_version_line(d), _HIGHP[:2])


def for_opengl(
    text: str,
    label: str,
    defines=(),
    include_paths=(),
    stage: str = "frag",
    translate: bool = True,
    file_lines: bool = False,
) -> str:
    """The file ``text`` (``label``) as an OpenGL driver takes it: as it is where it needs no
    preprocessing (no defines, no ``#include``, a dialect run as written or ``translate``
    False), else :func:`front_end`'s preprocessed (and with ``translate``, translated) text
    with glslang's own extensions and file-named ``#line`` s left out, line for line
    (``file_lines``: kept, for glslang, whose errors then name an included file)."""
    d = detect(text, label, version_define(defines))
    if not ((d.translated and translate) or defines or has_includes(text)):
        return text
    text = front_end(text, label, defines, include_paths, True, stage, translate)
    return text if file_lines else without_file_lines(text)


def without_file_lines(text: str) -> str:
    """Preprocessed ``text`` without glslang's own extensions and file-named ``#line`` s."""
    text = re.sub(r"^[ \t]*#[ \t]*extension[ \t]+GL_GOOGLE_\w+[^\n]*", "", text, flags=re.M)
    return re.sub(r'^([ \t]*#[ \t]*line[ \t]+\d+)[ \t]+"[^"\n]*"', r"\1", text, flags=re.M)
