"""SIMT lanes: a parallel loop whose iterations each run a data-dependent while loop of pure local arithmetic
(escape-time fractals: Mandelbrot, Julia) runs its iterations W at a time, the while loops in lock step.

LLVM's loop vectoriser cannot vectorise the iterations of such a loop, as each one's while runs a different
number of times (Taichi cannot either). This pass makes the parallel loop run over groups of W iterations
(its index becomes the group's), whose body is, for a loop body `prefix; while; suffix`:

    for l < n: i = base + l; act[l] = 1; prefix(i)             base = begin + g * W, n = min(W, end - base)
    while True:                                                one step of every lane
        any = 0
        for l < W: p = act[l]; the while's body, its branches flattened into predicates (an IF's blocks both
                   run, each under p & its condition), every store to a local masked (select(p, new, old)),
                   a break taking its lanes out of p; act[l] = p & !broke; any |= act[l]
        if any == 0: break
    for l < n: i = base + l; suffix(i)

(several such whiles at the top of the body: one step loop each, the code between them a lane loop). Every
local and value that lives from one of these parts into a later one has a slot per lane: an ALLOCA with
attrs `lanes` = W, read and written by LOCAL_LOAD / LOCAL_STORE with the lane index as their last operand
(codegen/llvm.py: an `alloca [W x T]`). The step's lane loop is straight-line code over consecutive lane
slots, which LLVM vectorises into <W x T> operations.

Results keep every bit: each lane executes exactly the scalar operations in the scalar order; a lane whose
while has ended computes on values nothing keeps. Hence the while's body may hold only operations that can
neither trap nor give LLVM poison (elementwise arithmetic, which codegen keeps from trapping, selects, casts
other than float -> int), locals and branches: no memory, atomics, prints, random numbers, nested loops; and
at most one float sum that fast_math lets LLVM reassociate (passes/accumulate.py), which could pair two of them
in one version and not the other (fast_math's reassociation is LLVM's to use: see _pure_while for what random
programs showed).
The parts of the body around the whiles run lane by lane, in iteration order within each part; so that
no other order can be observed, at most one part may have effects (stores, atomics, prints, asserts, random
numbers), the others may not read what the loop writes, and the loop's per-thread float sums and private
copies (whose rounding depends on the pool's chunks, counted in groups now) rule the rewrite out.

Run on the CPU only (a GPU is SIMT already), on forward kernels after parallel_strategy, not in debug mode.
"""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, walk
from simgrad.ir.ops import COMPARE, PURE, Op
from simgrad.passes.parallel_strategy import LoopStrategy

# an update of a local inside a rewritten part becomes load, this op, store (float min/max excepted: their
# atomic lowering is not the registry's)
_UPDATE_OPS = {"add": Op.ADD, "mul": Op.MUL, "and": Op.BIT_AND, "or": Op.BIT_OR, "xor": Op.BIT_XOR,
               "min": Op.MIN, "max": Op.MAX}
# never in a rewritten loop: real functions and sparse structure ops may do anything
_REFUSED = {Op.CALL, Op.SNODE_OP, Op.SPARSE_CELL, Op.SPARSE_ACTION, Op.TAPE_RESET, Op.TAPE_PUSH, Op.TAPE_POP,
            Op.CHECK_INDEX, Op.RET_STORE, Op.FUNC_RETURN}
# effects whose order across iterations can be observed
_EFFECTS = {Op.GLOBAL_STORE, Op.ATOMIC, Op.LOCAL_STORE, Op.PRINT, Op.ASSERT, Op.RANDOM}


#: vector registers' worth of lanes when the width is the host's: 4 independent vector chains per step hide the
#: latency of the step's arithmetic (Julia set at one thread with AVX-512: 8 lanes 3.5 ms, 16 2.0, 32 1.3, 64 0.84)
REGISTERS = 4


def lanes(kernel: Kernel, width: int, vector_bits: int = 0) -> bool:
    """Rewrite every top-level parallel loop that matches (see the module's doc) to run `width` lanes at a time;
    width -1: REGISTERS vector registers of `vector_bits` of the loop's widest lane values (8 to 64 lanes)."""
    if width == 0 or width == 1 or (width < 0 and vector_bits <= 0):
        return False

    def rewrite(loop: Stmt) -> list[Stmt] | None:
        parts = _match(loop)
        return None if parts is None else _Rewrite(loop, parts, width, vector_bits, kernel.body).run()

    return rewrite_loops(kernel, rewrite)


