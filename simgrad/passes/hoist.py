"""Hoist loop-invariant integer arithmetic out of top-level parallel loops.

LLVM would hoist these too; we do it in our IR so that codegen's analyses see them as loop-invariant:
`a = t * jacobi + k; p[a, i, j] += ...` then indexes one slice `a` of p in every iteration, which is
what lets an update go to a per-thread copy of that slice (codegen/privatize.py) or count as owned.
Only operations that cannot trap or report are moved (a division only by a constant other than 0 and -1, no
debug-mode overflow check), so a loop that runs zero times cannot fail because of what was hoisted out of it.
"""

from __future__ import annotations

from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import Op

_SAFE = {Op.CONST, Op.ADD, Op.SUB, Op.MUL, Op.NEG, Op.MIN, Op.MAX, Op.BIT_AND, Op.BIT_OR, Op.BIT_XOR, Op.BIT_NOT,
         Op.SHL, Op.SHR, Op.LOGICAL_NOT, Op.LT, Op.LE, Op.GT, Op.GE, Op.EQ, Op.NE, Op.SELECT, Op.CAST}
_DIVISIONS = {Op.FLOORDIV, Op.MOD, Op.RAW_DIV, Op.RAW_MOD}


def _movable(s: Stmt, loop: Stmt, inside: set) -> bool:
    if s.blocks or s.type is None or s.type.is_float or "overflow" in s.attrs:
        return False  # (a debug-mode overflow report is printed where, and only if, the user's code runs)
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
    out: list[Stmt] = []
    for loop in kernel.body.stmts:
        if loop.op is Op.RANGE_FOR and loop.attrs.get("parallel"):
            # every value computed in the loop, nested serial loops and branches included (`a = k + t * n`
            # evaluated in an inner loop of an adjoint is still one slice for the whole launch)
            inside = {id(x) for x in walk(loop.blocks[0])}
            changed |= _hoist_block(loop.blocks[0], loop, inside, kernel, out)
        out.append(loop)
    kernel.body.stmts = out
    return changed


def _hoist_block(block: Block, loop: Stmt, inside: set, kernel: Kernel, out: list) -> bool:
    """Move the movable statements of `block` and of the blocks nested in it, in order, to `out`."""
    changed = False
    keep = []
    for s in block.stmts:
        if _movable(s, loop, inside):
            inside.discard(id(s))
            s.block = kernel.body
            out.append(s)
            changed = True
            continue
        for b in s.blocks:
            changed |= _hoist_block(b, loop, inside, kernel, out)
        keep.append(s)
    block.stmts = keep
    return changed
