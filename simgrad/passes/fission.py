"""Loop fission of scatters: a parallel loop whose iterations compute a lot and then scatter into shared memory
with atomic updates (MPM's particle-to-grid transfer: F update, SVD, stress, then 3x3 or 3x3x3
`grid_v[base + offset] += weight * ...`) runs its iterations W at a time in two lane loops:

    for l < n: i = base + l; part 0(i), its values the scatters use stored in lane slots    n = min(W, end - base)
    for l < n: i = base + l; part 1(i): the scatters, reading the slots

LLVM's loop vectoriser refuses a loop whose read-modify-writes may collide between iterations, so without the
split the pure part before the scatters ran one iteration at a time; part 0's lane loop is straight-line (or
if-convertible) code over lanes that it vectorises into <W x T> operations. The group loop, the lane loops and the
lane slots are passes/lanes.py's (`_Rewrite`), with two parts and no while.

Part 1 is the top-level updates that are really shared (strategy atomic, pair or a private copy's: not plain, not
a per-thread sum), whose old value nothing uses, with the pointers only they use and the integer index arithmetic
only those pointers use (recomputed from a few slots: `base`, not 27 x 3 indices); part 0 is everything else,
moved above the scatters in its order. The new order runs part 0 of W iterations before part 1 of any of them,
which nobody can observe when part 0 neither reads nor writes memory part 1 updates: memory is told apart per
place of a dense field (tree and byte offset, the components of a vector field apart; codegen/alias.py's rule),
a sparse or quant field's whole tree, all ndarrays as one (one array may be passed twice).

Results keep every bit at one thread: each part runs its lanes in iteration order, so each updated element sees
the same additions in the same order (the pool's one-thread variants: plain updates, or the fields as thread 0's
private copies). At several threads the chunks are counted in groups of W, which moves chunk boundaries; the order
of float updates between threads (atomics, or per-thread copies summed after the loop) depended on the pool's
scheduling before too, and within a thread it stays the iteration order. Per-thread float sums (strategy reduce)
are added once per chunk, so moving the boundaries would change their rounding even at one thread: such loops
are left as they are.

Run on the CPU only (not the GPU targets), not in debug mode, on forward kernels and adjoints alike.
"""

from __future__ import annotations

from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Kernel, Stmt, walk
from simgrad.ir.ops import PURE, Op
from simgrad.passes.lanes import _jumps_out, _Rewrite, _walk_list, rewrite_loops
from simgrad.passes.parallel_strategy import PLAIN, REDUCE, LoopStrategy, _independent

#: never in a split loop: calls and sparse structure ops may do anything, the tape is a per-thread stack whose
#: order the split would change, prints and asserts order themselves against the scatters, loops are not
#: straight-line code the vectoriser can take
_REFUSED = {Op.CALL, Op.SNODE_OP, Op.SPARSE_CELL, Op.SPARSE_ACTION, Op.TAPE_RESET, Op.TAPE_PUSH, Op.TAPE_POP,
            Op.CHECK_INDEX, Op.RET_STORE, Op.FUNC_RETURN, Op.PRINT, Op.ASSERT, Op.WHILE, Op.RANGE_FOR,
            Op.BREAK, Op.CONTINUE}
#: float arithmetic part 0 must hold for the split to pay: a few values computed and scattered gain nothing from
#: a vectorised part 0 and pay for the slots
MIN_FLOAT_OPS = 16
#: float operations of part 0 per scatter below which the split is left out: each scattered value costs a slot
#: store in part 0 and a load in part 1. diffmpm3d's p2g (27 x 4 values, 7.2 float operations per scatter) measured
#: slower split in the example (kernel profiler, one thread: min 1.5 -> 2.1 ms a call, with a cell's values sharing
#: a slot; before that 1.5 -> 2.3), though a 3-D p2g of random particles on a 16^3 grid gained (1.7-2.5 -> 1.3);
#: mpm99's P2G (13.8) went 0.78 -> 0.24 ms, diffmpm3d's g2p.grad (31) 6.0 -> 2.9-3.8
MIN_FLOAT_OPS_PER_SCATTER = 10
#: bytes of lane slots per group: they stay in L1 while part 1 reads them back
SLOT_BYTES = 16384


def fission(kernel: Kernel, width: int, vector_bits: int = 0) -> bool:
    """Split every top-level parallel loop that matches (see the module's doc) into groups of `width` iterations;
    width -1: two vector registers of `vector_bits` of f32 lanes, halved while the slots exceed SLOT_BYTES."""
    if width == 0 or width == 1 or (width < 0 and vector_bits <= 0):
        return False

    def rewrite(loop: Stmt) -> list[Stmt] | None:
        parts = _match(loop)
        return None if parts is None else _Split(loop, parts, width, vector_bits, kernel.body).run()

    return rewrite_loops(kernel, rewrite)