def rewrite_loops(kernel: Kernel, rewrite) -> bool:
    """`rewrite(loop)` on every top-level parallel loop over indices (not cells, no list generation) that no lane
    rewrite has taken yet: the statements that go before the loop, or None (the loop does not match, unchanged).
    The driver of passes/lanes.py, lanes_memory.py and fission.py."""
    changed = False
    out: list[Stmt] = []
    for s in kernel.body.stmts:
        if s.op is Op.RANGE_FOR and s.attrs.get("parallel") and not s.attrs.get("cells") \
                and not s.attrs.get("listgen") and not s.attrs.get("simt"):
            before = rewrite(s)
            if before is not None:
                out += before
                changed = True
        out.append(s)
    kernel.body.stmts = out
    return changed


# -- matching ------------------------------------------------------------------------------------------------
def _match(loop: Stmt) -> list[list[Stmt] | Stmt] | None:
    """The loop body cut into parts: lists of statements (run lane by lane) alternating with the whiles that
    qualify (run in lock step); None when the loop does not qualify."""
    plan = loop.attrs.get("strategy")
    if not isinstance(plan, LoopStrategy) or plan.regions:
        return None
    if any(a.vtype.is_float for _place, adds in plan.reductions.values() for a in adds):
        return None  # a float sum's rounding depends on the pool's chunks
    inside = {id(x) for x in walk(loop.blocks[0])}
    if any(x.op in _REFUSED for x in walk(loop.blocks[0])):
        return None
    written = _written(loop, inside)
    parts: list[list[Stmt] | Stmt] = [[]]
    for s in loop.blocks[0].stmts:
        if s.op is Op.WHILE and _pure_while(s, inside, written):
            parts += [s, []]
        else:
            seg = parts[-1]
            assert isinstance(seg, list)
            seg.append(s)
    if len(parts) == 1:
        return None
    segments = [p for p in parts if isinstance(p, list)]
    if any(_jumps_out(seg) for seg in segments):
        return None  # a continue of the parallel loop would only end the lane's part
    effects = [k for k, seg in enumerate(segments) if any(_has_effect(x, inside) for x in _walk_list(seg))]
    if len(effects) > 1:
        return None
    for k, seg in enumerate(segments):
        if effects and k == effects[0]:
            continue
        if any(_reads(x, written) for x in _walk_list(seg)):
            return None  # it would read before the other iterations' part with effects wrote
    return parts


def _walk_list(stmts: list[Stmt]):
    for s in stmts:
        yield s
        for b in s.blocks:
            yield from walk(b)


def _memory(ref) -> tuple:
    """What a GLOBAL_PTR's target may share memory with: its SNode tree, or any ndarray argument (two
    arguments may be one array)."""
    if isinstance(ref, FieldRef):
        return ("tree", ref.layout[0])
    return ("arrays",)


def _written(loop: Stmt, inside: set) -> set:
    """Memory the loop writes: trees / ndarrays, and locals declared outside it."""
    out: set = set()
    for x in walk(loop.blocks[0]):
        if x.op in (Op.GLOBAL_STORE, Op.ATOMIC, Op.LOCAL_STORE):
            p = x.operands[0]
            if p.op is Op.GLOBAL_PTR:
                out.add(_memory(p.attrs["target"]))
            elif p.op is Op.ALLOCA and id(p) not in inside:
                out.add(("local", id(p)))
    return out


def _reads(x: Stmt, written: set) -> bool:
    if x.op is Op.GLOBAL_LOAD:
        return _memory(x.operands[0].attrs["target"]) in written
    if x.op is Op.LOCAL_LOAD:
        return ("local", id(x.operands[0])) in written
    return False


def _has_effect(x: Stmt, inside: set) -> bool:
    if x.op not in _EFFECTS:
        return False
    if x.op in (Op.LOCAL_STORE, Op.ATOMIC):  # a local of the iteration is no effect
        p = x.operands[0]
        return not (p.op is Op.ALLOCA and id(p) in inside)
    return True


def _jumps_out(stmts: list[Stmt]) -> bool:
    """A break or continue of the parallel loop itself (not of a loop nested in these statements)."""
    for s in stmts:
        if s.op in (Op.BREAK, Op.CONTINUE):
            return True
        if s.op is Op.IF and any(_jumps_out(b.stmts) for b in s.blocks):
            return True
    return False


