"""A conditional store to an element its block already stored to becomes an unconditional store of a select:

    x[p] = a; ...; if c: x[p] = b      ->      x[p] = a; ...; old = x[p]; x[p] = select(c, b, old)

The earlier store shows that the element is in bounds and written by this iteration anyway, so writing its own
value back when c is false reads and writes nothing new (another thread writing it meanwhile was a race
before). mpm's boundary conditions (`grid_v[i, j] += ...` then `if i < 3 and grid_v[i, j][0] < 0:
grid_v[i, j][0] = 0`) are then one store per component, which LLVM merges with the earlier ones; left as
branches they were masked scatters of their own in the vectorised grid loop (mpm128's grid update 0.031 ->
0.022 ms). The same holds without an earlier store when the condition is the same for the whole parallel loop
and the element is in bounds and the iteration's own (`_uniform_own`): a kernel argument picking a vector's
component.

Both sides of an if/else storing the same element (`if c: x[p] = a else: x[p] = b`, the indices from outside the
IF) store a local instead, and one store of the local follows the IF: LLVM merged a side's two adjacent zero
stores (`v[i, j] = ti.Vector([0.0, 0.0])`) into a memset the loop vectoriser cannot predicate, so
snow_phaseField's gradient loop never vectorised; with one unconditional store per element it does (the local
becomes a phi, the branch a select or a masked block).

Runs after autodiff (gradients see the program as written), on dense fields and ndarrays only (a sparse
element's store activates, a quant one is a read-modify-write of its cell)."""

from __future__ import annotations

from simgrad.ir.bounds import in_bounds
from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import PURE, Op
from simgrad.passes.parallel_strategy import injective_in


def store_select(kernel: Kernel) -> bool:
    changed = False
    for block in list(_blocks(kernel.body)):
        changed |= _in_block(block)
    return changed


def _blocks(block: Block):
    yield block
    for s in walk(block):
        yield from s.blocks


def _key(ptr: Stmt):
    return id(ptr.attrs.get("target")), tuple(id(o) for o in ptr.operands)


def _plain(ptr: Stmt) -> bool:
    t = ptr.attrs.get("target")
    return ptr.op is Op.GLOBAL_PTR and not ptr.attrs.get("lowered") and not (
        isinstance(t, FieldRef) and (t.levels or t.quant is not None))


def _in_block(block: Block) -> bool:
    stored: set = set()
    changed = False
    k = 0
    while k < len(block.stmts):
        s = block.stmts[k]
        if s.op is Op.GLOBAL_STORE and _plain(s.operands[0]):
            stored.add(_key(s.operands[0]))
        elif s.op is Op.IF:
            one = _lone_store(s, stored)
            if one is not None and (_key(one[0].operands[0]) in stored or _uniform_own(s, one[0])):
                new = _rewrite(s, *one)
                block.stmts[k:k + 1] = new
                k += len(new)
                changed = True
                continue
            pairs = _paired_stores(s)
            if pairs:
                block.stmts[k:k + 1] = new = _sink(s, pairs)
                k += len(new)
                changed = True
                continue
        k += 1
    return changed


def _uniform_own(s: Stmt, store: Stmt) -> bool:
    """Whether the IF's condition is the same for every iteration of the parallel loop it is in (no serial loop
    between) and the store's element is inside its field and written by no other iteration: then writing its
    own value back where the condition is false changes nothing anyone sees. A kernel argument choosing a
    vector's component (`v[i, j][k] = x`: one IF per component) is such a condition: its stores, kept
    conditional, were masked scatters in the vectorised loop (four per field for snow_phaseField's
    `phiRate[i, j][rk_loop]`), its selects are plain vector stores."""
    loop = s.block.parent if s.block is not None else None
    while loop is not None and loop.op is Op.IF:
        loop = loop.block.parent if loop.block is not None else None
    if loop is None or loop.op is not Op.RANGE_FOR or not loop.attrs.get("parallel"):
        return False
    inside = {id(x) for x in walk(loop.blocks[0])} | {id(loop)}
    ptr = store.operands[0]
    target = ptr.attrs.get("target")
    if id(s.operands[0]) in inside or not isinstance(target, FieldRef) or any(target.offset or ()) \
            or not in_bounds(ptr) or not injective_in(loop, ptr, inside):
        return False
    key = _key(ptr)
    return all(_key(x.operands[0]) == key for x in walk(loop.blocks[0])
               if x.op in (Op.GLOBAL_STORE, Op.ATOMIC) and x.operands[0].attrs.get("target") is target)


