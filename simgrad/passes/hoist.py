"""Hoist loop-invariant integer arithmetic out of top-level parallel loops.

LLVM would hoist these too; we do it in our IR so that codegen's analyses see them as loop-invariant:
`a = t * jacobi + k; p[a, i, j] += ...` then indexes one slice `a` of p in every iteration, which is
what lets an update go to a per-thread copy of that slice (codegen/privatize.py) or count as owned.
Only operations that cannot trap are moved (a division only by a constant other than 0 and -1), so a
loop that runs zero times cannot fail because of what was hoisted out of it.
"""

from __future__ import annotations

from simgrad.ir.nodes import Kernel, Stmt
from simgrad.ir.ops import Op

_SAFE = {Op.CONST, Op.ADD, Op.SUB, Op.MUL, Op.NEG, Op.MIN, Op.MAX, Op.BIT_AND, Op.BIT_OR, Op.BIT_XOR, Op.BIT_NOT,
         Op.SHL, Op.SHR, Op.LOGICAL_NOT, Op.LT, Op.LE, Op.GT, Op.GE, Op.EQ, Op.NE, Op.SELECT, Op.CAST}
_DIVISIONS = {Op.FLOORDIV, Op.MOD, Op.RAW_DIV, Op.RAW_MOD}


def _movable(s: Stmt, loop: Stmt, inside: set) -> bool:
    if s.blocks or s.type is None or s.type.is_float:
        return False
    if not all(id(o) not in inside and o is not loop for o in s.operands):
        return False
    if s.op is Op.CAST:
        return not s.operands[0].type.is_float
    if s.op in _DIVISIONS:
        d = s.operands[1]
        return d.op is Op.CONST and d.attrs["value"] not in (0, -1)
    return s.op in _SAFE


def hoist(kernel: Kernel) -> bool:
    changed = False
    out = []
    for loop in kernel.body.stmts:
        if loop.op is Op.RANGE_FOR and loop.attrs.get("parallel"):
            inner = loop.blocks[0]
            inside = {id(x) for x in inner.stmts}  # top level of the body: nested values never qualify
            keep = []
            for s in inner.stmts:
                if _movable(s, loop, inside):
                    inside.discard(id(s))
                    s.block = kernel.body
                    out.append(s)
                    changed = True
                else:
                    keep.append(s)
            inner.stmts = keep
        out.append(loop)
    kernel.body.stmts = out
    return changed
