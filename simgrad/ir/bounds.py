"""What the IR shows of an integer value's range, and so whether a dense element's indices are inside its
field's shape: the frontend's speculation of a choice's sides (frontend/speculate.py) and
passes/store_select.py's write-back of an element a branch did not store both need it."""

from __future__ import annotations

from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Stmt, walk
from simgrad.ir.ops import Op


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
