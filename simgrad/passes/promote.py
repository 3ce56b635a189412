"""Local promotion: a local assigned exactly once becomes its value.

Locals are ALLOCAs in our IR (LLVM's mem2reg turns them into registers later). A local with one store,
in the block that declares it, holds that store's value at every load after it, so those loads can use
the value directly. That is what lets our own analyses see through `a = t * jacobi + k; p[a, i, j]`
(the index is then an expression of loop-invariant values, see passes/hoist.py). Locals written more
than once, updated with `+=` (ATOMIC) or captured any other way are left alone.

A local stored several times (`v = inv_m * v_in; if c: v = [0, 0, 0]; ...`) is forwarded where its last store is
known: a load after a store in the same block or an enclosing one, with no store to it in between (a nested
block or loop that stores it, or a `+=`, makes it unknown again), reads that store's value. With simplify's
folding that removes branches nobody can take: diffmpm3d's grid_op zeroes `v_out` and then tests `lin =
v_out.dot(normal) < 0`, a nested branch whose values and decision the adjoint used to keep on its tape.
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
            if s.op is Op.LOCAL_STORE and k == 0 and len(s.operands) == 2:
                stores[id(o)] = stores.get(id(o), 0) + 1
            elif s.op is Op.ATOMIC and k == 0:  # an update: a store of a value not known here
                stores[id(o)] = stores.get(id(o), 0) + 2
            elif s.op is not Op.LOCAL_LOAD or len(s.operands) != 1:
                blocked.add(id(o))
    once = {a for a, n in stores.items() if n == 1 and a not in blocked}
    value_of: dict[int, Stmt] = {}  # LOCAL_LOAD -> the stored value
    if once:
        _forward(kernel.body, once, {}, value_of)
    many = {a for a, n in stores.items() if n > 1 and a not in blocked}
    if many:
        _forward_last(kernel.body, many, {}, value_of)
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


def _stored_in(blocks: tuple[Block, ...], many: set) -> set:
    """The candidate locals that a store or update anywhere inside `blocks` writes."""
    out = set()
    for b in blocks:
        for s in walk(b):
            if s.op in (Op.LOCAL_STORE, Op.ATOMIC) and s.operands and id(s.operands[0]) in many:
                out.add(id(s.operands[0]))
    return out


def _forward_last(block: Block, many: set, known: dict, value_of: dict) -> None:
    """Walk in program order knowing each local's last stored value; a statement with blocks (a branch, a loop)
    makes what it stores unknown after it, and a loop makes it unknown inside its body too (the back edge)."""
    known = dict(known)
    for s in block.stmts:
        if s.op is Op.LOCAL_LOAD and id(s.operands[0]) in known:
            value_of[id(s)] = known[id(s.operands[0])]
        if s.blocks:
            written = _stored_in(s.blocks, many)
            inner = {a: v for a, v in known.items() if a not in written} if s.op is not Op.IF else known
            for b in s.blocks:
                _forward_last(b, many, inner, value_of)
            known = {a: v for a, v in known.items() if a not in written}
        if s.op is Op.LOCAL_STORE and id(s.operands[0]) in many:
            known[id(s.operands[0])] = s.operands[1]
        elif s.op is Op.ATOMIC and s.operands and id(s.operands[0]) in many:
            known.pop(id(s.operands[0]), None)


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
