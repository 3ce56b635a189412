"""Sums in serial loops, made vectorisable (ti.init(fast_math=True), Taichi's default).

1. A field element whose index does not change inside a serial loop, and which the loop only adds to with
   updates that need no atomicity (parallel_strategy said `plain`: this thread owns it), is summed in a local
   and added to the field once after the loop (Taichi's cache_loop_invariant_global_vars, for sums).
   `force[i] += f` in the inner loop of an n-body force is then a local sum instead of a load and a store of
   memory per pair, which LLVM cannot keep in a register (it cannot tell the fields apart, and the update
   may be conditional). The local starts at the sum's identity (-0.0 for floats), and the element is
   updated after the loop only where its index lies inside the field, so an element the loop did not add to
   keeps its bits and no address outside the field is ever reached.
2. Each float sum into a local inside a serial loop (`acc = acc + x`, the shape a `+=` and the sums of 1.
   take) is marked `reassoc`: codegen emits that one fadd with LLVM's reassoc flag, which lets the loop
   vectoriser split the sum into partial sums (4-5x on an n-body force). Only the sum's order changes, as
   fast-math allows; fast_math=False keeps every sum in program order and skips both steps.
3. Likewise a float min/max reduction into a local (`m = ti.min(m, x)`, `m = ti.min(m, x, y)`: every
   min of the chain from the stored value down to the load of `m`) is marked `reassoc`; codegen/arith.py
   lowers those as llvm.minimumnum/maximumnum (nsz) instead of minnum/maxnum. Both give the other operand
   for a NaN, so the values are the same (a min/max is exact: only which of two equal zeros is picked may
   change, as nsz allows), but LLVM 22 vectorises a minnum reduction without nnan only when it is the loop's
   only reduction (with a NaN check), while minimumnum reductions vectorise in any number: marching_squares'
   render loop carries two.
"""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import Op


def accumulate(kernel: Kernel, cache_sums: bool = True) -> bool:
    changed = False
    if cache_sums:
        # statements whose value something uses (an update whose old value is read cannot become a local sum);
        # the rewrites below only remove such updates or add unused ones, so one walk serves every loop
        used = {id(o) for x in walk(kernel.body) for o in x.operands}
        for loop in kernel.body.stmts:
            if loop.op is Op.RANGE_FOR and loop.attrs.get("parallel"):
                changed |= _cache_in(loop.blocks[0], used)
    changed |= _mark_local_sums(kernel)
    return changed


def _serial_loop(s: Stmt) -> bool:
    return s.op is Op.WHILE or (s.op is Op.RANGE_FOR and not s.attrs.get("parallel"))


def _cache_in(block: Block, used: set[int]) -> bool:
    """Serial loops of `block` and below, outermost first (a sum cached at an outer loop is gone from the
    inner ones)."""
    changed = False
    for s in list(block.stmts):
        if _serial_loop(s):
            changed |= _cache_loop(s, block, used)
        for b in s.blocks:
            changed |= _cache_in(b, used)
    return changed


def _memory(ref) -> tuple | None:
    """Where a dense, unquantised field's values sit (tree, byte offset); None for any other target."""
    if not isinstance(ref, FieldRef) or ref.sparse or ref.quant is not None:
        return None
    return ref.layout[0], ref.layout[1]


def _cache_loop(loop: Stmt, parent: Block, used: set[int]) -> bool:
    inside = list(_walk_loop(loop))
    ids = {id(x) for x in inside}
    by_memory: dict[tuple | None, list[Stmt]] = {}  # field memory -> its GLOBAL_PTRs in the loop
    for x in inside:
        if x.op is Op.GLOBAL_PTR:
            by_memory.setdefault(_memory(x.attrs.get("target")), []).append(x)
        elif x.op is Op.CALL:
            return False  # a real function could reach any field
    users: dict[int, list[Stmt]] = {}
    for x in inside:
        for o in x.operands:
            if o.op is Op.GLOBAL_PTR:
                users.setdefault(id(o), []).append(x)
    changed = False
    for mem, ps in by_memory.items():
        if mem is None:
            continue
        first = ps[0]
        if any(p.operands != first.operands for p in ps) or any(id(o) in ids for o in first.operands):
            continue  # indexed by something the loop changes, or by two different indices
        if len({id(p.attrs["target"]) for p in ps}) != 1:
            continue  # two records of one place: leave it to the memory
        updates = [u for p in ps for u in users.get(id(p), [])]
        if not updates or not all(_plain_sum(u) and id(u) not in used for u in updates):
            continue
        _replace(loop, parent, first, ps, updates)
        changed = True
    return changed


def _walk_loop(loop: Stmt):
    for b in loop.blocks:
        yield from walk(b)


def _plain_sum(u: Stmt) -> bool:
    return u.op is Op.ATOMIC and u.attrs.get("kind") == "add" and u.attrs.get("strategy") == "plain"


