"""SIMT lanes with memory and counted loops (issue 25): passes/lanes.py's lock step for parallel loops whose
iterations each run a loop that reads fields, stores to the iteration's own elements, or counts to a bound of its
own (a rasterizer's `for k in range(count[tile])` over a tile's triangles, then 2x2 sub-samples per triangle).

passes/lanes.py runs W iterations of a parallel loop at a time, with a while of pure local arithmetic in lock step.
This pass takes the parallel loops it left and lets the lock-step parts (`_Rewrite`'s steps) be
- a serial range-for at the top of the body: `for k in range(b, e): body` becomes `c = b; while True: k = c;
  c = k + 1; if not k < e: break; body` (the counter is stored before the body, so a continue needs nothing of
  its own), each lane leaving when its own k reaches its own e;
- whiles and such loops whose bodies also
  - load fields the parallel loop never writes, at any index, and fields it writes only at the element the
    iteration owns (passes/parallel_strategy.py `_owned`). A lane that is off (its loop ended, its branch not taken,
    or past the range in the last group) computes on values nothing keeps, so every index of a load is
    select(p, index, the axis's first index) under the lane's predicate p (constants inside the shape excepted):
    an off lane reads the field's first element, never outside the field (`block_indicies[t, k]` one past a tile's
    count, `A[that garbage]`);
  - store to the iteration's own elements of fields, under `if p:` (the vectorised lane loop's masked scatter:
    an off lane, past the range too, touches nothing);
  - run serial loops of constant trip count (at most MAX_TRIPS, MAX_UNROLLED statements unrolled), flattened into
    the lane's predicates as the step's body is (no break of their own) and marked `unroll`: LLVM unrolls them
    whole, so the step's lane loop is straight-line code that it vectorises;
  still no atomics on memory, prints, asserts, random numbers or calls, nor float -> int casts; at most one sum
  passes/accumulate.py marked reassociable, and none in a nested loop (LLVM might vectorise that loop in the scalar
  code, with partial sums).
The lane loop of a step that touches memory is marked `parallel_lanes`: codegen puts its accesses in an access
group its loop ID names (no lane stores to an element another lane reads or stores), so LLVM vectorises it with
gathers and masked stores, needing no run-time overlap checks (which it cannot build for gathers).

Uniform counted loops (`_Uniformity`): when every lane of a group counts the same trips (the rasterizer's tile of
8 pixels in a row shares its triangle count and list), the loop stays a loop at the group's level, its statements
that are the same for every lane (the triangle's index and vertices: loads of fields the loop does not write, at
uniform indices, and pure arithmetic of those) run once per trip, and the rest in one lane loop under `lane < n`:
scalar loads broadcast, not gathers. Uniformity follows the index: a value is X + lane with X a multiple of W (the
innermost axis' index, groups cut per row when the row length is no multiple of W), and floor-dividing such a value
by a multiple of W gives one value for the group. At the host's width (-1) the pass runs only such loops, at the
widest power of two of f32 lanes down to 4 that makes some data-sized count uniform, and only where no uniform loop
gathers at lanes' own indices.

Every bit stays: each lane executes its iteration's scalar operations, loads and stores in the scalar order. The
iterations' parts interleave otherwise than in the scalar loop, so nothing they share may be seen: an element of a
field the loop stores to is the iteration's own (stored and read by it alone, `_owned` per field; every ndarray
counts as one array) or, as in passes/lanes.py, at most one part has effects other iterations can see (stores of
elements not owned, atomics on memory, kernel-scope locals, prints, asserts, random numbers) and the other parts do
not read what those write. No per-thread float sums or private copies (their rounding follows the pool's chunks).
"""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.bounds import value_range
from simgrad.ir.builder import Builder
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, offset_form, walk
from simgrad.ir.ops import PURE, Op
from simgrad.passes.digits import invariant_chain, invariant_digit
from simgrad.passes.lanes import _REFUSED, _UPDATE_OPS, _jumps_out, _Rewrite, _updatable, _walk_list, rewrite_loops
from simgrad.passes.parallel_strategy import LoopStrategy

#: a serial loop of constant trip count inside a lock-step part is unrolled whole: at most this many trips, and
#: trips times its statements at most MAX_UNROLLED
MAX_TRIPS = 64
MAX_UNROLLED = 2048


def lanes_memory(kernel: Kernel, width: int, vector_bits: int = 0) -> bool:
    """Rewrite every top-level parallel loop passes/lanes.py left that matches (see the module's doc) to run `width`
    lanes at a time: at a width the program asked for (ti.init(simt_lanes=W), W > 1), and at the host's (-1) where
    every lock-step loop is a uniform one, at a width `_group_uniformity` picks. (Lanes that gather at their own
    indices lost to the scalar loop on the machine measured, AMD Zen 5, whose gathers cost about a scalar load per
    element: docs/ARCHITECTURE.md, SIMT lanes.)"""
    if width == 0 or width == 1 or (width < 0 and vector_bits <= 0):
        return False

    def rewrite(loop: Stmt) -> list[Stmt] | None:
        if not _eligible(loop):
            return None
        inside = {id(x) for x in walk(loop.blocks[0])}
        uni = _group_uniformity(loop, width, vector_bits, _Memory(loop, inside), inside)
        if uni is None:
            return None
        matched = _match(loop, uni, all_uniform=width < 0)
        if matched is None:
            return None
        parts, counted = matched
        return _MemoryRewrite(loop, parts, uni.width, vector_bits, kernel.body, counted, uni).run()

    return rewrite_loops(kernel, rewrite)


