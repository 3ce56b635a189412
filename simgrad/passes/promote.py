"""Local promotion: a local assigned exactly once becomes its value.

Locals are ALLOCAs in our IR (LLVM's mem2reg turns them into registers later). A local with one store,
in the block that declares it, holds that store's value at every load after it, so those loads can use
the value directly. That is what lets our own analyses see through `a = t * jacobi + k; p[a, i, j]`
(the index is then an expression of loop-invariant values, see passes/hoist.py). Locals written more
than once, updated with `+=` (ATOMIC) or captured any other way are left alone.
"""

from __future__ import annotations

from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import Op


def promote(kernel: Kernel) -> bool:
    stores: dict[int, int] = {}
    blocked: set[int] = set()
    for s in walk(kernel.body):
        for k, o in enumerate(s.operands):
            if o.op is not Op.ALLOCA:
                continue
            if s.op is Op.LOCAL_STORE and k == 0:
                stores[id(o)] = stores.get(id(o), 0) + 1
            elif s.op is not Op.LOCAL_LOAD:
                blocked.add(id(o))
    once = {a for a, n in stores.items() if n == 1 and a not in blocked}
    if not once:
        return False
    value_of: dict[int, Stmt] = {}  # LOCAL_LOAD -> the stored value
    _forward(kernel.body, once, {}, value_of)
    if not value_of:
        return False
    left = set()
    for s in walk(kernel.body):
        if s.op is Op.LOCAL_LOAD and id(s) not in value_of:
            left.add(id(s.operands[0]))
    gone = once - left  # no load left: the local and its store go too
    _rewrite(kernel.body, value_of, gone)
    return True


def _forward(block: Block, once: set, known: dict, value_of: dict) -> None:
    """Walk in program order; a single store in the alloca's own block dominates everything after it."""
    known = dict(known)
    declared = {id(s) for s in block.stmts if s.op is Op.ALLOCA}
    for s in block.stmts:
        if s.op is Op.LOCAL_LOAD and id(s.operands[0]) in known:
            value_of[id(s)] = known[id(s.operands[0])]
        for b in s.blocks:
            _forward(b, once, known, value_of)
        if s.op is Op.LOCAL_STORE and id(s.operands[0]) in once and id(s.operands[0]) in declared:
            known[id(s.operands[0])] = s.operands[1]


def _rewrite(block: Block, value_of: dict, gone: set) -> None:
    keep = []
    for s in block.stmts:
        if id(s) in value_of or id(s) in gone or (s.op is Op.LOCAL_STORE and id(s.operands[0]) in gone):
            continue  # the load itself goes away, and so does a local nobody reads any more
        if any(id(o) in value_of for o in s.operands):
            s.operands = tuple(_resolve(o, value_of) for o in s.operands)
        for b in s.blocks:
            _rewrite(b, value_of, gone)
        keep.append(s)
    block.stmts = keep


def _resolve(o: Stmt, value_of: dict) -> Stmt:
    while id(o) in value_of:  # a stored value may itself be a promoted load
        o = value_of[id(o)]
    return o
