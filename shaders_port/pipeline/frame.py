"""Plumbing shared by every shader port: the output frame, constants resolution, the loop mode
of derivatives and the forward-mode Jacobian passes. Shader files hold only shader code.

* :class:`ShaderOutput`: colour (H, W, 3) linear RGB float32, water mask, diagnostics (H, W);
* :func:`resolve_constants`: ``Constants`` -> float32 opaque scalars / gradient-enabled Floats;
* :func:`finish_output`: lanes (water pixels in raster order) scattered into images, non-finite
  lanes zeroed, flagged and warned about;
* :func:`jacobian_passes` / :func:`tangents`: one forward-mode pass per named constant;
* ``USE_FROZEN`` / :func:`call_frozen`: plain renders and 'replay' Jacobians may replay recorded
  kernels (``dr.freeze``; ``STUDY_FREEZE=0`` traces), outputs checked before use.
"""

from __future__ import annotations

import dataclasses
import gc
import os
import warnings
from collections import OrderedDict
from dataclasses import dataclass

import drjit as dr
import numpy as np

from ..inputs import CONSTANT_SPECS, Constants, ShaderInputs
from .raster import prepare
from .texture import backend_types

# Plain renders and 'replay' Jacobians replay recorded kernels instead of re-tracing the shader
# (``dr.freeze``; benchmarks/bench_freeze.py measures the gain). ``STUDY_FREEZE=0`` (or this
# flag) traces every call.
USE_FROZEN = os.environ.get("STUDY_FREEZE", "1") != "0"

# One frozen function per configuration and uploaded frame (a fit's scene), at most
# MAX_FUNCTIONS kept (the least recently used dropped). A frame records twice (the first call,
# then once more when Dr.Jit makes the inputs that changed opaque); a function recorded more
# than MAX_RECORDINGS times is keyed wrongly and is traced from then on.
MAX_RECORDINGS = 4
MAX_FUNCTIONS = 64

_FROZEN: OrderedDict = OrderedDict()


class FrozenReplayWarning(UserWarning):
    """A frozen configuration gave a wrong replay or recorded too often and is traced now."""


_BROKEN: set = set()


def frozen(key: tuple, fn):
    """``dr.freeze(fn)``, one frozen function per ``key``: the Python-level configuration of a
    call (shader, variant options, the integer loop caps, diagnostics on/off). Dr.Jit 1.5.0's
    freeze was measured to replay a recording made with other Python int / bool arguments
    (``loop_cap=3`` after ``loop_cap=2`` replayed the 2-step loop; ``diagnose=True`` after
    ``False`` lost the extra outputs), so that configuration goes into the choice of the frozen
    function, never into its arguments. Scene values (texture matrices, sizes) are keyed
    by freeze itself (checked against traced renders in tests). The shader code must not bake
    a lane count into a recording (``dr.zeros(T, dr.width(x))`` inside the shader replays
    at the recorded width): loop flags start as width-1 values that the loop widens."""
    f = _FROZEN.get(key)
    if f is None:

        def packed(*args):
            return _pack(fn(*args))

        f = _FROZEN[key] = dr.freeze(packed, limit=MAX_RECORDINGS, warn_after=MAX_RECORDINGS + 1)
        while len(_FROZEN) > MAX_FUNCTIONS:
            _FROZEN.popitem(last=False)
    _FROZEN.move_to_end(key)
    return f


def _pack(tree):
    """A frozen function's result with every literal leaf (a value the same on every lane, e.g.
    a structurally zero derivative) replaced by ``("__literal__", type, value)``: a literal
    output would be recorded at its width and replayed at that width. Vectors (``Array3f``)
    become ``("__vector__", type, components...)`` so that each component is packed."""
    if isinstance(tree, dict):
        return {k: _pack(v) for k, v in tree.items()}
    if isinstance(tree, (list, tuple)):
        return type(tree)(_pack(v) for v in tree)
    if isinstance(tree, dr.ArrayBase):
        if dr.depth_v(tree) > 1:
            return ("__vector__", type(tree)) + tuple(_pack(tree[c]) for c in range(len(tree)))
        if tree.state == dr.VarState.Literal:
            return ("__literal__", type(tree), tree[0])
    return tree