def place(target) -> tuple:
    """The memory an access target may share bytes with: ("place", tree, byte offset) for a plain dense field's
    place, ("place", tree, None) for a sparse or quant field (its whole tree), ("arrays",) for any ndarray."""
    if isinstance(target, FieldRef):
        if target.levels or target.quant is not None:
            return ("place", target.layout[0], None)
        return ("place", target.layout[0], target.layout[1])
    return ("arrays",)


def overlap(a: tuple, b: tuple) -> bool:
    if a[0] != b[0]:
        return False
    if a[0] == "arrays":
        return True
    return a[1] == b[1] and (a[2] is None or b[2] is None or a[2] == b[2])


def _match(loop: Stmt) -> list[list[Stmt]] | None:
    """[part 0, part 1] (each in program order), or None when the loop does not qualify."""
    plan = loop.attrs.get("strategy")
    if not isinstance(plan, LoopStrategy):
        return None
    if any(a.vtype.is_float for _place, adds in plan.reductions.values() for a in adds):
        return None  # a float sum per thread is added once per chunk: moved boundaries change its rounding
    body = loop.blocks[0].stmts
    every = list(walk(loop.blocks[0]))
    if any(x.op in _REFUSED for x in every) or _jumps_out(body):
        return None
    used: dict[int, list[Stmt]] = {}
    for x in every:
        for o in x.operands:
            used.setdefault(id(o), []).append(x)
    scatters = [s for s in body if s.op is Op.ATOMIC and s.operands[0].op is Op.GLOBAL_PTR
                and s.attrs.get("strategy") not in (PLAIN, REDUCE, None) and not used.get(id(s))]
    if not scatters:
        return None
    late = {id(s) for s in scatters}
    top = {id(s) for s in body}
    for s in reversed(body):  # pointers and integer index arithmetic only the scatters use
        if id(s) in late or not used.get(id(s)) or not all(id(u) in late for u in used[id(s)]):
            continue
        if s.op is Op.GLOBAL_PTR or (s.op in PURE and s.op is not Op.TREE_ROOT and not s.vtype.is_float
                                     and all(not o.vtype.is_float for o in s.operands)):
            late.add(id(s))
    part0 = [s for s in body if id(s) not in late]
    part1 = [s for s in body if id(s) in late]
    assert all(id(s) in top for s in part1)
    written = {place(s.operands[0].attrs["target"]) for s in scatters}
    for x in _walk_list(part0):
        if x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC) and x.operands[0].op is Op.GLOBAL_PTR:
            mine = place(x.operands[0].attrs["target"])
            if any(overlap(mine, w) for w in written):
                return None  # part 0 reads or writes what another iteration's part 1 updates
    work = sum(1 for x in _walk_list(part0) if x.op in PURE and x.vtype.is_float)
    if work < MIN_FLOAT_OPS or work < MIN_FLOAT_OPS_PER_SCATTER * len(scatters):
        return None
    part0 = _local_stores(part0)
    # part 0's iterations share no element one of them stores to: its lane loop's accesses may be told parallel
    loop.attrs["fission_independent"] = _independent(loop, {id(x) for x in every}, _walk_list(part0))
    return [part0, part1]


def _key(ptr: Stmt) -> tuple:
    return (id(ptr.attrs["target"]), tuple(id(o) for o in ptr.operands))


def _local_stores(stmts: list[Stmt]) -> list[Stmt]:
    """Part 0 with its conditional stores made unconditional where that is exact: in an IF, the stores to (and loads
    of) an element that an earlier top-level statement of the part stored (so it is in bounds and the iteration
    writes it anyway) go to a local holding the element, loaded before the IF and stored back after it. mpm99's
    `if material[p] == 0: F[p] = ... elif material[p] == 2: F[p] = ...` then is pure code LLVM if-converts: masked
    stores of the 4 interleaved components kept part 0 scalar (P2G 0.67 -> 0.12 ms with F stored as a select)."""
    out: list[Stmt] = []
    stored: dict[tuple, Stmt] = {}
    for s in stmts:
        if s.op is Op.GLOBAL_STORE and s.operands[0].op is Op.GLOBAL_PTR:
            stored.setdefault(_key(s.operands[0]), s.operands[0])
        if s.op is Op.IF:
            keys = {_key(x.operands[0]) for x in walk_blocks(s) if x.op is Op.GLOBAL_STORE
                    and x.operands[0].op is Op.GLOBAL_PTR}
            if keys and keys <= stored.keys() and _apart(s, keys):
                out += _through_locals(s, {k: stored[k] for k in keys})
                continue
        out.append(s)
    return out


