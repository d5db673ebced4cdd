"""A user's own shader in an experiment (``fit.shader`` a GLSL file): its paths resolved, its
``fit.declare`` lines read, the ``UserShader`` loaded and checked, and the digest of the waves it
draws (``waves.source = "shader"``), under which the reference is cached."""

from __future__ import annotations

import re
from pathlib import Path

from shaders_port.spirv import dialects
from shaders_port.spirv.probe import waves_digest
from shaders_port.spirv.user_shader import UserShader
from shaders_port.spirv.user_vertex import UserVertex

from .._progress import log
from .errors import ExperimentError, clip_text


def _clip(v, limit: int = 80) -> str:
    """``repr(v)`` cut to a readable length (an echoed bad value must not flood the message)."""
    return clip_text(repr(v), limit)


# the endings engines give a GLSL fragment shader's file (Urho3D's one-file `Water.glsl`,
# Babylon.js's `water.fragment.fx`, `.fs` / `.fsh` of GLES code bases)
USER_SHADER_SUFFIXES = (".frag", ".glsl", ".fs", ".fsh", ".fx")


def is_user_shader(name: str) -> bool:
    """Whether ``fit.shader`` names a GLSL file of the user's (one of
    :data:`USER_SHADER_SUFFIXES`), not a shader of the space."""
    return str(name).endswith(USER_SHADER_SUFFIXES)


_DECLARE_FORMS = (
    "`constant NAME LOW HIGH [START]`, `bind NAME INPUT`, `value NAME V[,V...]`, "
    "`normal NAME [world|tangent]`, `up y|z` or `normal_map FILE`"
)


def user_declaration(lines: list | None) -> dict:
    """``fit.declare`` lines as a declaration table of
    ``shaders_port.spirv.user_shader.UserShader``: what the file's ``// @study`` pragmas say,
    given without editing the file (a ``normal_map FILE`` as :func:`check_user_shader` made it:
    absolute)."""
    decl: dict = {"constants": {}, "bindings": {}, "values": {}}
    for line in lines or []:
        parts = str(line).split()
        verb, args = (parts[0], parts[1:]) if parts else ("", [])
        try:
            if verb == "constant" and len(args) in (3, 4):
                decl["constants"][args[0]] = [float(args[1]), float(args[2]), *args[3:]]
                continue
            if verb == "bind" and len(args) == 2:
                decl["bindings"][args[0]] = args[1]
                continue
            if verb == "value" and len(args) == 2:
                decl["values"][args[0]] = [float(x) for x in args[1].split(",")]
                continue
            if verb == "normal" and len(args) in (1, 2):
                decl["normal"] = " ".join(args)
                continue
            if verb == "up" and args in (["y"], ["z"]):
                decl["up"] = args[0]
                continue
            if verb == "normal_map" and len(args) == 1:
                decl["normal_map"] = args[0]
                continue
        except ValueError:
            pass
        raise ExperimentError(f"fit.declare: {_clip(line)}: write {_DECLARE_FORMS}")
    return decl


def _keyed(key: str, exc: Exception) -> str:
    """``exc``'s message led by the key it is about, once (the shader's loader may name it)."""
    text = str(exc)
    return text if text.startswith(f"{key}:") else f"{key}: {text}"


def pair_defines(vertex_path, fragment_path, vertex_defines, fragment_defines) -> tuple:
    """The vertex shader's defines, with the fragment shader's ``#version`` line added when the
    vertex file carries no marker of its dialect (no ``#version``, no ``precision`` statement,
    no version define) and the fragment shader is GLSL ES: an engine compiles the pair as one
    dialect (three.js's WebGL 1 vertex shaders declare no precision), which a file without a
    marker would otherwise be read apart from (as GLSL 1.10)."""
    vdefs = tuple(vertex_defines)
    if dialects.version_define(vdefs) is not None:
        return vdefs
    if Path(vertex_path).resolve() == Path(fragment_path).resolve():
        return vdefs
    try:
        vert = dialects.detect(Path(vertex_path).read_text(encoding="utf-8"), "fit.vertex")
        frag = dialects.detect(Path(fragment_path).read_text(encoding="utf-8"), "fit.shader",
                               dialects.version_define(fragment_defines))  # fmt: skip
    except (OSError, UnicodeDecodeError, dialects.ShaderError):
        return vdefs  # the files' loaders say what is wrong
    if not frag.es or vert.line or vert.es:
        return vdefs
    return (*vdefs, f"#version {frag.version}" + (" es" if frag.version > 100 else ""))


