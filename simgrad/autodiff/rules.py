"""Derivative rules, one entry per differentiable Op.

A reverse (VJP) rule gets the IR builder `b`, the adjoint of the result `g` and the operand values, and
returns the contribution to each operand's adjoint (None: no contribution), emitted with the builder:
`lambda b, g, a: (b.mul(g, b.cos(a)),)`. Python numbers stand for constants of the other operand's type.
`NEEDS_VALUES` ops need their operand values in the backward pass (nonlinear ops); the others are
linear. Ops listed in `ZERO_GRADIENT` are piecewise constant: their derivative is zero almost everywhere,
which is what we propagate. Any float op without an entry here makes the transform raise a
GradientError naming it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from simgrad.ir.ops import Op


def _div(b, g, x, y):
    return b.div(g, y), b.neg(b.div(b.mul(g, x), b.mul(y, y)))


def _pow(b, g, x, y):
    dx = b.mul(g, b.mul(y, b.pow(x, b.sub(y, 1.0))))
    positive = b.gt(x, 0.0)
    safe = b.select(positive, x, 1.0)
    dy = b.select(positive, b.mul(g, b.mul(b.pow(x, y), b.log(safe))), 0.0)
    return dx, dy


def _atan2(b, g, y, x):
    r = b.add(b.mul(x, x), b.mul(y, y))
    return b.div(b.mul(g, x), r), b.neg(b.div(b.mul(g, y), r))


def _min(b, g, x, y):
    first = b.le(x, y)  # ties go to the first operand
    return b.select(first, g, 0.0), b.select(first, 0.0, g)


def _max(b, g, x, y):
    first = b.ge(x, y)
    return b.select(first, g, 0.0), b.select(first, 0.0, g)


def _abs(b, g, x):
    return (b.select(b.gt(x, 0.0), g, b.select(b.lt(x, 0.0), b.neg(g), 0.0)),)


def _tan(b, g, x):
    t = b.tan(x)
    return (b.mul(g, b.add(b.mul(t, t), 1.0)),)


def _tanh(b, g, x):
    t = b.tanh(x)
    return (b.mul(g, b.sub(1.0, b.mul(t, t))),)


# (builder, g, *operands) -> one contribution (or None) per operand
REVERSE: dict[Op, Callable[..., tuple]] = {
    Op.ADD: lambda b, g, x, y: (g, g),
    Op.SUB: lambda b, g, x, y: (g, b.neg(g)),
    Op.MUL: lambda b, g, x, y: (b.mul(g, y), b.mul(g, x)),
    Op.DIV: _div,
    Op.NEG: lambda b, g, x: (b.neg(g),),
    Op.POW: _pow,
    Op.MIN: _min,
    Op.MAX: _max,
    Op.ATAN2: _atan2,
    Op.SQRT: lambda b, g, x: (b.div(b.mul(g, 0.5), b.sqrt(x)),),
    Op.RSQRT: lambda b, g, x: (b.mul(b.mul(g, -0.5), b.div(b.rsqrt(x), x)),),
    Op.SIN: lambda b, g, x: (b.mul(g, b.cos(x)),),
    Op.COS: lambda b, g, x: (b.neg(b.mul(g, b.sin(x))),),
    Op.TAN: _tan,
    Op.ASIN: lambda b, g, x: (b.div(g, b.sqrt(b.sub(1.0, b.mul(x, x)))),),
    Op.ACOS: lambda b, g, x: (b.neg(b.div(g, b.sqrt(b.sub(1.0, b.mul(x, x))))),),
    Op.EXP: lambda b, g, x: (b.mul(g, b.exp(x)),),
    Op.LOG: lambda b, g, x: (b.div(g, x),),
    Op.TANH: _tanh,
    Op.ABS: _abs,
    Op.SELECT: lambda b, g, c, x, y: (None, b.select(c, g, 0.0), b.select(c, 0.0, g)),
}
NEEDS_VALUES = {op for op in REVERSE if op not in (Op.ADD, Op.SUB, Op.NEG)}
ZERO_GRADIENT = {Op.FLOOR, Op.CEIL, Op.ROUND, Op.LT, Op.LE, Op.GT, Op.GE, Op.EQ, Op.NE, Op.LOGICAL_NOT}


def _jvp(vjp: Callable[..., tuple]) -> Callable:
    """The forward (JVP) rule of an elementwise op from its reverse rule: for a scalar op the VJP contribution
    to operand k, `g * df/dx_k`, is linear in g, so with g = dx_k it is the JVP's term df/dx_k * dx_k. The
    result is the sum of the terms of the operands that have tangents (None: no tangent at all)."""

    def rule(b, tangents, *operands):
        terms = []
        for k, d in enumerate(tangents):
            if d is not None:
                c = vjp(b, d, *operands)[k]
                if c is not None:
                    terms.append(c)
        if not terms:
            return None
        total = terms[0]
        for c in terms[1:]:
            total = b.add(total, c)
        return total

    return rule


# (builder, tangent or None per operand, *operands) -> the result's tangent (or None): one beside every
# reverse rule, so both modes differentiate exactly the same operations
FORWARD: dict[Op, Callable[..., Any]] = {op: _jvp(rule) for op, rule in REVERSE.items()}
