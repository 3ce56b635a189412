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


# Ownership (passes/parallel_strategy.py) also accepts digits by loop-invariant values: a struct-for over an
# ndarray splits its flat index by the array's run-time extents (`L % n`, `(L // n) % m`, `L // n // m`).
Divisor = tuple  # (product of the constant divisors, sorted ids of the loop-invariant ones)


def invariant_digit(o: Stmt, loop: Stmt, inside: set) -> tuple[Divisor, object] | None:
    """(divisor, modulus) when o is (loop // divisor) % modulus by raw division by positive constants or by values
    from before the loop (`inside`: ids of the loop body's statements); modulus: a constant >= 2, the id of a
    loop-invariant value as ("v", id), or 0 for none."""

    def invariant(x: Stmt) -> bool:
        return x.op is not Op.CONST and x is not loop and id(x) not in inside

    mod: object = 0
    if o.op is Op.RAW_MOD:
        m = o.operands[1]
        if m.op is Op.CONST and m.attrs["value"] >= 2:
            mod = m.attrs["value"]
        elif invariant(m):
            mod = ("v", id(m))
        else:
            return None
        o = o.operands[0]
    const, ids = 1, []
    while o.op is Op.RAW_DIV:
        d = o.operands[1]
        if d.op is Op.CONST and d.attrs["value"] > 0:
            const *= d.attrs["value"]
        elif invariant(d):
            ids.append(id(d))
        else:
            return None
        o = o.operands[0]
    return ((const, tuple(sorted(ids))), mod) if o is loop else None


def invariant_chain(values: Sequence[Stmt], loop: Stmt, inside: set) -> bool:
    """Whether digits among `values` (invariant_digit) determine the loop index: from divisor 1, each next
    divisor the previous one times its modulus, up to a digit without modulus (then the index is the sum of
    digit x divisor along the chain, whatever the run-time extents)."""
    at: dict[Divisor, list] = {}
    for v in values:
        d = invariant_digit(v, loop, inside)
        if d is not None:
            at.setdefault(d[0], []).append(d[1])

    def reaches_end(place: Divisor, depth: int) -> bool:
        mods = at.get(place, [])
        if 0 in mods:
            return True
        for m in mods if depth < len(values) else ():
            if isinstance(m, int):
                nxt = (place[0] * m, place[1])
            else:
                assert isinstance(m, tuple)
                nxt = (place[0], tuple(sorted((*place[1], m[1]))))
            if reaches_end(nxt, depth + 1):
                return True
        return False

    return reaches_end((1, ()), 0)
