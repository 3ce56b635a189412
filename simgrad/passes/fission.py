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

from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Kernel, Stmt, walk
from simgrad.ir.ops import PURE, Op
from simgrad.passes.lanes import _jumps_out, _Rewrite, _walk_list
from simgrad.passes.parallel_strategy import PLAIN, REDUCE, LoopStrategy

#: never in a split loop: calls and sparse structure ops may do anything, the tape is a per-thread stack whose
#: order the split would change, prints and asserts order themselves against the scatters, loops are not
#: straight-line code the vectoriser can take
_REFUSED = {Op.CALL, Op.SNODE_OP, Op.SPARSE_CELL, Op.SPARSE_ACTION, Op.TAPE_RESET, Op.TAPE_PUSH, Op.TAPE_POP,
            Op.CHECK_INDEX, Op.RET_STORE, Op.FUNC_RETURN, Op.PRINT, Op.ASSERT, Op.WHILE, Op.RANGE_FOR,
            Op.BREAK, Op.CONTINUE}
#: float arithmetic part 0 must hold for the split to pay: a few values computed and scattered gain nothing from
#: a vectorised part 0 and pay for the slots
MIN_FLOAT_OPS = 16
#: bytes of lane slots per group: they stay in L1 while part 1 reads them back
SLOT_BYTES = 16384


def fission(kernel: Kernel, width: int, vector_bits: int = 0) -> bool:
    """Split every top-level parallel loop that matches (see the module's doc) into groups of `width` iterations;
    width -1: two vector registers of `vector_bits` of f32 lanes, halved while the slots exceed SLOT_BYTES."""
    if width == 0 or width == 1 or (width < 0 and vector_bits <= 0):
        return False
    changed = False
    out: list[Stmt] = []
    for s in kernel.body.stmts:
        if s.op is Op.RANGE_FOR and s.attrs.get("parallel") and not s.attrs.get("cells") \
                and not s.attrs.get("listgen") and not s.attrs.get("simt"):
            parts = _match(s)
            if parts is not None:
                out += _Split(s, parts, width, vector_bits, kernel.body).run()
                changed = True
        out.append(s)
    kernel.body.stmts = out
    return changed


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
    if sum(1 for x in _walk_list(part0) if x.op in PURE and x.vtype is not None and x.vtype.is_float) \
            < MIN_FLOAT_OPS:
        return None
    return [part0, part1]


class _Split(_Rewrite):
    """lanes.py's rewrite of two lane-loop parts, the loop marked `fission` (its width)."""

    mark = "fission"

    def _auto_width(self, vector_bits: int) -> int:
        slot_bytes = sum(max(o.vtype.bits, 8) // 8 for o in self.crossing.values())
        width = max(8, min(64, 2 * vector_bits // 32))
        while width > 8 and width * slot_bytes > SLOT_BYTES:
            width //= 2
        return width
