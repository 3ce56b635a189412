"""Derivative rules, one entry per differentiable Op.

A rule gets the adjoint of the result `g` and the operand values (as kernel expressions) and returns the
contribution to each operand's adjoint (None: no contribution). `NEEDS_VALUES` ops need their operand
values in the backward pass (nonlinear ops); the others are linear. Ops listed in `ZERO_GRADIENT` are
piecewise constant: their derivative is zero almost everywhere, which is what we propagate.
Any float op without an entry here makes the transform raise a GradientError naming it.
"""

from __future__ import annotations

from collections.abc import Callable

from simgrad.ir.ops import Op
from simgrad.lang import ops as o


def _div(g, a, b):
    return o.truediv(g, b), o.neg(o.truediv(o.mul(g, a), o.mul(b, b)))


def _pow(g, a, b):
    da = o.mul(g, o.mul(b, o.pow(a, o.sub(b, 1.0))))
    safe = o.select(o.gt(a, 0.0), a, 1.0)
    db = o.select(o.gt(a, 0.0), o.mul(g, o.mul(o.pow(a, b), o.log(safe))), 0.0)
    return da, db


def _atan2(g, y, x):
    r = o.add(o.mul(x, x), o.mul(y, y))
    return o.truediv(o.mul(g, x), r), o.neg(o.truediv(o.mul(g, y), r))


def _min(g, a, b):
    first = o.le(a, b)  # ties go to the first operand
    return o.select(first, g, 0.0), o.select(first, 0.0, g)


def _max(g, a, b):
    first = o.ge(a, b)
    return o.select(first, g, 0.0), o.select(first, 0.0, g)


def _abs(g, a):
    return (o.select(o.gt(a, 0.0), g, o.select(o.lt(a, 0.0), o.neg(g), 0.0)),)


# (g, *operands) -> one contribution (or None) per operand
REVERSE: dict[Op, Callable[..., tuple]] = {
    Op.ADD: lambda g, a, b: (g, g),
    Op.SUB: lambda g, a, b: (g, o.neg(g)),
    Op.MUL: lambda g, a, b: (o.mul(g, b), o.mul(g, a)),
    Op.DIV: _div,
    Op.NEG: lambda g, a: (o.neg(g),),
    Op.POW: _pow,
    Op.MIN: _min,
    Op.MAX: _max,
    Op.ATAN2: _atan2,
    Op.SQRT: lambda g, a: (o.truediv(o.mul(g, 0.5), o.sqrt(a)),),
    Op.RSQRT: lambda g, a: (o.mul(o.mul(g, -0.5), o.truediv(o.rsqrt(a), a)),),
    Op.SIN: lambda g, a: (o.mul(g, o.cos(a)),),
    Op.COS: lambda g, a: (o.neg(o.mul(g, o.sin(a))),),
    Op.TAN: lambda g, a: (o.mul(g, o.add(1.0, o.mul(o.tan(a), o.tan(a)))),),
    Op.ASIN: lambda g, a: (o.truediv(g, o.sqrt(o.sub(1.0, o.mul(a, a)))),),
    Op.ACOS: lambda g, a: (o.neg(o.truediv(g, o.sqrt(o.sub(1.0, o.mul(a, a))))),),
    Op.EXP: lambda g, a: (o.mul(g, o.exp(a)),),
    Op.LOG: lambda g, a: (o.truediv(g, a),),
    Op.TANH: lambda g, a: (o.mul(g, o.sub(1.0, o.mul(o.tanh(a), o.tanh(a)))),),
    Op.ABS: _abs,
    Op.SELECT: lambda g, c, a, b: (None, o.select(c, g, 0.0), o.select(c, 0.0, g)),
}
NEEDS_VALUES = {op for op in REVERSE if op not in (Op.ADD, Op.SUB, Op.NEG)}
ZERO_GRADIENT = {Op.FLOOR, Op.CEIL, Op.ROUND, Op.LT, Op.LE, Op.GT, Op.GE, Op.EQ, Op.NE, Op.LOGICAL_NOT}
