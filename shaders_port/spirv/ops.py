"""The value-level operations of the SPIR-V executor: GLSL arithmetic on Dr.Jit types.

A value is a scalar -- a Python number or bool (a constant the executor folds: loop counters,
integer constants, literals) or a Dr.Jit ``Float`` / ``Int32`` / ``UInt32`` / ``Bool`` of one
lane per pixel -- or a Python list of values (a vector's components, a matrix's columns, an
array's or a struct's members). Python floats are float32 numbers: folded arithmetic rounds to
float32 like the GPU. The GLSL.std.450 instructions follow the GLSL specification and the
hand ports' definitions (``shaders_port.pipeline.texture``: ``mix``, ``clamp``, ``pow``), so the
executor computes what the ports compute, operation for operation.

:class:`Mask` is a lane mask (a Python bool when the same for every lane) that remembers how it
was made, so that the two edges of a selection join back into exactly the mask before it (a
loop whose exits do not depend on the lanes is then unrolled, see ``spirv.execute``).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np

from ..pipeline.texture import clamp, gl_pow, mix


def is_py(x) -> bool:
    """True for a Python (folded) scalar."""
    return isinstance(x, (bool, int, float))


def f32(x: float) -> float:
    """``x`` rounded to float32, as a Python float."""
    return float(np.float32(x))


def lift(m, x, kind: str):
    """A scalar as a Dr.Jit value of ``kind`` ('float', 'int', 'uint', 'bool')."""
    t = {"float": m.Float, "int": m.Int32, "uint": m.UInt32, "bool": m.Bool}[kind]
    if isinstance(x, dr.ArrayBase):
        return x if type(x) is t else t(x)
    return t(x)


def detach(x):
    if isinstance(x, list):
        return [detach(v) for v in x]
    return dr.detach(x) if isinstance(x, dr.ArrayBase) and dr.is_diff_v(x) else x


def any_grad(x) -> bool:
    """Whether a value (or a component of it) carries AD derivatives."""
    if isinstance(x, list):
        return any(any_grad(v) for v in x)
    return isinstance(x, dr.ArrayBase) and dr.grad_enabled(x)


def tangent_part(x):
    """``x - detach(x)``: the value 0 carrying ``x``'s derivative (0 for a plain value)."""
    if isinstance(x, dr.ArrayBase) and dr.grad_enabled(x):
        return x - dr.detach(x)
    return 0.0


def cw(f, *args):
    """``f`` applied component by component to values of one shape (lists are vectors)."""
    if isinstance(args[0], list):
        return [cw(f, *(a[i] for a in args)) for i in range(len(args[0]))]
    return f(*args)


def _fold(f, py):
    """A scalar operation that folds Python operands with ``py`` (float32 for floats)."""

    def op(*a):
        if all(is_py(x) for x in a):
            with np.errstate(all="ignore"):
                return py(*a)
        return f(*a)

    return op


def _f(fn):  # a float32 folding of a NumPy function of float32 operands
    return lambda *a: float(fn(*(np.float32(x) for x in a)))


def _trunc_div(a, b):
    return int(a / b) if b else 0


def _smod(a, b):
    """GLSL ``%`` of signed integers as SPIR-V OpSMod: the sign of the divisor."""
    r = a % b  # Dr.Jit: the sign of the dividend (C)
    return dr.select((r != 0) & ((r < 0) != (b < 0)), r + b, r)