def _unpack(tree, lanes: int):
    """Inverse of :func:`_pack`: literals come back as ``lanes``-wide values."""
    tag = tree[0] if isinstance(tree, tuple) and tree and isinstance(tree[0], str) else None
    if tag == "__literal__":
        return dr.full(tree[1], tree[2], lanes)
    if tag == "__vector__":
        return tree[1](*(_unpack(v, lanes) for v in tree[2:]))
    if isinstance(tree, dict):
        return {k: _unpack(v, lanes) for k, v in tree.items()}
    if isinstance(tree, (list, tuple)):
        return type(tree)(_unpack(v, lanes) for v in tree)
    return tree


def _widths(tree, out: list) -> list:
    """Widths of every Dr.Jit leaf (each component of an ``Array3f``) of a nested result."""
    if isinstance(tree, dict):
        for v in tree.values():
            _widths(v, out)
    elif isinstance(tree, (list, tuple)):
        for v in tree:
            _widths(v, out)
    elif isinstance(tree, dr.ArrayBase):
        if dr.depth_v(tree) > 1:
            for c in range(len(tree)):
                _widths(tree[c], out)
        else:
            out.append(dr.width(tree))
    return out


def call_frozen(key: tuple, fn, m, P, *args, widths: tuple = ()):
    """``fn(m, P, *args)``, replayed from a recording when :data:`USE_FROZEN` (see
    :func:`frozen`); ``P`` is the frame's shading state (``Prepared``), whose upload number
    joins ``key`` and whose lane count every output leaf must have, or one of ``widths`` (the
    lanes of the frame's pixel quads, helper pixels included, for a value kept over them).

    A replay whose outputs have another width, or a function recorded more than
    :data:`MAX_RECORDINGS` times, is never passed on: the call is traced instead, and that
    configuration is traced from then on, with one warning.

    Python's cyclic garbage collector is off during the frozen call: collecting Dr.Jit values
    that an earlier call left in reference cycles (an exception's traceback frames) while a
    recording runs aborts Dr.Jit; they are collected once the call is over."""
    args = (m, P) + args
    if not USE_FROZEN or key in _BROKEN:
        return fn(*args)
    lanes = lane_count(P)
    f = frozen(key + (P.upload,), fn)
    was_collecting = gc.isenabled()
    gc.disable()  # the collector freeing other calls' Dr.Jit values mid-recording aborts Dr.Jit
    try:
        out = _unpack(f(*args), lanes)
    finally:
        if was_collecting:
            gc.enable()
    bad = sorted({w for w in _widths(out, []) if w != lanes and w not in widths})
    why = None
    if bad:
        why = f"a replay returned outputs of width {bad} for {lanes} lanes"
    elif f.n_recordings > MAX_RECORDINGS:
        why = f"it was recorded {f.n_recordings} times (its inputs' layout changes between calls)"
    if why is None:
        return out
    _BROKEN.add(key)
    warnings.warn(
        f"frozen {key[0]}: {why}; tracing this configuration from now on",
        FrozenReplayWarning,
        stacklevel=2,
    )
    return fn(*args) if bad else out


def lane_count(P) -> int:
    """Lanes (covered pixels) of a ``Prepared`` frame or its shading state."""
    return dr.width(P.varyingVecWorldPosition.x)


def python_config(C) -> tuple:
    """The plain Python values of resolved constants ``C`` (integer loop caps, ``loop_ad``) and
    which constants are differentiated (a Jacobian over other names is another recording), as a
    hashable tuple for :func:`frozen`."""
    plain = tuple(sorted((k, v) for k, v in C.values.items() if isinstance(v, (bool, int, str))))
    graded = []
    for k, v in sorted(C.values.items()):
        for j, x in enumerate(v if isinstance(v, tuple) else (v,)):
            if isinstance(x, dr.ArrayBase) and dr.grad_enabled(x):
                graded.append((k, j))
    return plain + (("differentiated", tuple(graded)),)


