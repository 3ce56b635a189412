"""Digits of a flattened loop index: struct-for and ndrange loops run over one flat index L and recover
their indices as `(L // d) % m` (raw division by constants). Ownership (passes/parallel_strategy.py)
and affine addressing (passes/lower_access.py) both ask which index values form such a chain."""

from __future__ import annotations

from collections.abc import Sequence

from simgrad.ir.nodes import Stmt
from simgrad.ir.ops import Op


def digit_of(o: Stmt, loop: Stmt) -> tuple[int, int] | None:
    """(divisor, modulus or 0) when o is (loop // divisor) % modulus by raw division by constants."""
    mod = 0
    if o.op is Op.RAW_MOD and o.operands[1].op is Op.CONST:
        mod = o.operands[1].attrs["value"]
        o = o.operands[0]
    div = 1
    while o.op is Op.RAW_DIV and o.operands[1].op is Op.CONST and o.operands[1].attrs["value"] > 0:
        div *= o.operands[1].attrs["value"]
        o = o.operands[0]
    return (div, mod) if o is loop and mod >= 0 else None


def digit_chain(values: Sequence[Stmt], loop: Stmt) -> list[tuple[int, int, int]] | None:
    """The digits among `values` that together determine the loop index, lowest first, as
    (position in values, divisor, modulus): the first has divisor 1, each next one's divisor is the
    previous divisor times its modulus, and the last has no modulus. Where several values are digits at
    one place, one without modulus ends the chain, else the widest continues it. None if no chain."""
    at: dict[int, list[tuple[int, int]]] = {}
    for k, v in enumerate(values):
        d = digit_of(v, loop)
        if d is not None:
            at.setdefault(d[0], []).append((d[1], k))
    chain = []
    place = 1
    while place in at:
        mod, k = min(at[place], key=lambda mk: (mk[0] != 0, -mk[0], mk[1]))  # no modulus, else the widest
        chain.append((k, place, mod))
        if mod == 0:
            return chain
        if mod <= 1:
            return None
        place *= mod
    return None