def _group_uniformity(loop: Stmt, width: int, vector_bits: int, mem: _Memory, inside: set) -> _Uniformity | None:
    """The lanes' uniformity at the width the program asked for; at the host's (-1), at the widest of one f32
    vector register's lanes down to 4 where some counted loop's trip count is the same for all lanes of a group
    (None: none is, and the host's width leaves the loop alone)."""
    if width > 0:
        return _Uniformity(loop, width, mem, inside)
    w = max(8, vector_bits // 32)
    while w >= 4:
        uni = _Uniformity(loop, w, mem, inside)
        if uni.pays():
            return uni
        w //= 2
    return None


# -- what the loop does to memory ----------------------------------------------------------------------------
def _key(target) -> object:
    """A field by its record; every ndarray argument as one (two arguments may be one array)."""
    return id(target) if isinstance(target, FieldRef) else "arrays"


class _Memory:
    """The targets the parallel loop stores to, and those of them whose every element is one iteration's own."""

    def __init__(self, loop: Stmt, inside: set):
        stores: dict[object, list[Stmt]] = {}
        reads: dict[object, list[Stmt]] = {}
        self.outer_written: set[int] = set()  # kernel-scope locals the loop writes
        for x in walk(loop.blocks[0]):
            if x.op in (Op.GLOBAL_STORE, Op.ATOMIC, Op.GLOBAL_LOAD) and x.operands[0].op is Op.GLOBAL_PTR:
                key = _key(x.operands[0].attrs["target"])
                (reads if x.op is Op.GLOBAL_LOAD else stores).setdefault(key, []).append(x.operands[0])
            elif x.op in (Op.LOCAL_STORE, Op.ATOMIC) and x.operands[0].op is Op.ALLOCA \
                    and id(x.operands[0]) not in inside:
                self.outer_written.add(id(x.operands[0]))
        self.written = set(stores)
        self.owned = {k for k, ptrs in stores.items() if _owned(ptrs + reads.get(k, []), loop, inside)}

    def seen(self, x: Stmt, inside: set) -> bool:
        """An effect of x that other iterations could see, or whose order among them could be."""
        if x.op in (Op.PRINT, Op.ASSERT, Op.RANDOM):
            return True
        if x.op not in (Op.LOCAL_STORE, Op.ATOMIC, Op.GLOBAL_STORE):
            return False
        p = x.operands[0]
        if p.op is Op.ALLOCA:
            return id(p) not in inside
        return p.op is not Op.GLOBAL_PTR or _key(p.attrs["target"]) not in self.owned

    def shared_read(self, x: Stmt) -> bool:
        """A read of what some iteration writes, other than an element the iteration owns."""
        if x.op is Op.GLOBAL_LOAD:
            key = _key(x.operands[0].attrs["target"])
            return key in self.written and key not in self.owned
        return x.op is Op.LOCAL_LOAD and id(x.operands[0]) in self.outer_written


def _owned(ptrs: list[Stmt], loop: Stmt, inside: set) -> bool:
    """Whether every access (`ptrs`) of a target names an element of the iteration's own: each has, at the same
    axes, the same digits of the loop index (passes/digits.py, each plus the same constant) and those determine the
    index; its other indices may be anything (`samples[i, j, s // 2, s % 2]` in `for i, j in pixels`, with s a
    nested loop's index, is iteration (i, j)'s whatever s is). Then no two iterations touch one element. (Wider
    than passes/parallel_strategy.py `_owned`, whose elements are injective in the index, every index of them.)"""
    forms = set()
    for p in ptrs:
        form, bases = [], []
        for axis, o in enumerate(p.operands):
            base, c = offset_form(o)
            if base is not None and invariant_digit(base, loop, inside) is not None:
                form.append((axis, id(base), c))
                bases.append(base)
        if not invariant_chain(bases, loop, inside):
            return False
        forms.add(tuple(form))
    return len(forms) == 1


def _dense(ptr: Stmt) -> bool:
    """An element of a dense field that is no quant cell, of a shape with no empty axis: its first element is there
    for an off lane to read."""
    t = ptr.attrs["target"]
    return isinstance(t, FieldRef) and not t.levels and t.quant is None and len(ptr.operands) == len(t.shape) \
        and all(n > 0 for n in t.shape)


# -- matching ------------------------------------------------------------------------------------------------
def _eligible(loop: Stmt) -> bool:
    """Whether the loop's plan and statements allow lanes at all (before any analysis of its memory)."""
    plan = loop.attrs.get("strategy")
    if not isinstance(plan, LoopStrategy) or plan.regions:
        return False
    if any(a.vtype.is_float for _place, adds in plan.reductions.values() for a in adds):
        return False  # a float sum's rounding depends on the pool's chunks
    return not any(x.op in _REFUSED for x in walk(loop.blocks[0]))


def _match(loop: Stmt, uni: _Uniformity, all_uniform: bool) \
        -> tuple[list[list[Stmt] | Stmt], dict[int, tuple[Stmt, Stmt]]] | None:
    """The loop body cut into parts as passes/lanes.py `_match` does, its counted lock-step loops made whiles (the
    uniform ones, `uni.steps`, stay loops), and for those {id(while): (its counter, its end)}; None (and the loop
    untouched) when the loop does not qualify, or with `all_uniform` some lock-step loop is not uniform. The loop is
    `_eligible`; `uni` holds its memory facts."""
    body = loop.blocks[0]
    mem, inside = uni.mem, uni.inside
    steps = [s for s in body.stmts
             if (s.op is Op.WHILE or (s.op is Op.RANGE_FOR and not s.attrs.get("parallel")))
             and _lockstep(s, mem, inside)]
    if not steps or (all_uniform and any(id(s) not in uni.steps for s in steps)):
        return None
    step_ids = {id(s) for s in steps}
    segments: list[list[Stmt]] = [[]]
    for s in body.stmts:
        if id(s) in step_ids:
            segments.append([])
        else:
            segments[-1].append(s)
    if any(_jumps_out(seg) for seg in segments):
        return None  # a continue of the parallel loop would only end the lane's part
    seen = [k for k, seg in enumerate(segments) if any(mem.seen(x, inside) for x in _walk_list(seg))]
    if len(seen) > 1:
        return None
    if any(k not in seen and any(mem.shared_read(x) for x in _walk_list(seg)) for k, seg in enumerate(segments)):
        return None  # it would read before the other iterations' part with effects wrote
    parts: list[list[Stmt] | Stmt] = [[]]
    new_body: list[Stmt] = []
    counted: dict[int, tuple[Stmt, Stmt]] = {}
    for s in body.stmts:
        if id(s) in step_ids:
            seg = parts[-1]
            assert isinstance(seg, list)
            if s.op is Op.RANGE_FOR and id(s) not in uni.steps:
                end = s.operands[1]
                before, s = _as_while(s)
                counted[id(s)] = (before[0], end)
                seg += before
                new_body += before
            parts += [s, []]
        else:
            seg = parts[-1]
            assert isinstance(seg, list)
            seg.append(s)
        new_body.append(s)
    body.stmts = new_body
    return parts, counted


def _lockstep(loop: Stmt, mem: _Memory, inside: set) -> bool:
    """Whether a while or serial range-for at the top of the parallel body may run in lock step (module doc)."""
    if sum(1 for x in walk(loop.blocks[0]) if x.attrs.get("reassoc")) > 1:
        return False  # (passes/lanes.py `_pure_while` says why)
    return _lockstep_body(loop.blocks[0].stmts, mem, inside, nested=False)


def _lockstep_body(stmts: list[Stmt], mem: _Memory, inside: set, nested: bool) -> bool:
    for x in stmts:
        op = x.op
        if op is Op.BREAK and nested:
            return False  # of a nested loop: its lanes would need a flag of their own
        if op in (Op.BREAK, Op.CONTINUE, Op.ALLOCA):
            continue
        if op is Op.IF:
            if not all(_lockstep_body(b.stmts, mem, inside, nested) for b in x.blocks):
                return False
            continue
        if op is Op.RANGE_FOR:
            if not _unrollable(x) or not _lockstep_body(x.blocks[0].stmts, mem, inside, nested=True):
                return False
            continue
        if op in (Op.LOCAL_LOAD, Op.LOCAL_STORE, Op.ATOMIC) and x.operands[0].op is Op.ALLOCA:
            p = x.operands[0]
            if id(p) not in inside and (op is not Op.LOCAL_LOAD or id(p) in mem.outer_written):
                return False  # a kernel-scope local: read only, and nobody in the loop writes it
            if op is Op.ATOMIC and not _updatable(x):
                return False
            continue
        if op is Op.GLOBAL_PTR:
            if not _dense(x):
                return False
            continue
        if op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE):
            ptr = x.operands[0]
            if ptr.op is not Op.GLOBAL_PTR or not _dense(ptr):
                return False
            key = _key(ptr.attrs["target"])
            if key not in mem.owned and (op is Op.GLOBAL_STORE or key in mem.written):
                return False
            continue
        if op is Op.CAST and x.operands[0].vtype.is_float and not x.vtype.is_float and x.vtype is not dt.u1:
            return False  # fptosi of an out-of-range value (an off lane's) is poison
        if op not in PURE or op is Op.TREE_ROOT:
            return False
    return True