@dataclass
class ShaderOutput:
    """One rendered frame.

    Attributes:
        color: TensorXf (H, W, 3) linear RGB (float32); 0 off the water and where the shader
            produced a non-finite value (see ``diagnostics['nonfinite']``).
        mask: TensorXf (H, W), 1.0 on water pixels else 0.0.
        diagnostics: dict name -> TensorXf (H, W), 0 off the water.
    """

    color: object
    mask: object
    diagnostics: dict
    lanes: object = dataclasses.field(default=None, repr=False)  # Array3f colour of the water
    # pixels in raster order (differentiable; used by render_with_jacobian)

    def numpy(self) -> dict:
        """``{'color': (H, W, 3), 'mask': (H, W), <diagnostic>: (H, W)}`` float32 NumPy arrays."""
        out = {
            "color": np.asarray(self.color.numpy(), dtype=np.float32),
            "mask": np.asarray(self.mask.numpy(), dtype=np.float32),
        }
        out.update(
            {k: np.asarray(v.numpy(), dtype=np.float32) for k, v in self.diagnostics.items()}
        )
        return out


@dataclass
class _Resolved:
    differentiable: bool
    values: dict

    def __getattr__(self, name):
        try:
            return self.__dict__["values"][name]
        except KeyError:
            raise AttributeError(name) from None


def resolve_constants(m, constants: Constants, loop_ad: str = "replay") -> _Resolved:
    """Validate ``constants`` and return them as Python floats / size-1 ``m.Float`` (names as in
    ``Constants`` plus ``waterColor`` / ``reflectColor`` as ``m.Array4f``)."""
    if not isinstance(constants, Constants):
        raise TypeError(f"expected Constants, got {type(constants).__name__}")
    constants.validate()
    vals, diff = {}, False

    def conv(name, x):
        nonlocal diff
        if isinstance(x, dr.ArrayBase):
            if dr.width(x) != 1:
                raise ValueError(
                    f"constant {name}: a Dr.Jit value must have size 1, got {dr.width(x)}"
                )
            v = float(np.asarray(dr.detach(x).numpy()).ravel()[0])
            lo, hi = CONSTANT_SPECS[name][3]
            # a float32 value on its bound is the bound rounded to float32 (1e-4 -> 9.9999997e-05)
            lo, hi = float(np.float32(lo)), float(np.float32(hi))
            if not (np.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"constant {name} = {v!r} is not finite or outside [{lo}, {hi}]")
            diff = diff or dr.grad_enabled(x)
            return x if type(x) is m.Float else m.Float(x)
        # float32 arithmetic, as a GLSL uniform / const; opaque so that a traced and a frozen
        # render compute the same (no literal folding) and new values reuse compiled kernels
        return dr.opaque(m.Float, float(np.float32(x)))

    for name, (glsl, kind, _, _) in CONSTANT_SPECS.items():
        v = getattr(constants, name)
        if kind.endswith("int"):
            if isinstance(v, dr.ArrayBase):
                raise TypeError(
                    f"constant {name} ({glsl}) is an integer loop cap; pass a Python int"
                )
            vals[name] = int(v)
        elif kind.endswith("vec4"):
            vals[name] = tuple(conv(name, x) for x in v)
        else:
            vals[name] = conv(name, v)
    if loop_ad not in ("replay", "evaluated"):
        raise ValueError(f"loop_ad must be 'replay' or 'evaluated', got {loop_ad!r}")
    vals["loop_ad"] = loop_ad
    vals["waterColor"] = m.Array4f(*vals["water_color"])
    vals["reflectColor"] = m.Array4f(*vals["reflect_color"])
    return _Resolved(diff, vals)


class evaluated_loops_if:
    """Context manager: turn ``JitFlag.SymbolicLoops`` off while active if ``cond`` (restored
    after)."""

    def __init__(self, cond: bool):
        self.cond = cond

    def __enter__(self):
        self.old = dr.flag(dr.JitFlag.SymbolicLoops)
        if self.cond:
            dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        return self

    def __exit__(self, *exc):
        dr.set_flag(dr.JitFlag.SymbolicLoops, self.old)
        return False


