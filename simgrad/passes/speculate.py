"""Conditional stores a parallel loop's iteration owns, made branch-free (the IF gets attrs `speculate`).

`if inside: samples[i, j, s] = colour` in a loop over the triangles of a pixel's tile (rendering/rasterizer.py)
is a branch per sample: LLVM keeps the samples apart and cannot vectorise them. When the branch's body only
computes values and stores them to elements that

- the iteration owns: among the indices are digits of the parallel loop's index that determine it
  (passes/digits.py), so no other iteration touches the element, and every access of the field in the
  loop is such an element (nothing else reads or writes it meanwhile), and
- are inside the field: every index's range, from constant loop bounds and digit arithmetic, lies in the
  field's shape, so the address is valid whether or not the condition holds,

codegen (codegen/llvm.py lower_if) emits the body unconditionally and each store as `store select(c, new,
old)`: the element is written back unchanged where the condition is false. The IR itself is untouched (the
Tape's and the torch bridge's analyses still see a conditional store); debug mode keeps the branch (its index
checks would report elements the program never writes). The four samples of a pixel then become one <4 x
float> computation (divisions included).
"""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import PURE, Op
from simgrad.passes.digits import digit_chain

_TYPES = (dt.f32, dt.f64, dt.i32, dt.i64, dt.u32, dt.u64)
_INT_LIMIT = 1 << 62  # ranges beyond this are not tracked (no overflow reasoning needed below it)


def speculate(kernel: Kernel) -> bool:
    for loop in kernel.body.stmts:
        if loop.op is Op.RANGE_FOR and loop.attrs.get("parallel"):
            _in_loop(loop)
    return False


def _in_loop(loop: Stmt) -> None:
    body = list(walk(loop.blocks[0]))
    owned: dict[int, bool] = {}  # id(field) -> every access of it in the loop is an owned element
    written: set[int] = set()  # fields the loop stores to or updates
    for x in body:
        if x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC) and x.operands[0].op is Op.GLOBAL_PTR:
            ptr = x.operands[0]
            key = id(ptr.attrs["target"])
            owned[key] = owned.get(key, True) and digit_chain(ptr.operands, loop) is not None
            if x.op is not Op.GLOBAL_LOAD:
                written.add(key)
        elif x.op is Op.CALL:
            return  # a real function could reach any field
    # a field nothing in the loop writes may be read anywhere inside it (no race with a speculated read)
    readable = {key: ok or key not in written for key, ok in owned.items()}
    ranges: dict[int, tuple[int, int] | None] = {}
    for x in body:
        if x.op is Op.IF and not x.blocks[1].stmts and _speculable(x.blocks[0], owned, readable, ranges):
            x.attrs["speculate"] = True


def _speculable(block: Block, owned: dict, readable: dict, ranges: dict) -> bool:
    stores = 0
    for s in block.stmts:
        if s.op is Op.GLOBAL_STORE:
            if not _inside(s.operands[0], owned, ranges):
                return False
            stores += 1
        elif s.op is Op.GLOBAL_LOAD:  # a read of a valid element no other iteration writes
            if not _inside(s.operands[0], readable, ranges):
                return False
        elif s.op is Op.GLOBAL_PTR:
            if not isinstance(s.attrs.get("target"), FieldRef):
                return False
        elif s.op not in PURE and s.op is not Op.LOCAL_LOAD:
            return False
    return stores > 0


def _inside(ptr: Stmt, allowed: dict, ranges: dict) -> bool:
    """An element of a dense field `allowed` says may be touched, whose indices lie in the field's shape."""
    target = ptr.attrs.get("target")
    if ptr.op is not Op.GLOBAL_PTR or not isinstance(target, FieldRef) or not allowed.get(id(target)):
        return False
    if target.sparse or target.quant is not None or target.offset or target.dtype not in _TYPES:
        return False
    shape = target.shape
    if len(shape) != len(ptr.operands):
        return False
    for idx, n in zip(ptr.operands, shape):
        r = _range(idx, ranges)
        if r is None or r[0] < 0 or r[1] >= n:
            return False
    return True


def _range(x: Stmt, memo: dict) -> tuple[int, int] | None:
    """[lo, hi] of an integer value: constants, loops with constant bounds, and + - * and division/remainder
    by positive constants of them; None when unknown."""
    if id(x) in memo:
        return memo[id(x)]
    memo[id(x)] = None  # (no cycles through loops: a loop's range comes from its bounds)
    r = _compute(x, memo)
    if r is not None and (abs(r[0]) > _INT_LIMIT or abs(r[1]) > _INT_LIMIT):
        r = None
    memo[id(x)] = r
    return r


def _compute(x: Stmt, memo: dict) -> tuple[int, int] | None:
    if x.type is None or not x.type.is_int:
        return None
    if x.op is Op.CONST:
        v = x.attrs["value"]
        return (int(v), int(v)) if isinstance(v, int) else None
    if x.op is Op.RANGE_FOR:
        a, b = (_range(o, memo) for o in x.operands[:2])
        return (a[0], b[1] - 1) if a is not None and b is not None and b[1] - 1 >= a[0] else None
    if x.op is Op.CAST:
        r = _range(x.operands[0], memo)
        return r if r is not None and _fits(r, x.type) else None
    if x.op in (Op.ADD, Op.SUB, Op.MUL):
        a, b = (_range(o, memo) for o in x.operands)
        if a is None or b is None:
            return None
        if x.op is Op.ADD:
            r = (a[0] + b[0], a[1] + b[1])
        elif x.op is Op.SUB:
            r = (a[0] - b[1], a[1] - b[0])
        else:
            p = [u * v for u in a for v in b]
            r = (min(p), max(p))
        return r if _fits(r, x.type) else None  # no wrap-around inside the range
    if x.op in (Op.RAW_DIV, Op.RAW_MOD, Op.FLOORDIV, Op.MOD) and x.operands[1].op is Op.CONST:
        c = x.operands[1].attrs["value"]
        a = _range(x.operands[0], memo)
        if not isinstance(c, int) or c <= 0 or a is None:
            return None
        if x.op in (Op.RAW_DIV, Op.RAW_MOD) and a[0] < 0:
            return None  # C's truncation: keep to the non-negative case
        if x.op in (Op.RAW_DIV, Op.FLOORDIV):
            return a[0] // c, a[1] // c
        return a if a[0] >= 0 and a[1] < c else (0, c - 1)
    return None


def _fits(r: tuple[int, int], t) -> bool:
    bits = t.bits
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if t.is_signed else (0, (1 << bits) - 1)
    return lo <= r[0] and r[1] <= hi