def _pure_while(w: Stmt, inside: set, written: set) -> bool:
    """A while whose body is local arithmetic, branches, breaks and continues only, with at most one float sum that
    passes/accumulate.py let LLVM reassociate (fast_math). The lanes keep the flag, so LLVM folds such a sum within
    a step as in the scalar loop (`x += 0.261 * x` into `x * 1.261`: dropping the flag made 2 of 300 random programs
    of tests/passes/test_lanes_fuzz.py differ); but two of them, `x += a; x += b`, LLVM paired in the scalar loop
    and not between the lanes' masked stores (4 of 300 differed in an f32's last bit), so such whiles are left as
    they are. (With one, LLVM still folded `x0 + 2 * x0` into `x0 * 3` in a scalar loop's peeled first step, which
    the lanes have not: 1 of 1100 random programs with fast_math, none of 600 without.)"""
    if sum(1 for x in walk(w.blocks[0]) if x.attrs.get("reassoc")) > 1:
        return False
    for x in walk(w.blocks[0]):
        op = x.op
        if op in (Op.IF, Op.BREAK, Op.CONTINUE, Op.ALLOCA):
            continue
        if op in (Op.LOCAL_LOAD, Op.LOCAL_STORE, Op.ATOMIC):
            p = x.operands[0]
            if p.op is not Op.ALLOCA:
                return False
            if id(p) not in inside:  # a kernel-scope local: read only, and nobody in the loop writes it
                if op is not Op.LOCAL_LOAD or ("local", id(p)) in written:
                    return False
            if op is Op.ATOMIC and not _updatable(x):
                return False
            continue
        if op is Op.CAST and x.operands[0].vtype.is_float and not x.vtype.is_float and x.vtype is not dt.u1:
            return False  # fptosi of an out-of-range value (a finished lane's) is poison
        if op not in PURE or op in (Op.GLOBAL_PTR, Op.TREE_ROOT):
            return False
    return True


def _updatable(x: Stmt) -> bool:
    kind = x.attrs.get("kind")
    if x.vtype is dt.u1:
        return False
    if kind == "xchg":
        return True
    if kind in ("min", "max") and x.vtype.is_float:
        return False
    return kind in _UPDATE_OPS