def finish_output(m, P, color, diag: dict, shader: str) -> ShaderOutput:
    """Flag non-finite lanes, scatter lanes into (H, W) images, warn if any pixel was non-finite."""
    r = P.raster
    n = r.width * r.height
    nonfinite = ~(dr.isfinite(color.x) & dr.isfinite(color.y) & dr.isfinite(color.z))
    if "nonfinite" in diag:  # intermediate vectors whose NaN a clamp or a lookup can hide
        nonfinite |= diag["nonfinite"] > 0
    dr.eval(color, nonfinite, {k: v for k, v in diag.items() if k != "nonfinite"})  # one kernel
    idx = m.UInt32(r.index.astype(np.uint32))
    flat = dr.zeros(m.Float, 3 * n)
    lanes = m.Array3f(*(dr.select(nonfinite, 0.0, color[c]) for c in range(3)))
    for c in range(3):
        dr.scatter(flat, lanes[c], 3 * idx + c)
    diag = dict(diag)
    diag["nonfinite"] = dr.select(nonfinite, 1.0, 0.0)
    images = {}
    for k, v in diag.items():
        img = dr.zeros(m.Float, n)
        dr.scatter(img, m.Float(dr.detach(v)), idx)
        images[k] = m.TensorXf(img, shape=(r.height, r.width))
    count = int(dr.sum(diag["nonfinite"])[0]) if dr.width(diag["nonfinite"]) else 0
    if count:
        warnings.warn(
            f"{shader}: {count} water pixel(s) were non-finite (NaN/inf) and set to 0; "
            "see diagnostics['nonfinite'] (e.g. a degenerate normal from bumptex_mult "
            "or a zero-length vector)",
            RuntimeWarning,
            stacklevel=3,
        )
    mask = m.TensorXf(m.Float(r.mask.ravel().astype(np.float32)), shape=(r.height, r.width))
    return ShaderOutput(m.TensorXf(flat, shape=(r.height, r.width, 3)), mask, images, lanes)


def _parse_name(name: str):
    if name.endswith("]") and "[" in name:
        base, idx = name[:-1].split("[", 1)
        if base in ("water_color", "reflect_color") and idx in ("0", "1", "2", "3"):
            return base, int(idx)
    elif name in CONSTANT_SPECS and not CONSTANT_SPECS[name][1].endswith(("int", "vec4")):
        return name, None
    raise ValueError(
        f"cannot differentiate with respect to {name!r}: use a float key of "
        "CONSTANT_SPECS or 'water_color[i]' / 'reflect_color[i]' (i = 0..3)"
    )


def tangents(m, color, diag: dict, params: list):
    """Forward-mode passes of one shaded frame: ``(colour lanes Array3f, diag, grads)``, where
    ``grads[j]`` is the Array3f derivative of the colour lanes w.r.t. ``params[j]``. The graph is
    kept between passes and the gradients cleared; non-finite lanes get colour and derivative 0."""
    bad = ~(dr.isfinite(color.x) & dr.isfinite(color.y) & dr.isfinite(color.z))
    bad |= diag["nonfinite"] > 0
    lanes = m.Array3f(*(dr.select(bad, 0.0, color[c]) for c in range(3)))
    # a param the colour does not depend on (a constant read by no code of the frame) has
    # derivative 0
    keep = dr.ADFlag.ClearInterior | dr.ADFlag.ClearInput | dr.ADFlag.AllowNoGrad
    grads = []
    for p in params:
        for q in params:
            dr.clear_grad(q)
        dr.clear_grad(lanes)
        dr.set_grad(p, 1.0)
        grads.append(m.Array3f(dr.forward_to(lanes, flags=keep)))
    return color, {k: dr.detach(v) for k, v in diag.items()}, grads