def _replace(loop: Stmt, parent: Block, ptr: Stmt, ptrs: list[Stmt], updates: list[Stmt]) -> None:
    t = updates[0].operands[1].type
    loc = loop.loc
    acc = Builder.detached(Op.ALLOCA, t, (), None, loc, parent)
    # -0.0 is the float sum's identity (x + -0.0 is x, bit for bit, -0.0 included): an element the loop did not
    # add to gets back exactly its value
    start = Builder.constant(-0.0 if t.is_float else 0, t)
    before = [acc, Builder.detached(Op.LOCAL_STORE, None, (acc, start), None, loc, parent)]
    for u in updates:  # `p += v` -> acc = acc + v
        block = u.block
        assert block is not None
        k = block.stmts.index(u)
        old = Builder.detached(Op.LOCAL_LOAD, t, (acc,), None, u.loc, block)
        new = Builder.detached(Op.ADD, t, (old, u.operands[1]), {"reassoc": True}, u.loc, block)
        block.stmts[k:k + 1] = [old, new, Builder.detached(Op.LOCAL_STORE, None, (acc, new), None, u.loc, block)]
    for p in ptrs:
        assert p.block is not None
        p.block.stmts.remove(p)
    # after the loop, `field[index] += acc`, only where the index is inside the field (the loop may have run no
    # update, and then the program never reached that address)
    after: list[Stmt] = []
    cond = None
    ref = ptr.attrs["target"]
    for axis, idx in enumerate(ptr.operands):
        lo = ref.offset[axis] if ref.offset else 0
        for op, bound in ((Op.GE, lo), (Op.LT, lo + ref.shape[axis])):
            c = Builder.detached(op, dt.i32, (idx, Builder.constant(bound, idx.type)), None, loc, parent)
            after.append(c)
            if cond is not None:
                c = Builder.detached(Op.BIT_AND, dt.i32, (cond, c), None, loc, parent)
                after.append(c)
            cond = c
    total = Builder.detached(Op.LOCAL_LOAD, t, (acc,), None, loc, parent)
    p2 = Builder.detached(Op.GLOBAL_PTR, ptr.type, ptr.operands, dict(ptr.attrs), ptr.loc, parent)
    add = Builder.detached(Op.ATOMIC, updates[0].type, (p2, total), dict(updates[0].attrs), loc, parent)
    if cond is None:
        after += [total, p2, add]
    else:
        branch = Builder.detached(Op.IF, None, (cond,), None, loc, parent, nblocks=2)
        for x in (total, p2, add):
            x.block = branch.blocks[0]
        branch.blocks[0].stmts = [total, p2, add]
        after.append(branch)
    k = parent.stmts.index(loop)
    parent.stmts[k:k + 1] = [*before, loop, *after]


def _mark_local_sums(kernel: Kernel) -> bool:
    """`a = a + x` and `a += x` (float, `a` a local) inside a serial loop whose every write of `a` is such a
    sum (a local the body also assigns afresh, such as a ti.func's parameter copy, carries no sum): the sum may
    be reassociated. The same for float min/max reductions, every write of the local one kind of them."""
    changed = False
    for loop in walk(kernel.body):
        if not _serial_loop(loop):
            continue
        sums: dict[int, list[Stmt]] = {}  # local -> the reassociable statements of its reduction
        kinds: dict[int, set] = {}  # local -> the kinds of reduction its writes are (one, or not marked)
        other: set[int] = set()
        for s in _walk_loop(loop):
            if s.op is Op.ATOMIC and s.operands[0].op is Op.ALLOCA:
                if s.type.is_float and _plain_sum(s):
                    sums.setdefault(id(s.operands[0]), []).append(s)
                    kinds.setdefault(id(s.operands[0]), set()).add(Op.ADD)
                else:
                    other.add(id(s.operands[0]))
            elif s.op is Op.LOCAL_STORE:
                var, v = s.operands
                chain = _reduction_chain(v, var)
                if chain:
                    sums.setdefault(id(var), []).extend(chain)
                    kinds.setdefault(id(var), set()).add(v.op)
                else:
                    other.add(id(var))
        for var, stmts in sums.items():
            if var in other or len(kinds[var]) > 1:
                continue
            for a in stmts:
                changed |= not a.attrs.get("reassoc")
                a.attrs["reassoc"] = True
    return changed


def _reduction_chain(v: Stmt, var: Stmt) -> list[Stmt]:
    """The statements of a float reduction step `v` of local `var`: `a + x` with `a` a load of `var`, or a
    tree of mins (maxes) with a load of `var` among its leaves (`ti.min(m, x, y)`); [] for anything else."""
    if v.type is None or not v.type.is_float or v.op not in (Op.ADD, Op.MIN, Op.MAX):
        return []
    if v.op is Op.ADD:
        return [v] if any(o.op is Op.LOCAL_LOAD and o.operands[0] is var for o in v.operands) else []
    chain, todo, found = [], [v], False
    while todo:
        x = todo.pop()
        chain.append(x)
        for o in x.operands:
            if o.op is Op.LOCAL_LOAD and o.operands[0] is var:
                found = True
            elif o.op is v.op and o.type is v.type and all(o is not c for c in chain):
                todo.append(o)
    return chain if found else []