def walk_blocks(s: Stmt):
    for b in s.blocks:
        yield from walk(b)


def _apart(s: Stmt, keys: set) -> bool:
    """Whether the IF touches the memory of those elements only through them, and never updates them."""
    places = [place(p.attrs["target"]) for p in _pointers(s, keys)]
    for x in walk_blocks(s):
        if x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC) and x.operands[0].op is Op.GLOBAL_PTR:
            ptr = x.operands[0]
            if _key(ptr) in keys:
                if x.op is Op.ATOMIC:
                    return False
            elif any(overlap(place(ptr.attrs["target"]), q) for q in places):
                return False
        elif x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC):
            return False  # an absolute address: it could be anything
    return True


def _pointers(s: Stmt, keys: set) -> list[Stmt]:
    return [x.operands[0] for x in walk_blocks(s) if x.op is Op.GLOBAL_STORE and _key(x.operands[0]) in keys]


def _through_locals(s: Stmt, ptrs: dict[tuple, Stmt]) -> list[Stmt]:
    """[load each element into a new local, the IF accessing the locals instead, store each local back]."""
    block = s.block
    before: list[Stmt] = []
    after: list[Stmt] = []
    local: dict[tuple, Stmt] = {}
    for k, ptr in ptrs.items():
        t = ptr.vtype
        a = Builder.detached(Op.ALLOCA, t, (), None, s.loc, block)
        old = Builder.detached(Op.GLOBAL_LOAD, t, (ptr,), {"own_store": True}, s.loc, block)
        before += [a, old, Builder.detached(Op.LOCAL_STORE, None, (a, old), None, s.loc, block)]
        new = Builder.detached(Op.LOCAL_LOAD, t, (a,), None, s.loc, block)
        after += [new, Builder.detached(Op.GLOBAL_STORE, None, (ptr, new), None, s.loc, block)]
        local[k] = a
    for x in walk_blocks(s):
        if x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE) and x.operands[0].op is Op.GLOBAL_PTR \
                and _key(x.operands[0]) in local:
            a = local[_key(x.operands[0])]
            if x.op is Op.GLOBAL_LOAD:
                x.op, x.operands = Op.LOCAL_LOAD, (a,)
            else:
                x.op, x.operands = Op.LOCAL_STORE, (a, x.operands[1])
    return [*before, s, *after]


class _Split(_Rewrite):
    """lanes.py's rewrite of two lane-loop parts, the loop marked `fission` (its width)."""

    mark = "fission"

    def _enter(self, k: int, lane: Stmt, lb: Builder) -> None:
        super()._enter(k, lane, lb)
        if k == 0 and self.loop.attrs.pop("fission_independent", False):
            # codegen/llvm.py: its loads and stores (lane slots included) in an access group of the lane loop's
            # `llvm.loop.parallel_accesses`; without it diffmpm3d's p2g (F[f + 1, p] stored, x, v, C, F of step f
            # read, one tree) stayed scalar: "too many memory checks needed"
            lane.attrs["parallel_lanes"] = True

    def _make_slots(self, b: Builder) -> None:
        """The values one cell's scatters add (grid_v[I][0..2], grid_m[I]: consecutive updates at the same indices)
        share a slot, a cell's values side by side per lane: part 1 reads them as one vector where its updates
        are one (a <4 x float> read-modify-write), not 4 loads and inserts."""
        self.spread = {}
        groups: list[list[Stmt]] = []
        last: tuple | None = None
        for s in self.parts[1]:
            if s.op is not Op.ATOMIC or id(s.operands[1]) not in self.crossing:
                continue
            cell = tuple(id(i) for i in s.operands[0].operands)
            v = s.operands[1]
            if groups and cell == last and v.vtype is groups[-1][0].vtype and v not in groups[-1]:
                groups[-1].append(v)
            else:
                groups.append([v])
            last = cell
        for g in groups:
            if len(g) < 2 or any(id(v) in self.spread for v in g):
                continue
            shared = b.emit(Op.ALLOCA, g[0].vtype, (), {"lanes": self.width * len(g)})
            for c, v in enumerate(g):
                self.slot[id(v)] = shared
                self.spread[id(v)] = (len(g), c)
        for key, o in self.crossing.items():
            if key not in self.slot:
                self.slot[key] = b.emit(Op.ALLOCA, o.vtype, (), {"lanes": self.width})

    def _auto_width(self, vector_bits: int) -> int:
        slot_bytes = sum(max(o.vtype.bits, 8) // 8 for o in self.crossing.values())
        width = max(8, min(64, 2 * vector_bits // 32))
        while width > 8 and width * slot_bytes > SLOT_BYTES:
            width //= 2
        return width