def _lone_store(s: Stmt, stored: set) -> tuple[Stmt, int] | None:
    """(the store, the side it is on) when one side of the IF is empty and the other is pure statements (and
    loads of elements stored before in the block) ending with one store to a plain element."""
    full = [k for k, b in enumerate(s.blocks) if b.stmts]
    if len(full) != 1:
        return None
    side = s.blocks[full[0]].stmts
    last = side[-1]
    if last.op is not Op.GLOBAL_STORE or not _plain(last.operands[0]):
        return None
    for x in side[:-1]:
        if x.blocks or not (x.op in PURE or x.op is Op.GLOBAL_LOAD and _plain(x.operands[0])
                            and _key(x.operands[0]) in stored):
            return None
    return last, full[0]


def _rewrite(s: Stmt, store: Stmt, side: int) -> list[Stmt]:
    """The side's statements, the old value's load, the select and one store, in the IF's block."""
    hoisted = s.blocks[side].stmts[:-1]
    scratch = Block()
    b = Builder(scratch)
    b.loc = store.loc
    ptr, value = store.operands
    old = b.emit(Op.GLOBAL_LOAD, ptr.type, (ptr,), {"own_store": True})  # what this iteration stored: not in place
    chosen = b.select(s.operands[0], value, old) if side == 0 else b.select(s.operands[0], old, value)
    b.emit(Op.GLOBAL_STORE, None, (ptr, chosen))
    out = [*hoisted, *scratch.stmts]
    for x in out:
        x.block = s.block
    return out


#: what may follow a sunk store on its side: no exit from the side, no call or assert, nothing sparse
_UNSINKABLE = {Op.BREAK, Op.CONTINUE, Op.FUNC_RETURN, Op.CALL, Op.ASSERT, Op.SNODE_OP, Op.SPARSE_CELL,
               Op.SPARSE_ACTION}


def _side_stores(side: Block, inner: set) -> dict:
    """key -> the side's one top-level store of a plain element whose indices come from outside the IF, which
    nothing after it on the side (nested blocks included) touches the field of or leaves the side past."""
    found: dict = {}
    for k, s in enumerate(side.stmts):
        if s.op is not Op.GLOBAL_STORE or not _plain(s.operands[0]):
            continue
        ptr = s.operands[0]
        if any(id(o) in inner for o in ptr.operands):
            continue
        target = ptr.attrs.get("target")
        later = [x for y in side.stmts[k + 1:] for x in (y, *_inner(y))]
        if any(x.op in _UNSINKABLE or any(o.op is Op.GLOBAL_PTR and o.attrs.get("target") is target
                                          for o in (x, *x.operands)) for x in later):
            continue
        key = _key(ptr)
        found[key] = None if key in found else s  # stored twice: not moved
    return {key: s for key, s in found.items() if s is not None}


def _inner(s: Stmt):
    """The statements nested in `s`."""
    for b in s.blocks:
        yield from walk(b)


def _paired_stores(s: Stmt) -> list[tuple[Stmt, Stmt]]:
    """(then-store, else-store) pairs of the same element, at most one per field (distinct places)."""
    if len(s.blocks) != 2 or not all(b.stmts for b in s.blocks):
        return []
    inner = {id(x) for x in _inner(s)}
    then, other = (_side_stores(b, inner) for b in s.blocks)
    pairs, fields = [], set()
    for key, st in then.items():
        if key in other and key[0] not in fields:
            fields.add(key[0])
            pairs.append((st, other[key]))
    return pairs


def _sink(s: Stmt, pairs: list[tuple[Stmt, Stmt]]) -> list[Stmt]:
    """A local per pair ahead of the IF, each side's store storing it instead, one store of it after the IF."""
    before, after = Block(), Block()
    b, a = Builder(before), Builder(after)
    for one, two in pairs:
        ptr, value = one.operands
        b.loc = a.loc = one.loc
        local = b.emit(Op.ALLOCA, value.type)
        for st in (one, two):
            side = st.block
            assert side is not None
            at = side.stmts.index(st)
            new = Builder.detached(Op.LOCAL_STORE, None, (local, st.operands[1]), None, st.loc, side)
            side.stmts[at] = new
        where = a.emit(Op.GLOBAL_PTR, ptr.type, ptr.operands, dict(ptr.attrs))
        a.emit(Op.GLOBAL_STORE, None, (where, a.emit(Op.LOCAL_LOAD, value.type, (local,))))
    out = [*before.stmts, s, *after.stmts]
    for x in out:
        x.block = s.block
    return out
