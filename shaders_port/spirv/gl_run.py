"""Which text of a user's fragment shader OpenGL runs, and on which context (the GL check).

:func:`plan` chooses, for a :class:`~shaders_port.spirv.user_shader.UserShader` written back
with values (:meth:`UserShader.written`), a :class:`GLRun`:

* desktop GLSL 330-460 core: the file as written, on an OpenGL core-profile context;
* desktop GLSL 1.10-1.50 and the ``compatibility`` profiles: the file as written, on an
  OpenGL compatibility-profile context (``gl.contexts``; the study's vertex shader in GLSL 1.20
  or 1.50 compatibility, its built-ins fed by the fixed-function state, ``gl.dialect``) when
  the driver makes one that runs the file's version (OpenGL 4.5 compatibility on llvmpipe:
  GLSL 1.10-4.50);
* GLSL ES 1.00-3.20: the file as written, on an OpenGL ES context (the study's vertex shader in
  the file's GLSL ES version) when the driver makes one that runs it (ES 3.2 on llvmpipe),
  with every value at ``highp`` (``dialects.at_highp``: ``lowp`` and ``mediump`` read as
  ``highp``, highp the default of floats, ints and samplers) unless ``highp`` is False: the
  executor computes at 32-bit and llvmpipe computes ``lowp`` and ``mediump`` at 16-bit float;
* otherwise the core-profile translation (``dialects.front_end``: GLSL 330 core) on a
  core-profile context, with the reason (``why``); GLSL ES 3.10 and later, which has none, is
  refused (``dialects.ShaderError``) with the reason. ``as_written`` False asks for it.

A file with ``#include`` s or the experiment's defines is run preprocessed by glslang in its own
dialect (the includes and defines expanded). A shader run after the user's own vertex shader
runs with that file as written alike where the two link as written (GLSL ES: one version;
desktop GLSL: both before 1.40 or both from 1.40 on; the grid's attributes fed to its
compatibility built-in attributes, ``gl.grid``), else as the pair's translation.
Which contexts this machine makes, and the newest
GLSL version each runs, are found once per process (:func:`context_support`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..gl import contexts
from ..gl.dialect import dialect_renderer_class
from ..gl.renderer import GLRenderer
from ..gl.round_trip import TranslatedRenderer
from . import dialects, engine_inputs
from .engine_inputs import split_view, to_up

__all__ = ["GLRun", "context_support", "plan", "fixed_function_matrices"]

AS_WRITTEN = "your file as written"
PREPROCESSED = " (its #include files and defines expanded by glslang's preprocessor)"
HIGHP = ", every value at highp (lowp and mediump read as highp)"
TRANSLATION = "its core-profile translation (GLSL 330 core)"


@dataclass(frozen=True)
class GLRun:
    """A user's fragment shader as OpenGL runs it: ``text`` (the GLSL the driver compiles),
    ``kind`` (the context, ``gl.contexts.KINDS``), ``what`` (which text, in words: "your file
    as written" or "its core-profile translation (GLSL 330 core)"), ``why`` (why the
    translation ran: '' when the file runs as written), ``dialect`` (the file's)."""

    text: str
    kind: str
    what: str
    why: str
    dialect: dialects.Dialect
    vertex: str | None = None  # the user's vertex shader as run (None: the study's or its GLSL 330)

    @property
    def as_written(self) -> bool:
        return self.what.startswith(AS_WRITTEN)


@functools.lru_cache(maxsize=None)
def context_support(kind: str) -> tuple[int, str]:
    """(newest GLSL version the context runs (0: none made), the context in words or why
    none was made) for a context of ``kind`` on this machine, found by making one."""
    try:
        ctx = contexts.create_context(kind)
    except (RuntimeError, ImportError) as exc:
        return 0, str(exc).splitlines()[0]
    try:
        return contexts.glsl_version(ctx), contexts.describe(ctx)
    finally:
        ctx.release()


def _vertex_as_written(shader, kind: str, values: dict):
    """(the user's vertex shader as written, with ``values`` in place of its constants'
    initializers, for a context of ``kind``, '') when it links there with the fragment shader
    as written, else (None, why)."""
    vs, d = shader.vertex.shader, shader.dialect
    v = dialects.detect(vs.original, vs.label, dialects.version_define(vs.defines))
    # GLSL ES links shaders of one version; desktop GLSL does not link 1.30 and earlier with
    # 1.40 and later
    ok = v.es == d.es and (
        v.version == d.version if d.es else (v.version < 140) == (d.version < 140)
    )
    if not ok:
        return None, f"your vertex shader ({v.name}) does not link with {d.name} as written"
    text = shader.vertex_written(values)
    own = dialects.for_opengl(text, vs.label, vs.defines, vs.include_paths, "vert", False)
    return own, ""


def plan(shader, values: dict | None = None, as_written: bool = True, highp: bool = True):
    """The :class:`GLRun` of ``shader`` written back with ``values`` (module doc)."""
    d = shader.dialect
    written = shader.written(values or {})
    what = AS_WRITTEN + (PREPROCESSED if shader.defines or dialects.has_includes(written) else "")
    own = dialects.for_opengl(written, shader.label, shader.defines, shader.include_paths,
                              translate=False)  # fmt: skip
    if not d.translated and d.runs_on_desktop_gl:
        return GLRun(own, "core", what, "", d)
    kind = "es" if d.es else "compatibility"
    version, about = context_support(kind)
    vertex, why = _vertex_as_written(shader, kind, values or {}) if shader.vertex else (None, "")
    if not as_written:
        why = "the translation asked for"
    elif version >= d.version and not why:
        if kind == "es" and highp:
            own, what = dialects.at_highp(own, shader.label), what + HIGHP
            vertex = vertex and dialects.at_highp(vertex, shader.vertex.label)
        return GLRun(own, kind, what, "", d, vertex)
    if not why:
        api = "OpenGL ES" if kind == "es" else "OpenGL compatibility-profile"
        why = (
            f"no {api} context here ({about})" if version == 0
            else f"{d.name} is newer than {about} runs"
        )  # fmt: skip
    if not d.runs_on_desktop_gl:
        raise dialects.ShaderError(
            f"{shader.label} is {d.name}, which no context here runs ({why}) and which has no "
            "core-profile translation; glslang compiled it with its ES profile"
        )
    return GLRun(shader.gl_source(values), "core", TRANSLATION, why, d)


def fixed_function_matrices(inputs, up: str = "y") -> dict:
    """{'modelview', 'projection'}: the frame's view and projection (``split_view``; model =
    identity) in the world frame ``up``, float64 (4, 4) acting on column vectors, as a
    compatibility context's fixed-function matrices; a ``view_proj`` that is no perspective
    times a rigid view is loaded whole as the projection (the modelview the identity)."""
    try:
        view, proj = split_view(inputs)
    except ValueError:
        view, proj = np.eye(4), np.asarray(inputs.view_proj, np.float64)
    return {"modelview": to_up(up, view, "matrix"), "projection": proj}


def renderer(shader, inputs, values: dict, source=None, reflection=None, es=None, **how):
    """The GL renderer of :meth:`UserShader.gl_renderer` for ``values`` (checked): the
    :func:`plan` 's text (``how``: its ``as_written`` and ``highp``) on its context
    (``r.gl_run`` the plan, ``r.context`` the context in words); or, with every uniform
    constant set as the material sets it (``r.gl_run`` None), ``source`` with its
    ``reflection`` (the HLSL round trip) on a core context, or ``source`` after the vertex
    shader ``es`` (the export's GLSL ES 3.00 files) on an OpenGL ES context."""
    bindings = shader.run_bindings()
    if shader.vertex is not None:  # its uniforms that are study or engine inputs
        bindings = {**shader.vertex.shader.inputs, **bindings}
    run = plan(shader, values, **how) if source is None else None
    base = GLRenderer if reflection is None else TranslatedRenderer
    # every constant that is a uniform of a stage gets its value, as the engine's material sets
    # it: one the text leaves without initializer must (a bare one where the dialect takes no
    # initializer, one an #include declares, every one of the engine targets); one with an
    # initializer holds the same value (a name no stage declares as a uniform is skipped)
    unset = {c.name: np.asarray(values[c.name], np.float32).tobytes()
             for c in shader.constants.values()}  # fmt: skip
    unset.update({n: np.float32(v).tobytes() for n, v in shader.values.items()})
    up = shader.engine["up"]
    if run is not None and run.kind != "core":
        matrices = fixed_function_matrices(inputs, up)
        base = dialect_renderer_class(base, run.kind, run.dialect.version, matrices)
    elif es is not None:
        base = dialect_renderer_class(base, "es", 300, vertex=es)
    if shader.vertex is not None:  # the grid drawn with the user's GLSL vertex shader
        vertex = es if run is None else run.vertex
        builtins = dialects.BUILTIN_ATTRIBUTES if vertex is not None else None
        if vertex is None:  # the GLSL 330 it is compiled as, the values in place
            vertex = shader.vertex_gl_source(values)
        base = shader.vertex.gl_class(base, inputs, up, vertex, builtins)
    base = engine_inputs.gl_class(base, shader.engine)
    label = shader.label

    class _Bound(base):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            self.name = label  # messages name the user's file
            self.gl_run, self.context = run, contexts.describe(self.ctx)

        def _sampler_uniform(self, prog, sname):
            for name in [n for n, s in bindings.items() if s == sname] + [sname]:
                found = super()._sampler_uniform(prog, name)
                if found is not None:
                    return found
            return None

        def _write_uniforms(self, prog, vals):
            renamed = {**unset, **vals}
            for n, s in bindings.items():
                if s in vals:
                    renamed[n] = vals[s]
            super()._write_uniforms(prog, renamed)

    if reflection is None:
        return _Bound("water_refraction", inputs, source=run.text if run else source)
    return _Bound("water_refraction", inputs, source, reflection)