# -- the rewrite ---------------------------------------------------------------------------------------------
class _Rewrite:
    """Builds the group loop's body from the parts (see the module's doc); the loop is marked with attrs[mark] = W
    (passes/fission.py's two lane-loop parts: `fission`)."""

    mark = "simt"

    def __init__(self, loop: Stmt, parts: list, width: int, vector_bits: int, outer: Block):
        self.loop = loop
        self.parts = parts
        self.outer = outer
        self.ity = loop.vtype  # the loop index's type
        self.part_of: dict[int, int] = {}
        for k, p in enumerate(parts):
            for x in (_walk_list(p) if isinstance(p, list) else walk(p.blocks[0])):
                self.part_of[id(x)] = k
        # values used in a later part than their own: locals get lane slots (so do the while's own locals), other
        # values a lane slot each, written at the end of their part; pointers are recomputed where used instead
        self.lane_local: set[int] = set()
        self.crossing: dict[int, Stmt] = {}
        for k, p in enumerate(parts):
            for x in (_walk_list(p) if isinstance(p, list) else walk(p.blocks[0])):
                if x.op is Op.ALLOCA and not isinstance(p, list):
                    self.lane_local.add(id(x))
                for o in x.operands:
                    self._need(o, k)
        self.slot: dict[int, Stmt] = {}
        self.width = width if width > 0 else self._auto_width(vector_bits)

    def _auto_width(self, vector_bits: int) -> int:
        """The host's width: vector registers' worth of the widest value that has lane slots."""
        slots = [o.vtype for o in self.crossing.values()] + [
            x.vtype for x in walk(self.loop.blocks[0]) if x.op is Op.ALLOCA and id(x) in self.lane_local]
        widest = max([32] + [max(t.bits, 8) for t in slots])
        return min(64, max(8, REGISTERS * vector_bits // widest))

    def _need(self, o: Stmt, k: int) -> None:
        """Part k uses o: give o a lane slot if it comes from another part."""
        home = self.part_of.get(id(o))
        if home is None or home == k:
            return
        if o.op is Op.ALLOCA:
            self.lane_local.add(id(o))
        elif o.op is Op.GLOBAL_PTR:
            for i in o.operands:
                self._need(i, k)
        else:
            self.crossing.setdefault(id(o), o)

    def run(self) -> list[Stmt]:
        """Rewrite the loop in place; returns the statements that go before it (the group count)."""
        loop, w = self.loop, self.width
        before = Block()
        b = Builder(before)
        b.loc = loop.loc
        begin, end = loop.operands
        ngroups = self._group_count(b, begin, end)
        loop.operands = (b.const(0, self.ity), ngroups)
        plan = loop.attrs["strategy"]
        plan.grain = max(1, -(-plan.grain // w))  # the same work per chunk, counted in groups
        plan.weight *= w  # updates per group (the private copies' pay-off, codegen/privatize.py)
        loop.attrs[self.mark] = w
        body = Block(loop)
        b = Builder(body)
        b.loc = loop.loc
        self.b = b
        self.base, self.n = self._group_start(b, begin, end)
        allocas = {id(x): x for x in walk(loop.blocks[0]) if x.op is Op.ALLOCA}
        for a in allocas.values():
            if id(a) in self.lane_local:
                a.attrs["lanes"] = w
                a.block = body
                body.stmts.append(a)
        self._make_slots(b)
        if any(not isinstance(p, list) for p in self.parts):  # lock-step whiles: which lanes still run
            self.act = b.emit(Op.ALLOCA, dt.i32, (), {"lanes": w})
            self.any = b.emit(Op.ALLOCA, dt.i32)
        for k, p in enumerate(self.parts):
            if isinstance(p, list):
                self._segment(k, p, followed=k + 1 < len(self.parts) and not isinstance(self.parts[k + 1], list))
            else:
                self._step(k, p)
        loop.blocks = (body,)
        for x in before.stmts:
            x.block = self.outer
        return before.stmts

    def _group_start(self, b: Builder, begin: Stmt, end: Stmt) -> tuple[Stmt, Stmt]:
        """The group's first iteration (its lane 0's index) and its count of iterations (i32, at most W)."""
        w = self.width
        base = b.add(begin, b.mul(self.loop, b.const(w, self.ity)))
        left = b.sub(end, base)
        wide = b.const(w, self.ity)
        return base, b.cast(b.select(b.lt(left, wide), left, wide), dt.i32)

    def _make_slots(self, b: Builder) -> None:
        """A lane slot (ALLOCA of W values) per value crossing parts; `self.spread[key]` = (k, c) places a value at
        index lane * k + c of a shared slot instead (passes/fission.py)."""
        self.spread: dict[int, tuple[int, int]] = {}
        for key, o in self.crossing.items():
            self.slot[key] = b.emit(Op.ALLOCA, o.vtype, (), {"lanes": self.width})

    def _slot_index(self, key: int, lane: Stmt, into: Block | None) -> Stmt:
        """The index of `lane`'s place in key's slot, computed in `into` (None: the lane loop's builder)."""
        if key not in self.spread:
            return lane
        k, c = self.spread[key]
        i32 = lane.vtype
        if into is None:
            return self.lb.add(self.lb.mul(lane, self.lb.const(k, i32)), self.lb.const(c, i32))
        m = Builder.detached(Op.MUL, i32, (lane, Builder.constant(k, i32)), None, self.loop.loc, into)
        a = Builder.detached(Op.ADD, i32, (m, Builder.constant(c, i32)), None, self.loop.loc, into)
        into.stmts += [m, a]
        return a

    def _group_count(self, b: Builder, begin: Stmt, end: Stmt) -> Stmt:
        """ceil(max(end - begin, 0) / W), without overflow near the index type's maximum."""
        w = self.width
        if begin.op is Op.CONST and end.op is Op.CONST:
            known = max(int(end.attrs["value"]) - int(begin.attrs["value"]), 0)
            return b.const(-(-known // w), self.ity)
        zero = b.const(0, self.ity)
        count = b.select(b.gt(end, begin), b.sub(end, begin), zero)
        whole = b.shr(count, b.const(w.bit_length() - 1, self.ity))
        rest = b.cast(b.ne(b.bit_and(count, b.const(w - 1, self.ity)), zero), self.ity)
        return b.add(whole, rest)

    # -- lane loops --------------------------------------------------------------------------------------------
    def _lane_loop(self, count: Stmt) -> tuple[Stmt, Builder]:
        loop = self.b.emit(Op.RANGE_FOR, dt.i32, (self.b.const(0, dt.i32), count),
                           {"parallel": False, "top": False, "lanes": True}, nblocks=1)
        lb = Builder(loop.blocks[0])
        lb.loc = self.loop.loc
        return loop, lb

    def _enter(self, k: int, lane: Stmt, lb: Builder) -> None:
        """Start part k's lane loop (index `lane`, body builder `lb`): `self.local` maps what the part sees in
        place of a statement (values of other parts, the loop index, updates rewritten to loads)."""
        self.lane, self.lb, self.k = lane, lb, k
        self.local: dict[int, Stmt] = {}

    def _operand(self, o: Stmt) -> Stmt:
        """o as part k sees it: the loop index is base + lane; a value of an earlier part is its lane slot's,
        loaded at the top of the lane loop's body when first needed; a pointer is recomputed there."""
        got = self.local.get(id(o))
        if got is not None:
            return got
        home = self.part_of.get(id(o))
        if o is not self.loop and (home is None or home == self.k or o.op is Op.ALLOCA):
            return o
        lb = self.lb
        if o is self.loop:
            v = lb.add(self.base, lb.cast(self.lane, self.ity))
        elif o.op is Op.GLOBAL_PTR:
            v = lb.emit(Op.GLOBAL_PTR, o.type, tuple(self._operand(i) for i in o.operands), dict(o.attrs))
        else:
            v = lb.emit(Op.LOCAL_LOAD, o.vtype, (self.slot[id(o)], self._slot_index(id(o), self.lane, None)))
        self.local[id(o)] = v
        return v

    def _segment(self, k: int, stmts: list[Stmt], followed: bool) -> None:
        """Statements between whiles, lane by lane over the group's n iterations."""
        if not stmts and not followed:
            return
        loop, lb = self._lane_loop(self.n)
        self._enter(k, loop, lb)
        if followed:
            lb.emit(Op.LOCAL_STORE, None, (self.act, lb.const(1, dt.i32), loop))
        rest = Block(loop)
        self._plain(stmts, rest)
        for s in stmts:
            if id(s) in self.slot:
                value = self.local.get(id(s), s)
                at = self._slot_index(id(s), loop, rest)
                rest.stmts.append(Builder.detached(Op.LOCAL_STORE, None, (self.slot[id(s)], value, at), None,
                                                   s.loc, rest))
        for x in rest.stmts:
            x.block = loop.blocks[0]
        loop.blocks[0].stmts += rest.stmts

    def _plain(self, stmts: list[Stmt], into: Block) -> None:
        """Move `stmts` into `into`: operands as this part sees them, lane locals accessed at the lane."""
        for s in stmts:
            if id(s) in self.lane_local:  # declared in the group's body
                continue
            s.operands = tuple(self._operand(o) for o in s.operands)
            lane_op = s.op in (Op.LOCAL_LOAD, Op.LOCAL_STORE, Op.ATOMIC) and id(s.operands[0]) in self.lane_local
            if lane_op and s.op is Op.ATOMIC:
                old, new = self._update(s, into)
                into.stmts.append(Builder.detached(Op.LOCAL_STORE, None, (s.operands[0], new, self.lane), None,
                                                   s.loc, into))
                self.local[id(s)] = old
                continue
            if lane_op:
                s.operands = (*s.operands, self.lane)
            s.block = into
            into.stmts.append(s)
            for blk in s.blocks:
                moved = blk.stmts
                blk.stmts = []
                self._plain(moved, blk)

    def _update(self, s: Stmt, into: Block) -> tuple[Stmt, Stmt]:
        """`x op= v` on a lane local, as (the old value, the new value) loaded and computed in `into` (a sum keeps
        the reassoc passes/accumulate.py gave it: LLVM then folds it in a step as in the scalar loop)."""
        var, v = s.operands[0], s.operands[1]
        old = Builder.detached(Op.LOCAL_LOAD, s.vtype, (var, self.lane), None, s.loc, into)
        into.stmts.append(old)
        kind = s.attrs["kind"]
        if kind == "xchg":
            return old, v
        attrs = {"reassoc": True} if s.attrs.get("reassoc") else None
        new = Builder.detached(_UPDATE_OPS[kind], s.vtype, (old, v), attrs, s.loc, into)
        into.stmts.append(new)
        return old, new

    # -- step loops --------------------------------------------------------------------------------------------
    def _step(self, k: int, w: Stmt) -> None:
        """One while, all lanes in lock step: the step loop, around a lane loop over all W lanes."""
        b = self.b
        step = b.emit(Op.WHILE, None, (), {"simt": self.width}, nblocks=1)
        sb = Builder(step.blocks[0])
        sb.loc = w.loc
        sb.emit(Op.LOCAL_STORE, None, (self.any, sb.const(0, dt.i32)))
        outer_b, self.b = self.b, sb
        loop, lb = self._lane_loop(sb.const(self.width, dt.i32))
        self.b = outer_b
        self._enter(k, loop, lb)
        lb.loc = w.loc
        p = lb.emit(Op.LOCAL_LOAD, dt.i32, (self.act, loop))
        self.broke: Stmt | None = None
        body = Block(loop)
        self._predicated(w.blocks[0].stmts, p, body)
        for x in body.stmts:
            x.block = loop.blocks[0]
        loop.blocks[0].stmts += body.stmts
        live = p if self.broke is None else lb.bit_and(p, lb.eq(self.broke, lb.const(0, dt.i32)))
        lb.emit(Op.LOCAL_STORE, None, (self.act, live, loop))
        lb.emit(Op.LOCAL_STORE, None, (self.any, lb.bit_or(lb.emit(Op.LOCAL_LOAD, dt.i32, (self.any,)), live)))
        done = sb.emit(Op.IF, None, (sb.eq(sb.emit(Op.LOCAL_LOAD, dt.i32, (self.any,)), sb.const(0, dt.i32)),),
                       nblocks=2)
        with sb.inside(done.blocks[0]):
            sb.emit(Op.BREAK, None)

    def _predicated(self, stmts: list[Stmt], p: Stmt, into: Block) -> Stmt | None:
        """Flatten `stmts` into `into` under predicate p (an i32 0/1): pure statements run for every lane, stores
        keep the old value where p is 0, an IF runs both blocks under p and its condition or its negation, a
        break adds p to the broken lanes. Returns the predicate after the statements (None: no lane gets there)."""
        for s in stmts:
            if s.op is Op.BREAK:
                self.broke = p if self.broke is None else self._emit(Op.BIT_OR, dt.i32, (self.broke, p), into)
                return None
            if s.op is Op.CONTINUE:
                return None
            if id(s) in self.lane_local:
                continue
            s.operands = tuple(self._operand(o) for o in s.operands)
            if s.op is Op.IF:
                c = s.operands[0]
                if c.op not in COMPARE:  # any nonzero value takes the branch: a 0/1 predicate of it
                    c = self._emit(Op.NE, dt.i32, (c, Builder.constant(0, c.vtype)), into)
                pt = self._emit(Op.BIT_AND, dt.i32, (p, c), into)
                pe = self._emit(Op.BIT_AND, dt.i32,
                                (p, self._emit(Op.EQ, dt.i32, (c, Builder.constant(0, dt.i32)), into)), into)
                then = self._predicated(s.blocks[0].stmts, pt, into)
                else_ = self._predicated(s.blocks[1].stmts, pe, into)
                if then is pt and else_ is pe:
                    continue  # neither block jumps: p holds as it was
                if then is None:
                    if else_ is None:
                        return None
                    p = else_
                elif else_ is None:
                    p = then
                else:
                    p = self._emit(Op.BIT_OR, dt.i32, (then, else_), into)
                continue
            if s.op is Op.LOCAL_LOAD:
                if id(s.operands[0]) in self.lane_local:
                    s.operands = (*s.operands, self.lane)
            elif s.op in (Op.LOCAL_STORE, Op.ATOMIC):
                var = s.operands[0]
                if s.op is Op.ATOMIC:
                    old, new = self._update(s, into)
                    self.local[id(s)] = old
                else:
                    new = s.operands[1]
                    old = self._emit(Op.LOCAL_LOAD, var.vtype, (var, self.lane), into)
                    s.block = None
                kept = self._emit(Op.SELECT, var.vtype, (p, new, old), into)
                into.stmts.append(Builder.detached(Op.LOCAL_STORE, None, (var, kept, self.lane), None, s.loc, into))
                continue
            s.block = into
            into.stmts.append(s)
        return p

    def _emit(self, op: Op, t, operands: tuple, into: Block) -> Stmt:
        s = Builder.detached(op, t, operands, None, self.lb.loc, into)
        into.stmts.append(s)
        return s