def _first_store(a: Stmt) -> Stmt | None:
    """The store that starts a local's life, when one does: the first statement after its declaration, in the
    declaring block, that stores it, with no access of it before."""
    home = a.block
    assert home is not None
    for s in home.stmts[home.stmts.index(a) + 1:]:
        if s.op is Op.LOCAL_STORE and s.operands[0] is a:
            return s
        if any(a in x.operands for x in (s, *(y for b in s.blocks for y in walk(b)))):
            return None
    return None


def _unrollable(loop: Stmt) -> bool:
    """A serial loop of constant trip count, small enough to unroll whole, with no reassociable sum (the scalar
    code's loop could be vectorised with partial sums)."""
    if loop.attrs.get("parallel"):
        return False
    b, e = loop.operands
    if b.op is not Op.CONST or e.op is not Op.CONST:
        return False
    trips = int(e.attrs["value"]) - int(b.attrs["value"])
    size = sum(1 for _ in walk(loop.blocks[0]))
    if any(x.attrs.get("reassoc") for x in walk(loop.blocks[0])):
        return False
    return trips <= MAX_TRIPS and max(trips, 0) * size <= MAX_UNROLLED


def _as_while(loop: Stmt) -> tuple[list[Stmt], Stmt]:
    """`for k in range(b, e): body` as `c = b` (returned first) and `while True: k = c; c = k + 1; if not k < e:
    break; body`."""
    begin, end = loop.operands
    t = loop.vtype
    home = loop.block
    counter = Builder.detached(Op.ALLOCA, t, (), None, loop.loc, home)
    init = Builder.detached(Op.LOCAL_STORE, None, (counter, begin), None, loop.loc, home)
    w = Builder.detached(Op.WHILE, None, (), None, loop.loc, home, nblocks=1)
    wb = Builder(w.blocks[0])
    wb.loc = loop.loc
    k = wb.emit(Op.LOCAL_LOAD, t, (counter,))
    wb.emit(Op.LOCAL_STORE, None, (counter, wb.add(k, wb.const(1, t))))
    stop = wb.emit(Op.IF, None, (wb.ge(k, end),), nblocks=2)
    with wb.inside(stop.blocks[0]):
        wb.emit(Op.BREAK, None)
    old = loop.blocks[0].stmts
    for x in old:
        x.block = w.blocks[0]
    w.blocks[0].stmts += old
    for x in walk(w.blocks[0]):
        if loop in x.operands:
            x.operands = tuple(k if o is loop else o for o in x.operands)
    return [counter, init], w


