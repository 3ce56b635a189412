"""A conditional store to an element its block already stored to becomes an unconditional store of a select:

    x[p] = a; ...; if c: x[p] = b      ->      x[p] = a; ...; old = x[p]; x[p] = select(c, b, old)

The earlier store shows that the element is in bounds and written by this iteration anyway, so writing its own
value back when c is false reads and writes nothing new (another thread writing it meanwhile was a race
before). mpm's boundary conditions (`grid_v[i, j] += ...` then `if i < 3 and grid_v[i, j][0] < 0:
grid_v[i, j][0] = 0`) are then one store per component, which LLVM merges with the earlier ones; left as
branches they were masked scatters of their own in the vectorised grid loop (mpm128's grid update 0.031 ->
0.022 ms). Runs after autodiff (gradients see the program as written), on dense fields and ndarrays only
(a sparse element's store activates, a quant one is a read-modify-write of its cell)."""

from __future__ import annotations

from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import PURE, Op


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
            if one is not None and _key(one[0].operands[0]) in stored:
                new = _rewrite(s, *one)
                block.stmts[k:k + 1] = new
                k += len(new)
                changed = True
                continue
        k += 1
    return changed


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