def jacobian_passes(
    shade_tangents,
    shader: str,
    inputs: ShaderInputs,
    constants: Constants,
    names: list[str],
    backend: str,
    loop_ad: str,
    lanes=None,
    maps=None,
):
    """Shared driver of ``render_with_jacobian``: every named scalar becomes a gradient-enabled
    size-1 Float; ``shade_tangents(m, P, C, params, frozen)`` shades once and runs one
    forward-mode pass per name (see :func:`tangents`), replayed from recorded kernels
    (``dr.freeze``) in ``loop_ad='replay'`` mode. Returns ``(ShaderOutput, J (H, W, 3, k))``.

    ``lanes``: None, or a callable ``lanes(m, raster, colour, nonfinite, grads)`` that takes
    the evaluated lanes where they were computed (``colour`` Array3f, 0 on non-finite lanes;
    ``nonfinite`` Bool; ``grads`` one Array3f per name; ``raster.index`` the lanes' flat pixel
    indices) and whose return value is returned in place of the images: nothing of the frame
    is read back to the host here (``study.fit.normal_equations``). ``maps``: None, or
    ``maps(m, P)``, the prepared frame with the derived maps the shader reads
    (``pipeline.normal_maps.with_maps``)."""
    m = backend_types(backend)
    if not names:
        raise ValueError("names is empty: give at least one constant to differentiate")
    changes, params = {}, []
    for name in names:
        base, idx = _parse_name(name)
        cur = changes.get(base, getattr(constants, base))
        # opaque, as resolve_constants makes the other constants: a literal would be folded into
        # the first recording's kernels and round differently from the replays
        if idx is None:
            p = dr.opaque(
                m.Float, float(dr.detach(cur)[0]) if isinstance(cur, dr.ArrayBase) else float(cur)
            )
            changes[base] = p
        else:
            comps = list(cur)
            x = comps[idx]
            p = dr.opaque(
                m.Float, float(dr.detach(x)[0]) if isinstance(x, dr.ArrayBase) else float(x)
            )
            comps[idx] = p
            changes[base] = tuple(comps)
        dr.enable_grad(p)
        params.append(p)
    P = prepare(inputs, m)
    if maps is not None:
        P = maps(m, P)
    C = resolve_constants(m, constants.replace(**changes), loop_ad)
    try:
        with evaluated_loops_if(loop_ad == "evaluated"):
            frozen = USE_FROZEN and loop_ad == "replay"
            color, diag, grads = shade_tangents(
                m, P.shading_state() if frozen else P, C, params, frozen
            )
            dr.eval(color, diag, grads)  # primal and all tangents together
    finally:
        for p in params:
            dr.disable_grad(p)
    return jacobian_output(m, P, color, diag, grads, shader, lanes)


def jacobian_output(m, P, color, diag: dict, grads: list, shader: str, lanes=None):
    """What ``render_with_jacobian`` returns for one evaluated frame (``P`` prepared, ``color``
    Array3f and ``grads`` one Array3f per name, over the lanes of ``P.raster``):
    ``(ShaderOutput, J (H, W, 3, k) float32)``, or what ``lanes`` returns
    (:func:`jacobian_passes`)."""
    if lanes is not None:
        color = dr.detach(color)
        bad = ~(dr.isfinite(color.x) & dr.isfinite(color.y) & dr.isfinite(color.z))
        if "nonfinite" in diag:
            bad |= diag["nonfinite"] > 0
        colour = m.Array3f(*(dr.select(bad, 0.0, color[c]) for c in range(3)))
        return lanes(m, P.raster, colour, bad, grads)
    out = finish_output(m, P, dr.detach(color), diag, shader)
    r = P.raster
    J = np.zeros((r.width * r.height, 3, len(grads)), dtype=np.float32)
    for j, g in enumerate(grads):
        J[r.index, :, j] = np.asarray(g.numpy(), dtype=np.float32).T
    return out, J.reshape(r.height, r.width, 3, len(grads))


def _raster_index(out: ShaderOutput) -> np.ndarray:
    """Flat pixel indices of the lanes of ``out`` (water pixels in raster order)."""
    return np.flatnonzero(np.asarray(out.mask.numpy()).ravel() > 0.5)


def nonfinite_any(*vectors):
    """Bool per lane: some component of some Array3f in ``vectors`` is NaN or infinite."""
    bad = None
    for v in vectors:
        b = ~(dr.isfinite(v.x) & dr.isfinite(v.y) & dr.isfinite(v.z))
        bad = b if bad is None else bad | b
    return bad