# -- what every lane of a group shares ------------------------------------------------------------------------
#: how a value varies over a group's lanes: the same for every lane, or X + lane with X a multiple of the width
#: (the lane's own index on the innermost axis: `j` of `for i, j in pixels`), X >= 0 or not
UNIFORM, ALIGNED, ALIGNED_NONNEG = "uniform", "aligned", "aligned>=0"
_ALIGNED_OPS = {Op.CAST, Op.ADD, Op.SUB, Op.FLOORDIV, Op.RAW_DIV, Op.MOD, Op.RAW_MOD, Op.SHR}


def _row_length(loop: Stmt, width: int) -> int | None:
    """M when the loop runs over rows of M iterations, M no multiple of the width (`raw_mod(i, M)` in the body of a
    loop over [0, rows * M)): its groups are then cut per row, so that a group's iterations share the row (a tile
    of 8 pixels shares its triangle list; 500-pixel rows in 8-lane groups would straddle rows)."""
    begin, end = loop.operands
    if begin.op is not Op.CONST or int(begin.attrs["value"]) != 0 or end.op is not Op.CONST:
        return None
    total = int(end.attrs["value"])
    for x in loop.blocks[0].stmts:
        if x.op is Op.RAW_MOD and x.operands[0] is loop and x.operands[1].op is Op.CONST:
            m = int(x.operands[1].attrs["value"])
            if m > 0 and total % m == 0 and m % width:
                return m
    return None


class _Uniformity:
    """Which statements of the parallel body have one value for every active lane of a group of `width` iterations
    (`kind`: UNIFORM), or are X + lane with X a multiple of the width (ALIGNED: the innermost axis' index), and which
    serial counted loops at its top level run the same trips in every lane (`steps`: bounds uniform, no break or
    continue). Only statements every iteration runs count (the body's top level and such loops' top level): a
    group runs them once, as lane 0 (always an active lane), before the lanes. Rules: constants and values from
    outside the loop are uniform; pure operations and loads of fields the loop does not write are uniform in uniform
    operands; X + lane floor-divided by a multiple of the width is uniform (lanes 0..W-1 stay in one block of it),
    taken modulo one stays aligned, as does adding a multiple of the width or widening it."""

    def __init__(self, loop: Stmt, width: int, mem: _Memory, inside: set):
        self.loop = loop
        self.width = width
        self.rows = _row_length(loop, width)
        self.inside = inside  # the ids of the body's statements
        self.mem = mem
        self.kind: dict[int, str] = {}
        self.steps: set[int] = set()
        self._visit(loop.blocks[0].stmts)

    def of(self, o: Stmt) -> str | None:
        if o.op is Op.CONST or id(o) not in self.inside and o is not self.loop:
            return UNIFORM
        if o is self.loop:
            begin = self.loop.operands[0]
            if self.rows is None and begin.op is Op.CONST and int(begin.attrs["value"]) % self.width == 0:
                return ALIGNED_NONNEG if int(begin.attrs["value"]) >= 0 else ALIGNED
            return None
        return self.kind.get(id(o))

    def uniform(self, s: Stmt) -> bool:
        """A statement of the body that the group runs once (statements made after the analysis are not)."""
        return self.kind.get(id(s)) == UNIFORM

    def _visit(self, stmts: list[Stmt], top: bool = True) -> None:
        for s in stmts:
            k = self._classify(s)
            if k is not None:
                self.kind[id(s)] = k
            if s.op is Op.RANGE_FOR and k == UNIFORM:
                if top:
                    self.steps.add(id(s))
                self._visit(s.blocks[0].stmts, top=False)

    def pays(self) -> bool:
        """Whether the host's width should take the loop: a uniform loop whose trips are data (LLVM vectorises no
        loop around one), and no uniform loop loading at lanes' own indices (gathers) but its own elements."""
        counted = False
        for x in self.loop.blocks[0].stmts:
            if id(x) not in self.steps:
                continue
            counted = counted or any(o.op is not Op.CONST for o in x.operands)
            for y in walk(x.blocks[0]):
                if y.op is Op.GLOBAL_LOAD and not self.uniform(y) \
                        and _key(y.operands[0].attrs["target"]) not in self.mem.owned:
                    return False
        return counted

    def _classify(self, s: Stmt) -> str | None:
        op = s.op
        kinds = [self.of(o) for o in s.operands]
        if op is Op.RANGE_FOR:
            jumps = any(x.op in (Op.BREAK, Op.CONTINUE) for x in walk(s.blocks[0]))
            ok = not s.attrs.get("parallel") and not jumps and all(k == UNIFORM for k in kinds) \
                and _lockstep(s, self.mem, self.inside)
            return UNIFORM if ok else None
        if op is Op.GLOBAL_LOAD:
            ptr = s.operands[0]
            free = ptr.op is Op.GLOBAL_PTR and _key(ptr.attrs["target"]) not in self.mem.written
            return UNIFORM if free and kinds[0] == UNIFORM else None
        if op not in PURE or op is Op.TREE_ROOT:
            return None
        if all(k == UNIFORM for k in kinds):
            return UNIFORM
        return self._aligned(s, kinds)

    def _aligned(self, s: Stmt, kinds: list) -> str | None:
        """The kind of an integer operation on an aligned value and a constant."""
        op, w = s.op, self.width
        if op is Op.RAW_MOD and self.rows is not None and s.operands[0] is self.loop \
                and s.operands[1].op is Op.CONST and int(s.operands[1].attrs["value"]) == self.rows:
            return ALIGNED_NONNEG  # the row's own index: J0 + lane, J0 a multiple of W
        if op is Op.RAW_DIV and self.rows is not None and s.operands[0] is self.loop \
                and s.operands[1].op is Op.CONST and int(s.operands[1].attrs["value"]) % self.rows == 0:
            return UNIFORM  # (row * M + J0 + lane) // (r * M): the row's
        if op not in _ALIGNED_OPS or not s.vtype.is_int or kinds[0] not in (ALIGNED, ALIGNED_NONNEG):
            return None
        if op is Op.CAST:
            src = s.operands[0].vtype
            return kinds[0] if src.is_int and s.vtype.bits >= src.bits and (s.vtype.is_signed or kinds[0] ==
                                                                          ALIGNED_NONNEG) else None
        c = s.operands[1] if len(s.operands) == 2 else None
        if c is None or c.op is not Op.CONST:
            return None
        v = int(c.attrs["value"])
        nonneg = kinds[0] == ALIGNED_NONNEG
        if op in (Op.ADD, Op.SUB) and v % w == 0:
            return ALIGNED_NONNEG if nonneg and (v >= 0) == (op is Op.ADD) else ALIGNED
        if v > 0 and v % w == 0 and (op is Op.FLOORDIV or op is Op.RAW_DIV and nonneg):
            return UNIFORM
        if v > 0 and v % w == 0 and (op is Op.MOD or op is Op.RAW_MOD and nonneg):
            return ALIGNED_NONNEG
        if op is Op.SHR and 0 <= v < s.vtype.bits and (1 << v) % w == 0 and (nonneg or s.vtype.is_signed):
            return UNIFORM
        return None


