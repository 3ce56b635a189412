"""Which statements of a run-time choice's sides (`a and b`, `a or b`, `x if c else y`) may run before the
choice is known: then both sides are computed and a select picks one, with no branch around them. Pure
arithmetic may (integer division by zero does not trap: codegen divides by 1), and so may a load of a
dense field element whose indices are provably inside the field's shape, such as the element a
struct-for visits (`i < 3 and grid_v[i, j][0] < 0`): reading it cannot fault and nothing but the choice
sees its value. A call, a store, a print, a debug overflow report, an index check, an ndarray or sparse
element, or an index not known in bounds (`i < n and x[i] > 0` must not read x[n]) keeps the branch, as
in Taichi with short_circuit_operators."""

from __future__ import annotations

from simgrad.ir import ops as O
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Stmt, walk
from simgrad.ir.ops import Op

_ALWAYS = O.PURE | {Op.LOCAL_LOAD, Op.ALLOCA}


def speculatable(blocks) -> bool:
    """May every statement of these blocks (the sides of a choice) run whether or not its side is chosen?
    Locals the sides declare may be stored to (a ti.func's parameters), nothing else."""
    own = {x for b in blocks for x in walk(b) if x.op is Op.ALLOCA}
    for b in blocks:
        for x in walk(b):
            if x.op is Op.GLOBAL_LOAD:
                if not in_bounds(x.operands[0]):
                    return False
            elif x.op is Op.LOCAL_STORE:
                if x.operands[0] not in own:
                    return False
            elif x.op not in _ALWAYS or "overflow" in x.attrs:
                return False
    return True


def in_bounds(ptr: Stmt) -> bool:
    """Is ptr a dense field element whose every index is known to lie inside the field's shape?"""
    if ptr.op is not Op.GLOBAL_PTR:
        return False
    t = ptr.attrs.get("target")
    if not isinstance(t, FieldRef) or t.levels:
        return False
    shape = t.shape
    if len(ptr.operands) != len(shape):
        return False
    for i, n in zip(ptr.operands, shape):
        r = value_range(i)
        if r is None or r[0] < 0 or r[1] >= n:
            return False
    return True


def value_range(s: Stmt, depth: int = 0) -> tuple[int, int] | None:
    """[lo, hi] that the integer value of s lies in, when the IR shows it: constants, the index of a loop
    with constant bounds, and raw digits, casts, sums and differences of those; None otherwise."""
    if depth > 16 or s.type is None or not s.type.is_int:
        return None
    if s.op is Op.LOCAL_LOAD:
        v = _stored_value(s)
        return None if v is None else value_range(v, depth + 1)
    if s.op is Op.CONST:
        v = s.attrs["value"]
        return (v, v) if isinstance(v, int) else None
    if s.op is Op.RANGE_FOR:
        b, e = (x.attrs["value"] if x.op is Op.CONST else None for x in s.operands[:2])
        return (b, e - 1) if isinstance(b, int) and isinstance(e, int) and e > b else None
    if s.op is Op.CAST and s.operands[0].type.is_int:
        r = value_range(s.operands[0], depth + 1)
        return r if r is not None and _fits(r, s.type) else None
    if s.op in (Op.RAW_DIV, Op.RAW_MOD, Op.ADD, Op.SUB) and len(s.operands) == 2:
        a = value_range(s.operands[0], depth + 1)
        b = value_range(s.operands[1], depth + 1)
        if a is None or b is None:
            return None
        if s.op is Op.ADD:
            r = (a[0] + b[0], a[1] + b[1])
        elif s.op is Op.SUB:
            r = (a[0] - b[1], a[1] - b[0])
        elif a[0] < 0 or b[0] != b[1] or b[0] <= 0:  # raw digits of a non-negative index by a constant
            return None
        elif s.op is Op.RAW_DIV:
            r = (a[0] // b[0], a[1] // b[0])
        else:
            r = a if a[1] < b[0] else (0, b[0] - 1)
        return r if _fits(r, s.type) else None  # a wrapping sum is not its interval
    return None


def _stored_value(load: Stmt) -> Stmt | None:
    """The value a local holds at `load` when it is written once, in the block that declares it, before the
    load, and the load is in no loop nested in that block (a ti.func's parameter, a name assigned once): else
    None. A write after the load can then reach it only through the block's start, past that one write."""
    a = load.operands[0]
    home = a.block
    if a.op is not Op.ALLOCA or not isinstance(home, Block):
        return None
    writes = [x for x in walk(home) if x is not load and a in x.operands and x.op is not Op.LOCAL_LOAD]
    if len(writes) != 1 or writes[0].op is not Op.LOCAL_STORE or writes[0].block is not home:
        return None
    x = load
    while x.block is not home:  # the load's statement in the declaring block
        if x.block is None or x.block.parent is None or x.block.parent.op in (Op.RANGE_FOR, Op.WHILE):
            return None  # inside a loop of the block, a write after the load would reach it next time round
        x = x.block.parent
    return writes[0].operands[1] if home.stmts.index(writes[0]) < home.stmts.index(x) else None


def _fits(r: tuple[int, int], t) -> bool:
    bits = t.bits
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if t.is_signed else (0, (1 << bits) - 1)
    return lo <= r[0] and r[1] <= hi
