"""Local simplification: constant folding, algebraic identities, common subexpressions, dead code.

Every elementwise op with constant operands folds to exactly what the instruction computes at its type
(ir/opdefs.py through ir/numeric.py): integers wrap, floats round at their width (f16 through f32, as
LLVM promotes it), math functions are the very libm calls the kernel would make, float min/max return the
non-NaN operand (llvm.minnum), integer division by zero is not folded; identities keep the sign of zero
(x + 0.0 is not x when x is -0.0)."""

from __future__ import annotations

import math

from simgrad.ir import ops as O
from simgrad.ir.builder import Builder
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import OPS, Op


def simplify(kernel: Kernel) -> bool:
    changed = False
    while True:
        uses = _replace_pass(kernel.body, {}, {})
        uses += _fold_branches(kernel.body)
        removed = _dce(kernel.body, _use_counts(kernel.body))
        if not (uses or removed):
            return changed
        changed = True


def _const(s: Stmt):
    return s.attrs["value"] if s.op is Op.CONST else None


def fold(s: Stmt):
    """The constant value of an elementwise statement whose operands are all constants (ir/opdefs.py: exactly
    what the instruction computes at its type), or None."""
    d = OPS.get(s.op)
    if d is None or not s.operands:
        return None
    values = []
    for o in s.operands:
        if o.op is not Op.CONST:
            return None
        values.append(o.attrs["value"])
    return d.fold(s.operands[0].vtype, *values)


_IDENTITY_OPS = {Op.ADD, Op.SUB, Op.MUL, Op.CAST, Op.SELECT}


def _identity(s: Stmt):
    """x + 0, x * 1, x - 0 -> x (integers, and floats where exact); select(c, a, b) with a constant c -> a or b."""
    if s.op not in _IDENTITY_OPS:
        return None
    if s.op is Op.SELECT:
        c = _const(s.operands[0])
        return None if c is None or s.operands[1].type is not s.type or s.operands[2].type is not s.type \
            else s.operands[1] if c else s.operands[2]
    if s.op in (Op.ADD, Op.SUB, Op.MUL) and len(s.operands) == 2:
        a, b = s.operands
        cb, ca = _const(b), _const(a)
        if s.op in (Op.ADD, Op.SUB) and cb == 0 and (not s.vtype.is_float or _keeps_sign(s.op, cb)):
            return a
        if s.op is Op.ADD and ca == 0 and (not s.vtype.is_float or _keeps_sign(s.op, ca)):
            return b
        if s.op is Op.MUL and cb == 1:
            return a
        if s.op is Op.MUL and ca == 1:
            return b
    if s.op is Op.CAST and s.operands[0].type is s.type:
        return s.operands[0]
    return None


def _keeps_sign(op: Op, zero: float) -> bool:
    """x + (-0.0) and x - 0.0 are x for every x; x + 0.0 is +0.0 for x = -0.0."""
    negative = math.copysign(1.0, zero) < 0
    return negative if op is Op.ADD else not negative


def _key(s: Stmt, repl):
    """A hashable identity of a pure statement's value (None: not a CSE candidate). Constants count by
    value (each is its own object), and an integer `x + (-c)` is `x - c`, so `t + t_offset` with
    t_offset = -1 and `t - 1` are one value (one slice of a field for the parallel analyses)."""
    if s.op not in O.PURE or s.op is Op.ARG:
        return None
    if s.op is Op.GLOBAL_PTR and getattr(s.attrs["target"], "sparse", False):
        return None  # a sparse element's write activates at its own place: a read must not share it
    op, operands = s.op, [("c", o.type, _const_key(o)) if o.op is Op.CONST else id(o) for o in s.operands]
    if op is Op.ADD and not s.vtype.is_float and isinstance(operands[1], tuple) and operands[1][2] < 0:
        op, operands[1] = Op.SUB, ("c", operands[1][1], -operands[1][2])
    return (op, s.type, tuple(operands), tuple(s.attrs.items()))


def _const_key(c: Stmt):
    """A constant's value as a key: -0.0 and 0.0 are equal in Python but not the same operand (`cast -0.0` and
    `cast 0.0` were one value once promote forwarded constants into them)."""
    v = c.attrs["value"]
    return (v, math.copysign(1.0, v)) if c.vtype.is_float else v


def _replace_pass(block: Block, repl: dict, seen: dict) -> int:
    n = 0
    seen = dict(seen)
    for s in block.stmts:
        if any(id(o) in repl for o in s.operands):
            s.operands = tuple(repl.get(id(o), o) for o in s.operands)
            n += 1
        folded = fold(s)
        if folded is not None:
            repl[id(s)] = Builder.constant(folded, s.vtype, s.loc)
            n += 1
            continue
        ident = _identity(s)
        if ident is not None:
            repl[id(s)] = ident
            n += 1
            continue
        k = _key(s, repl)
        if k is not None:
            if k in seen:
                repl[id(s)] = seen[k]
                n += 1
                continue
            seen[k] = s
        inner = seen
        if s.op is Op.RANGE_FOR and s.attrs.get("parallel"):
            # a parallel loop becomes a task that captures outside values by value: an address must be
            # recomputed inside it, not shared
            inner = {k: v for k, v in seen.items() if v.op is not Op.GLOBAL_PTR}
        for b in s.blocks:
            n += _replace_pass(b, repl, inner)
    return n


def _fold_branches(block: Block) -> int:
    """`if c` with a constant c is the branch it takes, its statements in the enclosing block (`if lsq > 0.5` on a
    compile-time vector's length; `if lin < 0` once promote has forwarded a zeroed vector)."""
    n = 0
    out: list[Stmt] = []
    for s in block.stmts:
        for b in s.blocks:
            n += _fold_branches(b)
        c = _const(s.operands[0]) if s.op is Op.IF else None
        if c is None:
            out.append(s)
            continue
        taken = s.blocks[0] if c else s.blocks[1] if len(s.blocks) > 1 else None
        for t in taken.stmts if taken is not None else ():
            t.block = block
            out.append(t)
        n += 1
    block.stmts = out
    return n


def _use_counts(block: Block) -> dict:
    counts: dict[int, int] = {}
    for s in walk(block):
        for o in s.operands:
            counts[id(o)] = counts.get(id(o), 0) + 1
    return counts


def _dce(block: Block, counts: dict) -> int:
    removed = 0
    keep = []
    for s in block.stmts:
        for b in s.blocks:
            removed += _dce(b, counts)
        if s.op not in O.SIDE_EFFECTS and s.op is not Op.ALLOCA and counts.get(id(s), 0) == 0:
            removed += 1
            continue
        keep.append(s)
    block.stmts = keep
    return removed
