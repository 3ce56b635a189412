"""Derivative tables, derived from the elementwise registry (ir/opdefs.py, where each op's reverse rule
sits beside its definition) plus SELECT.

A reverse (VJP) rule gets the IR builder `b`, the adjoint of the result `g` and the operand values, and
returns the contribution to each operand's adjoint (None: no contribution), emitted with the builder.
`NEEDS_VALUES` ops need their operand values in the backward pass (nonlinear ops); the others are
linear. Ops listed in `ZERO_GRADIENT` are piecewise constant: their derivative is zero almost everywhere,
which is what we propagate. Any float op without an entry here makes the transform raise a
GradientError naming it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from simgrad.ir.opdefs import OPS
from simgrad.ir.ops import Op

# (builder, g, *operands) -> one contribution (or None) per operand
REVERSE: dict[Op, Callable[..., tuple]] = {
    **{op: d.vjp for op, d in OPS.items() if d.vjp is not None},
    Op.SELECT: lambda b, g, c, x, y: (None, b.select(c, g, 0.0), b.select(c, 0.0, g)),
}
NEEDS_VALUES = {op for op in REVERSE if not (op in OPS and OPS[op].linear)}
ZERO_GRADIENT = {op for op, d in OPS.items() if d.zero_gradient}


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