# -- slices of own elements in lane slots ---------------------------------------------------------------------
#: at most this many elements of a target in one lane's slice, and slice elements times lanes
MAX_SLICE = 64
MAX_SLICE_SLOTS = 4096


class _Slice:
    """The elements of a target a lock-step part stores to that are the lane's own: its digit axes as the
    iteration has them, its other axes whole. The part reads and writes them in lane slots (`slot`: ALLOCA of
    size * W lanes, element e of lane l at e * W + l): a masked store to memory is a scatter, slow on some CPUs
    (AMD's), which kept LLVM from vectorising the lane loop; a select into a slot is a vector store."""

    def __init__(self, ptr: Stmt, digits: dict[int, Stmt]):
        self.target = ptr.attrs["target"]
        self.ptr_type = ptr.type
        self.attrs = dict(ptr.attrs)
        self.digits = digits  # axis -> the index statement (from before the part)
        self.types = [o.vtype for o in ptr.operands]
        shape = self.target.shape
        offset = self.target.offset or (0,) * len(shape)
        self.lo = {a: offset[a] for a in range(len(shape)) if a not in digits}
        self.strides: dict[int, int] = {}
        size = 1
        for a in reversed(range(len(shape))):
            if a not in digits:
                self.strides[a] = size
                size *= shape[a]
        self.size = size
        self.slot: Stmt | None = None
        self.read = True  # the part loads the target too (else `dirty` flags say which elements to store back)
        self.dirty: Stmt | None = None

    def elements(self):
        """Each element's indices on the other axes, in slot order."""
        axes = sorted(self.strides)
        shape = self.target.shape
        for flat in range(self.size):
            yield {a: self.lo[a] + (flat // self.strides[a]) % shape[a] for a in axes}


def _slices(w: Stmt, part_of: dict[int, int], k: int, width: int, loop: Stmt, body: set) -> dict[object, _Slice]:
    """The targets step w (part k) stores to whose accesses in it all name the lane's own slice (`_Slice`): digit
    indices from before the part, other indices uniform (constants and nested loops' indices, no lane's own values)
    and inside the shape."""
    accesses: dict[object, list[Stmt]] = {}
    for x in walk(w.blocks[0]):
        if x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE, Op.ATOMIC) and x.operands[0].op is Op.GLOBAL_PTR:
            accesses.setdefault(_key(x.operands[0].attrs["target"]), []).append(x)
    inside = {id(x) for x in walk(w.blocks[0])}
    out = {}
    for key, xs in accesses.items():
        if not any(x.op is Op.GLOBAL_STORE for x in xs) or any(x.op is Op.ATOMIC for x in xs):
            continue
        ptrs = [x.operands[0] for x in xs]
        t = ptrs[0].attrs["target"]
        if not isinstance(t, FieldRef):
            continue
        digits = {}
        for axis, o in enumerate(ptrs[0].operands):
            base, _c = offset_form(o)
            if base is not None and invariant_digit(base, loop, body) is not None:
                digits[axis] = o
        if not digits or any(part_of.get(id(o)) == k for o in digits.values()):
            continue
        sl = _Slice(ptrs[0], digits)
        if sl.size > MAX_SLICE or sl.size * width > MAX_SLICE_SLOTS:
            continue
        ok = True
        for p in ptrs:
            for a in sl.strides:
                o = p.operands[a]
                r = value_range(o) if _uniform(o, inside) else None
                if r is None or r[0] < sl.lo[a] or r[1] >= sl.lo[a] + t.shape[a]:
                    ok = False
        if ok:
            sl.read = any(x.op is Op.GLOBAL_LOAD for x in xs)
            out[key] = sl
    return out


def _uniform(o: Stmt, inside: set, depth: int = 0) -> bool:
    """The same value for every lane: constants, indices of loops nested in the part, integer arithmetic of those."""
    if o.op is Op.CONST:
        return True
    if depth > 16 or id(o) not in inside:
        return False
    if o.op is Op.RANGE_FOR:
        return True
    if o.op in (Op.RAW_DIV, Op.RAW_MOD, Op.ADD, Op.SUB, Op.CAST) and o.vtype.is_int:
        return all(_uniform(x, inside, depth + 1) for x in o.operands)
    return False


# -- the rewrite ---------------------------------------------------------------------------------------------
class _MemoryRewrite(_Rewrite):
    """passes/lanes.py's rewrite, whose steps also load, store and run nested counted loops (module doc)."""

    def __init__(self, loop: Stmt, parts: list, width: int, vector_bits: int, outer: Block,
                 counted: dict[int, tuple[Stmt, Stmt]], uni: _Uniformity):
        super().__init__(loop, parts, width, vector_bits, outer)
        self.uni = uni
        # uniform statements run once per group, as lane 0 (`_hoist`): no lane slots; `group` maps a statement to
        # its value at the group's level (itself, moved there, or a copy computed for lane 0)
        self.crossing = {k: o for k, o in self.crossing.items() if not uni.uniform(o)}
        self.group: dict[int, Stmt] = {}
        # an aligned statement's operands as the body had them (a lane loop it moves into rewrites them)
        self.aligned = {id(x): x.operands for x in walk(loop.blocks[0]) if uni.of(x) in (ALIGNED, ALIGNED_NONNEG)}
        self.counted = counted
        self.memory_step = False
        self.slices: dict[object, _Slice] = {}
        body_ids = {id(x) for x in walk(loop.blocks[0])}
        self.step_slices = {k: _slices(w, self.part_of, k, self.width, loop, body_ids)
                            for k, w in enumerate(parts) if not isinstance(w, list)}
        self.store_if: Stmt | None = None  # the last masked store's IF, which the next one under p may join
        # a local a step's body declares and stores before any read is the lane's for one trip of the body: a
        # scalar of the lane loop (LLVM keeps it in a register), its first store plain, not a lane slot
        self.first_store: dict[int, Stmt] = {}
        for w in parts:
            if not isinstance(w, list):
                for a in walk(w.blocks[0]):
                    if a.op is Op.ALLOCA:
                        first = _first_store(a)
                        if first is not None:
                            self.first_store[id(a)] = first
                            self.lane_local.discard(id(a))

    # -- uniform statements and loops --------------------------------------------------------------------------
    def _group_start(self, b: Builder, begin: Stmt, end: Stmt) -> tuple[Stmt, Stmt]:
        """Groups cut per row when the uniformity's rows are (`_row_length`): group g is row g // C's lanes from
        J0 = (g % C) * W, C = ceil(M / W) groups a row, the last one short."""
        m = self.uni.rows
        if m is None:
            return super()._group_start(b, begin, end)
        per_row = -(-m // self.width)
        t = self.ity
        row = b.emit(Op.RAW_DIV, t, (self.loop, b.const(per_row, t)))
        first = b.mul(b.emit(Op.RAW_MOD, t, (self.loop, b.const(per_row, t))), b.const(self.width, t))
        left = b.sub(b.const(m, t), first)
        wide = b.const(self.width, t)
        return b.add(b.mul(row, b.const(m, t)), first), b.cast(b.select(b.lt(left, wide), left, wide), dt.i32)

    def _group_count(self, b: Builder, begin: Stmt, end: Stmt) -> Stmt:
        m = self.uni.rows
        if m is None:
            return super()._group_count(b, begin, end)
        return b.const(int(end.attrs["value"]) // m * -(-m // self.width), self.ity)

    def _hoist(self, stmts: list[Stmt]) -> list[Stmt]:
        """Move the uniform statements of `stmts` to the group's level (the builder's block), in order; returns the
        others."""
        rest = []
        for s in stmts:
            if not self.uni.uniform(s) or s.op is Op.RANGE_FOR:
                rest.append(s)
                continue
            s.operands = tuple(self._group_value(o) for o in s.operands)
            s.block = self.b.block
            self.b.block.stmts.append(s)
            self.group[id(s)] = s
        return rest

    def _group_value(self, o: Stmt) -> Stmt:
        """o at the group's level: lane 0's value (a uniform statement moved there, an aligned one computed again)."""
        if o.op is Op.CONST or (id(o) not in self.uni.inside and o is not self.loop):
            return o
        if o is self.loop:
            return self.base
        got = self.group.get(id(o))
        if got is None:
            got = self.b.emit(o.op, o.type, tuple(self._group_value(x) for x in self.aligned[id(o)]), dict(o.attrs))
            self.group[id(o)] = got
        return got

    def _operand(self, o: Stmt) -> Stmt:
        got = self.group.get(id(o))
        if got is not None and self.uni.uniform(o):
            return got
        return super()._operand(o)

    def _segment(self, k: int, stmts: list[Stmt], followed: bool) -> None:
        super()._segment(k, self._hoist(stmts), followed)

    def _uniform_trips(self, k: int, loop: Stmt, bounds: tuple[Stmt, Stmt]) -> None:
        """A counted loop with the same trips in every lane: the loop itself at the group's level over `bounds`,
        each trip its uniform statements once, then the others in one lane loop over all W lanes under `lane < n`."""
        stmts = loop.blocks[0].stmts
        loop.operands = bounds
        loop.blocks = (Block(loop),)
        loop.block = self.b.block
        self.b.block.stmts.append(loop)
        self.group[id(loop)] = loop
        around_b, saved = self.b, dict(self.group)  # values computed in a trip stay in it
        self.b = Builder(loop.blocks[0])
        self.b.loc = loop.loc
        rest = self._hoist(stmts)
        self.memory_step = any(x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE) and
                               _key(x.operands[0].attrs["target"]) not in self.slices for x in _walk_list(rest))
        lanes, lb = self._lane_loop(self.b.const(self.width, dt.i32))
        self._enter(k, lanes, lb)
        lb.loc = loop.loc
        self.broke = None
        self.store_if = None
        body = Block(lanes)
        self._predicated(rest, lb.lt(lanes, self.n), body)
        for x in body.stmts:
            x.block = lanes.blocks[0]
        lanes.blocks[0].stmts += body.stmts
        self.memory_step = False
        self.group = saved
        self.b = around_b

    def _step(self, k: int, w: Stmt) -> None:
        """The step loop, its slices loaded before and stored after it; a counted loop's only when a lane enters it
        (a group of iterations whose counts are all 0 does no step: loads, slices, nothing), a uniform one's
        (`uni.steps`) when it has trips."""
        outer_b = self.b
        self.slices = self.step_slices.get(k, {})
        for sl in self.slices.values():
            sl.slot = self.b.emit(Op.ALLOCA, sl.target.dtype, (), {"lanes": sl.size * self.width})
            if not sl.read:
                sl.dirty = self.b.emit(Op.ALLOCA, dt.i32, (), {"lanes": sl.size * self.width})
        uniform = id(w) in self.uni.steps
        if uniform:
            begin, end = (self._group_value(o) for o in w.operands)
            runs = self.b.emit(Op.IF, None, (self.b.lt(begin, end),), nblocks=2)
            self.b = Builder(runs.blocks[0])
            self.b.loc = w.loc
        elif id(w) in self.counted:
            self.b = self._entered(k, *self.counted[id(w)])
        self._slice_loop(k, load=True)
        if uniform:
            self._uniform_trips(k, w, (begin, end))
        else:
            self.memory_step = any(x.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE) for x in walk(w.blocks[0]))
            super()._step(k, w)
            self.memory_step = False
        self._slice_loop(k, load=False)
        self.slices = {}
        self.b = outer_b

    def _entered(self, k: int, counter: Stmt, end: Stmt) -> Builder:
        """A lane loop clearing `act` of the lanes whose count is already reached, and an IF on any lane left: the
        builder of its body."""
        b = self.b
        b.emit(Op.LOCAL_STORE, None, (self.any, b.const(0, dt.i32)))
        loop, lb = self._lane_loop(b.const(self.width, dt.i32))
        self._enter(k, loop, lb)
        live = lb.bit_and(lb.emit(Op.LOCAL_LOAD, dt.i32, (self.act, loop)),
                          lb.lt(lb.emit(Op.LOCAL_LOAD, counter.vtype, (counter, loop)), self._operand(end)))
        lb.emit(Op.LOCAL_STORE, None, (self.act, live, loop))
        lb.emit(Op.LOCAL_STORE, None, (self.any, lb.bit_or(lb.emit(Op.LOCAL_LOAD, dt.i32, (self.any,)), live)))
        guard = b.emit(Op.IF, None, (b.ne(b.emit(Op.LOCAL_LOAD, dt.i32, (self.any,)), b.const(0, dt.i32)),),
                       nblocks=2)
        inner = Builder(guard.blocks[0])
        inner.loc = b.loc
        return inner

    def _slice_loop(self, k: int, load: bool) -> None:
        """Before the step, each lane's slices of its own elements into their slots; after it, back."""
        if not self.slices:
            return
        loop, lb = self._lane_loop(self.n)
        self._enter(k, loop, lb)
        for sl in self.slices.values():
            digits = {a: self._operand(o) for a, o in sl.digits.items()}
            for flat, rest in enumerate(sl.elements()):
                idx = tuple(digits[a] if a in digits else lb.const(rest[a], sl.types[a]) for a in
                            range(len(sl.types)))
                at = lb.add(lb.const(flat * self.width, dt.i32), loop)
                if load and sl.dirty is not None:  # stored only: nothing to load, no element written yet
                    lb.emit(Op.LOCAL_STORE, None, (sl.dirty, lb.const(0, dt.i32), at))
                    continue
                if not load and sl.dirty is not None:  # back only the elements the lane wrote
                    written = lb.emit(Op.IF, None, (lb.emit(Op.LOCAL_LOAD, dt.i32, (sl.dirty, at)),), nblocks=2)
                    lb.blocks.append(written.blocks[0])
                ptr = lb.emit(Op.GLOBAL_PTR, sl.ptr_type, idx, dict(sl.attrs))
                if load:
                    lb.emit(Op.LOCAL_STORE, None, (sl.slot, lb.emit(Op.GLOBAL_LOAD, sl.target.dtype, (ptr,)), at))
                else:
                    lb.emit(Op.GLOBAL_STORE, None, (ptr, lb.emit(Op.LOCAL_LOAD, sl.target.dtype, (sl.slot, at))))
                if not load and sl.dirty is not None:
                    lb.blocks.pop()

    def _lane_loop(self, count: Stmt) -> tuple[Stmt, Builder]:
        loop, lb = super()._lane_loop(count)
        if self.memory_step:  # the lanes touch no element another lane stores (codegen: an access group)
            loop.attrs["parallel_lanes"] = True
        return loop, lb

    def _predicated(self, stmts: list[Stmt], p: Stmt, into: Block) -> Stmt | None:
        for s in stmts:
            if s.op is Op.GLOBAL_PTR:
                continue  # made again at each access, with indices safe for it
            if s.op in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE) and _key(s.operands[0].attrs["target"]) in self.slices:
                self._slice_access(s, p, into)
            elif s.op is Op.GLOBAL_LOAD:
                s.operands = (self._pointer(s.operands[0], p, into),)
                s.block = into
                into.stmts.append(s)
            elif s.op is Op.GLOBAL_STORE:
                self._masked_store(s, p, into)
                continue
            elif s.op is Op.RANGE_FOR:
                self._nested(s, p, into)
            elif s.op in (Op.LOCAL_STORE, Op.ATOMIC) and id(s.operands[0]) in self.first_store:
                self._scalar_store(s, p, into)
            else:
                q = super()._predicated([s], p, into)
                if q is None:
                    return None
                p = q
            self.store_if = None
        return p

    def _slice_access(self, s: Stmt, p: Stmt, into: Block) -> None:
        """A load or store of an element of the lane's slice: its slot (a store keeps the old value where p is 0)."""
        ptr = s.operands[0]
        sl = self.slices[_key(ptr.attrs["target"])]
        at: Stmt | None = None
        for a, stride in sl.strides.items():
            o = self._operand(ptr.operands[a])
            lo = Builder.constant(sl.lo[a], o.vtype)
            term = self._emit(Op.MUL, o.vtype, (self._emit(Op.SUB, o.vtype, (o, lo), into),
                                                Builder.constant(stride * self.width, o.vtype)), into)
            term = term if term.vtype is dt.i32 else self._emit(Op.CAST, dt.i32, (term,), into)
            at = term if at is None else self._emit(Op.ADD, dt.i32, (at, term), into)
        at = self.lane if at is None else self._emit(Op.ADD, dt.i32, (at, self.lane), into)
        t = sl.target.dtype
        if s.op is Op.GLOBAL_LOAD:
            s.op, s.operands = Op.LOCAL_LOAD, (sl.slot, at)
            s.block = into
            into.stmts.append(s)
            return
        old = self._emit(Op.LOCAL_LOAD, t, (sl.slot, at), into)
        kept = self._emit(Op.SELECT, t, (p, self._operand(s.operands[1]), old), into)
        into.stmts.append(Builder.detached(Op.LOCAL_STORE, None, (sl.slot, kept, at), None, s.loc, into))
        if sl.dirty is not None:
            flag = self._emit(Op.BIT_OR, dt.i32, (self._emit(Op.LOCAL_LOAD, dt.i32, (sl.dirty, at), into), p), into)
            into.stmts.append(Builder.detached(Op.LOCAL_STORE, None, (sl.dirty, flag, at), None, s.loc, into))

    def _pointer(self, ptr: Stmt, p: Stmt, into: Block) -> Stmt:
        """ptr's element as this lane reads it: where p is 0, each index not known to be inside the shape is the
        axis's first (a field's index offset)."""
        t = ptr.attrs["target"]
        idx = []
        for axis, o in enumerate(ptr.operands):
            v = self._operand(o)
            lo = t.offset[axis] if t.offset else 0
            if not (o.op is Op.CONST and lo <= int(o.attrs["value"]) < lo + t.shape[axis]):
                v = self._emit(Op.SELECT, v.vtype, (p, v, Builder.constant(lo, v.vtype)), into)
            idx.append(v)
        q = Builder.detached(Op.GLOBAL_PTR, ptr.type, tuple(idx), dict(ptr.attrs), ptr.loc, into)
        into.stmts.append(q)
        return q

    def _masked_store(self, s: Stmt, p: Stmt, into: Block) -> None:
        """`if p: x[I] = v`, in the IF of the store just before when that has the same p."""
        ptr, v = s.operands
        value = self._operand(v)
        cur = self.store_if
        if cur is None or cur.operands[0] is not p or not into.stmts or into.stmts[-1] is not cur:
            cur = self._emit(Op.IF, None, (p,), into)
            cur.blocks = (Block(cur), Block(cur))
            self.store_if = cur
        then = cur.blocks[0]
        q = Builder.detached(Op.GLOBAL_PTR, ptr.type, tuple(self._operand(o) for o in ptr.operands),
                             dict(ptr.attrs), ptr.loc, then)
        then.stmts.append(q)
        s.operands = (q, value)
        s.block = then
        then.stmts.append(s)

    def _scalar_store(self, s: Stmt, p: Stmt, into: Block) -> None:
        """A store or update of a scalar local (`first_store`): the first store as it is, others select(p, new,
        old)."""
        s.operands = tuple(self._operand(o) for o in s.operands)
        var = s.operands[0]
        if s is self.first_store[id(var)]:
            s.block = into
            into.stmts.append(s)
            return
        old = self._emit(Op.LOCAL_LOAD, var.vtype, (var,), into)
        if s.op is Op.ATOMIC:
            kind = s.attrs["kind"]
            new = s.operands[1]
            if kind != "xchg":
                attrs = {"reassoc": True} if s.attrs.get("reassoc") else None
                new = Builder.detached(_UPDATE_OPS[kind], s.vtype, (old, new), attrs, s.loc, into)
                into.stmts.append(new)
            self.local[id(s)] = old
        else:
            new = s.operands[1]
        kept = self._emit(Op.SELECT, var.vtype, (p, new, old), into)
        into.stmts.append(Builder.detached(Op.LOCAL_STORE, None, (var, kept), None, s.loc, into))

    def _nested(self, s: Stmt, p: Stmt, into: Block) -> None:
        """A serial loop of constant trip count: its body flattened under p, every lane running every trip, the loop
        unrolled whole by LLVM."""
        s.operands = tuple(self._operand(o) for o in s.operands)
        s.attrs["unroll"] = True
        s.block = into
        into.stmts.append(s)
        body = s.blocks[0]
        stmts = body.stmts
        body.stmts = []
        self.store_if = None
        self._predicated(stmts, p, body)