def load_user_shader(values: dict):
    """The ``UserShader`` of ``fit.shader`` (a resolved path) and ``fit.declare``, after its
    ``fit.vertex`` (a resolved path) when set; ExperimentError naming the problem."""
    vertex = None
    if values.get("fit.vertex"):
        try:
            vdefs = values.get("fit.vertex_defines")
            vdefs = values.get("fit.defines") or () if vdefs is None else vdefs
            vertex = UserVertex.from_file(
                values["fit.vertex"],
                values["fit.vertex_grid"],
                pair_defines(
                    values["fit.vertex"],
                    values["fit.shader"],
                    vdefs,
                    values.get("fit.defines") or (),
                ),  # fmt: skip
                values.get("fit.include_paths") or (),
                Path(values["fit.vertex"]).resolve() == Path(values["fit.shader"]).resolve(),
            )
        except (ValueError, RuntimeError) as exc:
            raise ExperimentError(_keyed("fit.vertex", exc)) from None
    try:
        return UserShader.from_file(
            values["fit.shader"],
            user_declaration(values["fit.declare"]),
            values.get("fit.defines") or (),
            values.get("fit.include_paths") or (),
            vertex=vertex,
        )
    except ValueError as exc:
        raise ExperimentError(_keyed("fit.shader", exc)) from None


def shader_waves_digest(shader) -> str:
    """The digest of what makes the waves of ``waves.source = "shader"`` of the user's shader
    ``shader`` (``UserShader``, :func:`check_user_shader`'s;
    ``shaders_port.spirv.probe.waves_digest``): the reference is cached under it."""
    if shader.normal is None:
        raise ExperimentError(
            f"waves.source = 'shader': {shader.label} does not name the variable that holds its "
            "surface normal; add `// @study normal NAME` (world frame) or `// @study normal NAME "
            "tangent` to it, or `normal NAME` to fit.declare"
        )
    try:
        return waves_digest(shader)
    except ValueError as exc:
        raise ExperimentError(_keyed("fit.shader", exc)) from None


def _resolved(value: str, base) -> str:
    p = Path(value).expanduser()
    return str((p if p.is_absolute() else (base or Path.cwd()) / p).resolve())


def _resolve_vertex(values: dict, base) -> None:
    """``fit.vertex`` as an absolute path: ``"auto"`` the ``.vert`` beside ``fit.shader`` (a
    resolved path), else relative to ``base``; ``fit.vertex_grid`` as two ints."""
    v = values.get("fit.vertex")
    values["fit.vertex_grid"] = [int(round(c)) for c in values["fit.vertex_grid"]]
    if not v:
        return
    if v == "auto":
        p = Path(values["fit.shader"]).with_suffix(".vert")
        if not p.is_file():
            raise ExperimentError(
                f'fit.vertex = "auto": no vertex shader {p.name} beside the fragment shader; '
                "name the file in fit.vertex or unset it (the study's water.vert)"
            )
        values["fit.vertex"] = str(p.resolve())
    else:
        values["fit.vertex"] = _resolved(v, base)


def _declared_file(line, base) -> str:
    """A ``fit.declare`` line with the FILE of ``normal_map FILE`` made absolute (relative to
    ``base``, the experiment file's folder); any other line as it is."""
    parts = str(line).split()
    if len(parts) == 2 and parts[0] == "normal_map":
        return f"normal_map {_resolved(parts[1], base)}"
    return line


def check_user_shader(values: dict, base: dict):
    """``fit.shader``, ``fit.vertex`` and ``fit.include_paths`` made absolute (relative to the
    experiment file), ``fit.defines`` checked; the shader read, compiled and its bindings
    checked (before any reference is rendered). Returns the ``UserShader``."""
    values["fit.shader"] = _resolved(values["fit.shader"], base.get("fit.shader"))
    _resolve_vertex(values, base.get("fit.vertex"))
    incs = values["fit.include_paths"] or []
    values["fit.include_paths"] = [_resolved(p, base.get("fit.include_paths")) for p in incs]
    values["fit.declare"] = [_declared_file(line, base.get("fit.declare")) for line in
                             values["fit.declare"] or []] or values["fit.declare"]  # fmt: skip
    for p in values["fit.include_paths"]:
        if not Path(p).is_dir():
            raise ExperimentError(f"fit.include_paths: no folder {_clip(p)}")
    for key in ("fit.defines", "fit.vertex_defines"):
        for d in values[key] or []:
            ok = re.fullmatch(r"[A-Za-z_]\w*(=[^\n]*)?|![A-Za-z_]\w*|#version \d+( \w+)?", d)
            if not ok or d.startswith("GL_"):
                raise ExperimentError(
                    f'{key}: {_clip(d)} is not "NAME" or "NAME=VALUE" (a preprocessor name: '
                    'letters, digits and _, not starting with GL_), "!NAME" (leave the '
                    'function NAME out of this stage) or "#version N" (the version line your '
                    "engine puts before a file without one)"
                )
    if values["fit.vertex_defines"] is not None and not values["fit.vertex"]:
        raise ExperimentError("fit.vertex_defines is for your own fit.vertex; set it or remove it")
    shader = load_user_shader(values)
    try:
        shader.check()
    except ValueError as exc:
        raise ExperimentError(_keyed("fit.shader", exc)) from None
    if values["fit.parameters"] is not None:  # e.g. a shipped experiment's list
        log(
            f"experiment: fit.parameters names the study's constants; {shader.label} fits the "
            f"constants its declaration names ({', '.join(shader.constants)})"
        )
        values["fit.parameters"] = None
    return shader