BINARY = {
    "OpFAdd": _fold(lambda a, b: a + b, _f(np.add)),
    "OpFSub": _fold(lambda a, b: a - b, _f(np.subtract)),
    "OpFMul": _fold(lambda a, b: a * b, _f(np.multiply)),
    "OpFDiv": _fold(lambda a, b: a / b, _f(np.divide)),
    "OpFMod": _fold(lambda a, b: a - b * dr.floor(a / b), _f(lambda a, b: a - b * np.floor(a / b))),
    "OpIAdd": _fold(lambda a, b: a + b, lambda a, b: a + b),
    "OpISub": _fold(lambda a, b: a - b, lambda a, b: a - b),
    "OpIMul": _fold(lambda a, b: a * b, lambda a, b: a * b),
    "OpSDiv": _fold(lambda a, b: a // b, _trunc_div),
    "OpUDiv": _fold(lambda a, b: a // b, _trunc_div),
    "OpSRem": _fold(lambda a, b: a % b, lambda a, b: int(math.fmod(a, b)) if b else 0),
    "OpSMod": _fold(_smod, lambda a, b: a % b if b else 0),
    "OpUMod": _fold(lambda a, b: a % b, lambda a, b: a % b if b else 0),
    "OpBitwiseAnd": _fold(lambda a, b: a & b, lambda a, b: a & b),
    "OpBitwiseOr": _fold(lambda a, b: a | b, lambda a, b: a | b),
    "OpBitwiseXor": _fold(lambda a, b: a ^ b, lambda a, b: a ^ b),
    "OpShiftLeftLogical": _fold(lambda a, b: a << b, lambda a, b: a << b),
    "OpShiftRightArithmetic": _fold(lambda a, b: a >> b, lambda a, b: a >> b),
    "OpFOrdEqual": _fold(lambda a, b: a == b, lambda a, b: a == b),
    "OpFOrdNotEqual": _fold(lambda a, b: a != b, lambda a, b: a != b and a == a and b == b),
    "OpFUnordNotEqual": _fold(lambda a, b: ~(a == b), lambda a, b: not a == b),
    "OpFOrdLessThan": _fold(lambda a, b: a < b, lambda a, b: a < b),
    "OpFOrdGreaterThan": _fold(lambda a, b: a > b, lambda a, b: a > b),
    "OpFOrdLessThanEqual": _fold(lambda a, b: a <= b, lambda a, b: a <= b),
    "OpFOrdGreaterThanEqual": _fold(lambda a, b: a >= b, lambda a, b: a >= b),
    "OpIEqual": _fold(lambda a, b: a == b, lambda a, b: a == b),
    "OpINotEqual": _fold(lambda a, b: a != b, lambda a, b: a != b),
    "OpSLessThan": _fold(lambda a, b: a < b, lambda a, b: a < b),
    "OpSGreaterThan": _fold(lambda a, b: a > b, lambda a, b: a > b),
    "OpSLessThanEqual": _fold(lambda a, b: a <= b, lambda a, b: a <= b),
    "OpSGreaterThanEqual": _fold(lambda a, b: a >= b, lambda a, b: a >= b),
    "OpULessThan": _fold(lambda a, b: a < b, lambda a, b: a < b),
    "OpUGreaterThan": _fold(lambda a, b: a > b, lambda a, b: a > b),
    "OpULessThanEqual": _fold(lambda a, b: a <= b, lambda a, b: a <= b),
    "OpUGreaterThanEqual": _fold(lambda a, b: a >= b, lambda a, b: a >= b),
    "OpLogicalAnd": _fold(lambda a, b: a & b, lambda a, b: a and b),
    "OpLogicalOr": _fold(lambda a, b: a | b, lambda a, b: a or b),
    "OpLogicalEqual": _fold(lambda a, b: ~(a ^ b), lambda a, b: a == b),
    "OpLogicalNotEqual": _fold(lambda a, b: a ^ b, lambda a, b: a != b),
}
UNARY = {
    "OpFNegate": _fold(lambda a: -a, _f(np.negative)),
    "OpSNegate": _fold(lambda a: -a, lambda a: -a),
    "OpLogicalNot": _fold(lambda a: ~a, lambda a: not a),
    "OpIsNan": _fold(dr.isnan, math.isnan),
    "OpIsInf": _fold(dr.isinf, math.isinf),
}


def select(m, c, a, b, kind: str):
    """``c ? a : b`` per lane (``c`` a scalar mask, ``a``/``b`` values of one shape)."""
    if isinstance(a, list):
        return [select(m, c, x, y, kind) for x, y in zip(a, b)]
    if is_py(c):
        return a if c else b
    if is_py(a) and is_py(b) and a == b and type(a) is type(b):
        return a
    return dr.select(c, lift(m, a, kind), lift(m, b, kind))


def kind_of(x) -> str:
    """'float' | 'int' | 'uint' | 'bool' of a scalar value (the first leaf of a list)."""
    while isinstance(x, list):
        x = x[0]
    if isinstance(x, bool):
        return "bool"
    if isinstance(x, (int, float)):
        return "int" if isinstance(x, int) else "float"
    name = type(x).__name__
    return {"Bool": "bool", "Int": "int", "Int32": "int", "UInt": "uint", "UInt32": "uint"}.get(
        name, "float"
    )


def select_any(m, c, a, b):
    """``c ? a : b`` per lane for values of one shape whose leaves may differ in kind (a
    struct's members); each leaf's kind from the Dr.Jit operand, else the Python one."""
    if isinstance(a, list):
        return [select_any(m, c, x, y) for x, y in zip(a, b)]
    k = kind_of(b) if is_py(a) and not is_py(b) else kind_of(a)
    return select(m, c, a, b, k)


def dot(m, a, b):
    if all(is_py(x) for x in a + b):
        return f32(np.dot(np.float32(a), np.float32(b)))
    n = len(a)
    T = {2: m.Array2f, 3: m.Array3f, 4: m.Array4f}[n]
    return dr.dot(T(*a), T(*b))


def _vec(m, a):
    T = {2: m.Array2f, 3: m.Array3f, 4: m.Array4f}[len(a)]
    return T(*a)


def normalize(m, a):
    if all(is_py(x) for x in a):
        v = np.float32(a)
        return [float(x) for x in v / np.float32(np.sqrt(np.dot(v, v)))]
    v = dr.normalize(_vec(m, a))
    return [v[i] for i in range(len(a))]


def length(m, a):
    if not isinstance(a, list):
        return _fold(dr.abs, _f(np.abs))(a)
    if all(is_py(x) for x in a):
        return f32(np.linalg.norm(np.float32(a)))
    return dr.norm(_vec(m, a))


def refract(m, incident, normal, eta):
    """GLSL ``refract`` as the ports define it: 0 when ``k < 0``."""
    d = dot(m, normal, incident)
    k = 1.0 - eta * eta * (1.0 - d * d)
    s = eta * d + dr.sqrt(dr.maximum(k, 0.0))
    out = [eta * i - s * n for i, n in zip(incident, normal)]
    return [dr.select(k < 0.0, 0.0, o) for o in out]


def reflect(m, incident, normal):
    d = dot(m, normal, incident)
    return [i - 2.0 * d * n for i, n in zip(incident, normal)]


def _smoothstep(e0, e1, x):
    t = clamp((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _sign(x):
    return dr.select(x > 0, 1.0, dr.select(x < 0, -1.0, 0.0))


def _py_pow(x, y):
    return 0.0 if x == 0 else f32(np.exp2(np.float32(y) * np.log2(np.float32(x))))


# GLSL.std.450 instructions applied component by component: name -> (Dr.Jit, folded Python)
STD450 = {
    "Round": (dr.round, _f(np.round)),
    "RoundEven": (dr.round, _f(np.round)),
    "Trunc": (dr.trunc, _f(np.trunc)),
    "FAbs": (dr.abs, _f(np.abs)),
    "SAbs": (dr.abs, abs),
    "FSign": (_sign, _f(np.sign)),
    "Floor": (dr.floor, _f(np.floor)),
    "Ceil": (dr.ceil, _f(np.ceil)),
    "Fract": (lambda x: x - dr.floor(x), _f(lambda x: x - np.floor(x))),
    "Radians": (lambda x: x * (math.pi / 180), _f(np.radians)),
    "Degrees": (lambda x: x * (180 / math.pi), _f(np.degrees)),
    "Sin": (dr.sin, _f(np.sin)),
    "Cos": (dr.cos, _f(np.cos)),
    "Tan": (dr.tan, _f(np.tan)),
    "Asin": (dr.asin, _f(np.arcsin)),
    "Acos": (dr.acos, _f(np.arccos)),
    "Atan": (dr.atan, _f(np.arctan)),
    "Atan2": (dr.atan2, _f(np.arctan2)),
    "Pow": (gl_pow, _py_pow),
    "Exp": (dr.exp, _f(np.exp)),
    "Log": (dr.log, _f(np.log)),
    "Exp2": (dr.exp2, _f(np.exp2)),
    "Log2": (dr.log2, _f(np.log2)),
    "Sqrt": (dr.sqrt, _f(np.sqrt)),
    "InverseSqrt": (dr.rsqrt, _f(lambda x: 1 / np.sqrt(x))),
    "FMin": (dr.minimum, _f(np.minimum)),
    "FMax": (dr.maximum, _f(np.maximum)),
    "NMin": (dr.minimum, _f(np.fmin)),
    "NMax": (dr.maximum, _f(np.fmax)),
    "SMin": (dr.minimum, min),
    "SMax": (dr.maximum, max),
    "UMin": (dr.minimum, min),
    "UMax": (dr.maximum, max),
    "FClamp": (clamp, _f(lambda x, a, b: np.minimum(np.maximum(x, a), b))),
    "NClamp": (clamp, _f(lambda x, a, b: np.minimum(np.maximum(x, a), b))),
    "SClamp": (clamp, lambda x, a, b: min(max(x, a), b)),
    "UClamp": (clamp, lambda x, a, b: min(max(x, a), b)),
    "FMix": (mix, _f(lambda x, y, a: x * (1 - a) + y * a)),
    "Step": (lambda e, x: dr.select(x < e, 0.0, 1.0), lambda e, x: 0.0 if x < e else 1.0),
    "SmoothStep": (_smoothstep, _f(_smoothstep)),
    "Fma": (dr.fma, _f(lambda a, b, c: a * b + c)),
}


def std450(m, name: str, args: list, result_is_vector: bool):
    """GLSL.std.450 instruction ``name`` on the executor's values; None if unsupported."""
    if name in STD450:
        f, py = STD450[name]
        if isinstance(args[0], list) or any(isinstance(a, list) for a in args):
            n = max(len(a) for a in args if isinstance(a, list))
            args = [a if isinstance(a, list) else [a] * n for a in args]  # scalar operands
        return cw(_fold(f, py), *args)
    if name == "Length":
        return length(m, args[0])
    if name == "Distance":
        return length(m, cw(BINARY["OpFSub"], args[0], args[1]))
    if name == "Normalize":
        return normalize(m, args[0])
    if name == "Cross":
        (a0, a1, a2), (b0, b1, b2) = args
        sub, mul = BINARY["OpFSub"], BINARY["OpFMul"]
        return [
            sub(mul(a1, b2), mul(a2, b1)),
            sub(mul(a2, b0), mul(a0, b2)),
            sub(mul(a0, b1), mul(a1, b0)),
        ]
    if name == "Reflect":
        return reflect(m, *args)
    if name == "Refract":
        return refract(m, *args)
    if name == "FaceForward":
        n, i, nref = args
        d = dot(m, nref, i)
        return [dr.select(d < 0.0, x, -x) if not is_py(d) else (x if d < 0 else -x) for x in n]
    return None


class Mask:
    """A lane mask: ``value`` is a Python bool (the same on every lane) or a Dr.Jit ``Bool``.
    ``parent``/``cond``/``polarity`` record that it is ``parent & (cond == polarity)``, so
    :func:`join` of the two edges of one branch gives back ``parent`` itself."""

    __slots__ = ("value", "parent", "cond", "polarity")

    def __init__(self, value, parent=None, cond=None, polarity=True):
        self.value, self.parent, self.cond, self.polarity = value, parent, cond, polarity

    @property
    def static(self) -> bool:
        return isinstance(self.value, bool)


TRUE, FALSE = Mask(True), Mask(False)


def branch(mask: Mask, cond, polarity: bool) -> Mask:
    """The lanes of ``mask`` where ``cond`` (a scalar) equals ``polarity``."""
    if mask.value is False:
        return FALSE
    if isinstance(cond, bool):
        return mask if cond == polarity else FALSE
    c = cond if polarity else ~cond
    return Mask(c if mask.value is True else mask.value & c, mask, cond, polarity)


def both(a: Mask, b: Mask) -> Mask:
    """Lanes in ``a`` and in ``b``."""
    if a.value is False or b.value is False:
        return FALSE
    if a.value is True:
        return b
    if b.value is True:
        return a
    return Mask(a.value & b.value)


def join(masks: list) -> Mask:
    """The union of disjoint masks (the incoming edges of a block)."""
    masks = [k for k in masks if k.value is not False]
    merged = True
    while merged and len(masks) > 1:
        merged = False
        for i in range(len(masks)):
            for j in range(i + 1, len(masks)):
                a, b = masks[i], masks[j]
                if a.parent is not None and a.parent is b.parent and a.cond is b.cond:
                    masks = [k for n, k in enumerate(masks) if n not in (i, j)] + [a.parent]
                    merged = True
                    break
            if merged:
                break
    if not masks:
        return FALSE
    out = masks[0]
    for k in masks[1:]:
        if out.value is True or k.value is True:
            return TRUE
        out = Mask(out.value | k.value)
    return out
