"""The CPU target: each top-level parallel loop is outlined into a task function
`void task(ptr closure, i64 lo, i64 hi, i32 tid)` that the runtime's parallel_for (runtime/threadpool.py)
splits across threads. The closure (an i64 array on the caller's stack) holds the context pointer, then
every value the loop body uses from outside, then the per-thread copies of privatised regions.

What each task sets up (per-thread sums, per-thread copies) follows the loop's LoopStrategy
(passes/parallel_strategy.py); the variant over copies is chosen at run time (codegen/privatize.py).
"""

from __future__ import annotations

from simgrad.codegen.llvm import FunctionText, KernelCodegen, llvm_type
from simgrad.codegen.privatize import copy_layout, emit_private_launch, emit_runs_alone, slice_shift
from simgrad.ir.nodes import Stmt, offset_form, walk
from simgrad.ir.ops import Op
from simgrad.passes.parallel_strategy import PRIVATE, LoopStrategy
from simgrad.passes.privatize import Region
from simgrad.runtime import abi
from simgrad.runtime.jit import NO_SLP

Capture = tuple[int, str, bool]  # (closure slot, LLVM type, passed by value)


class CpuCodegen(KernelCodegen):
    """LLVM IR for the host CPU: parallel loops run on the native thread pool."""

    vecmath_target = True  # f32 sin, cos, exp ... vectorisable (codegen/vecmath.py) under fast_math

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.ntasks = 0

    def parallel_loop(self, f: FunctionText, s: Stmt) -> None:
        plan: LoopStrategy = s.attrs["strategy"]
        if any(x.op is Op.WHILE for x in walk(s.blocks[0])) and NO_SLP not in self.module.globals \
                and not any(x.attrs.get("simt") for x in self.kernel.body.stmts):
            # LLVM's SLP vectoriser packs the values a data-dependent loop carries (a complex number z) into
            # <2 x float> and unpacks them every iteration: the shuffles lengthen the carried chain (Julia and
            # Mandelbrot sets: 1.3-1.4x slower than scalar code); runtime/jit.py reads the marker. A kernel with
            # lanes in lock step (passes/lanes.py) keeps it: the lane loop of a step, fully unrolled, is what SLP
            # makes <W x T> code of, its lane slots kept in vector registers across steps
            self.module.globals.append(NO_SLP)
        captured = _free_values(s)
        regions = plan.regions
        clo = f.tmp("clo")
        f.prologue.append(f"  {clo} = alloca [{len(captured) + 2 * len(regions) + 1} x i64], align 8")  # copies, maps
        f.emit(f"store ptr %ctx, ptr {clo}")
        stored = {id(x.operands[0]) for x in walk(s.blocks[0]) if x.op in (Op.LOCAL_STORE, Op.ATOMIC)}
        slots: list[Capture] = []
        for k, v in enumerate(captured, start=1):
            by_value = v.op is Op.ALLOCA and id(v) not in stored  # read-only local: a private copy
            is_ptr = v.op is Op.GLOBAL_PTR or (v.op is Op.ALLOCA and not by_value)
            ty = "ptr" if is_ptr else llvm_type(v.vtype)
            src = f.v(v)
            if by_value:
                src = f.tmp("ld")
                f.emit(f"{src} = load {ty}, ptr {f.v(v)}")
            p = f.tmp("cap")
            f.emit(f"{p} = getelementptr i64, ptr {clo}, i64 {k}")
            f.emit(f"store {ty} {src}, ptr {p}")
            slots.append((k, ty, by_value))
        self.ntasks += 1
        tname = f"{self.symbol}_task{self.ntasks}"
        self._emit_task(s, plan, tname, captured, slots, [])
        ty = llvm_type(s.vtype)
        b64, e64 = f.tmp("b"), f.tmp("e")
        ext = "sext" if ty != "i64" else None
        for dst, src_stmt in ((b64, s.operands[0]), (e64, s.operands[1])):
            f.emit(f"{dst} = {ext} {ty} {f.v(src_stmt)} to i64" if ext else f"{dst} = add i64 {f.v(src_stmt)}, 0")
        pfor = f.ctx_slot(abi.CTX_PFOR, "ptr")
        grain = plan.grain  # decided before access lowering added its address arithmetic
        if not regions:
            if not _needs_atomics(s):
                f.emit(f"call void {pfor}(ptr @{tname}, ptr {clo}, i64 {b64}, i64 {e64}, i64 {grain})")
                return
            # the variant with plain updates, for when the pool runs the loop on this thread alone
            sname = f"{tname}_serial"
            self._emit_task(s, plan, sname, captured, slots, [], serial=True)
            _, alone = emit_runs_alone(f, f.ctx_slot(abi.CTX_NTHREADS, "i64"), b64, e64, grain)
            task = f.tmp("svtask")
            f.emit(f"{task} = select i1 {alone}, ptr @{sname}, ptr @{tname}")
            f.emit(f"call void {pfor}(ptr {task}, ptr {clo}, i64 {b64}, i64 {e64}, i64 {grain})")
            return
        pname = f"{tname}_private"
        self._emit_task(s, plan, pname, captured, slots, regions, first_slot=len(captured) + 1)
        # on one thread alone: the fields are thread 0's copies, no page marks, and the updates the copies do
        # not take are plain too
        alone_name = f"{pname}_serial"
        self._emit_task(s, plan, alone_name, captured, slots, regions, first_slot=len(captured) + 1, serial=True)
        nthreads = f.ctx_slot(abi.CTX_NTHREADS, "i64")
        emit_private_launch(f, regions, plan.weight, clo, len(captured) + 1, tname, pname, pfor, nthreads, b64,
                            e64, grain, alone_name)

    def _emit_task(self, s: Stmt, plan: LoopStrategy, tname: str, captured: list[Stmt], slots: list[Capture],
                   regions: list[Region], first_slot: int = 0, serial: bool = False) -> None:
        """The outlined loop: `task(closure, lo, hi, tid)`; with `regions`, the variant that adds into this
        thread's private copies of those regions (closure slots from `first_slot` hold the copies)."""
        t = FunctionText(self, tname, f"internal void @{tname}(ptr %clo, i64 %lo, i64 %hi, i32 %tid)", True)
        t.loop = s
        t.serial = serial
        if plan.independent:  # (a loop taichi would run in order at one thread keeps its order)
            self.parallel_group(t)
        t.prologue.append("  %ctx = load ptr, ptr %clo")
        for v, (k, ty, by_value) in zip(captured, slots):
            q, val = t.tmp("cap"), t.tmp("capv")
            t.prologue.append(f"  {q} = getelementptr i64, ptr %clo, i64 {k}")
            t.prologue.append(f"  {val} = load {ty}, ptr {q}")
            if by_value:
                copy = t.tmp("var")
                t.prologue.append(f"  {copy} = alloca {ty}")
                t.prologue.append(f"  store {ty} {val}, ptr {copy}")
                val = copy
            t.names[v] = val
        for k, r in enumerate(regions):
            _private_root(t, r, first_slot + k, first_slot + len(regions) + k)
        ty = llvm_type(s.vtype)
        lo, hi = t.tmp("lo"), t.tmp("hi")
        t.prologue.append(f"  {lo} = trunc i64 %lo to {ty}" if ty != "i64" else f"  {lo} = add i64 %lo, 0")
        t.prologue.append(f"  {hi} = trunc i64 %hi to {ty}" if ty != "i64" else f"  {hi} = add i64 %hi, 0")
        self.open_reductions(t, plan)  # per-thread sums, added once per chunk
        split = _row_split(s)
        if split is None:
            self.serial_loop(t, s, lo, hi)
        else:
            self._row_loops(t, s, lo, hi, *split)
        self.flush_reductions(t, plan)
        t.emit("ret void")
        self.module.functions.append(t.text())

    def _row_loops(self, t: FunctionText, s: Stmt, lo: str, hi: str, mod: Stmt, div: Stmt | None,
                   extent: Stmt) -> None:
        """The chunk [lo, hi) of a flat index i whose body splits it as (i / n, i % n) (ti.ndrange, a struct-for
        over several axes) runs as rows: an outer loop over q = i / n and an inner counted loop over r = i % n, so
        the body needs no division and its last-axis accesses are consecutive in r (LLVM vectorises the inner
        loop, which the division kept it from)."""
        ty = llvm_type(s.vtype)
        pre, ohead, obody, ihead, ibody, ilatch, olatch, done = (t.label(x) for x in (
            "rpre", "rowhead", "rowbody", "colhead", "colbody", "collatch", "rowlatch", "rowdone"))
        q0, r0, q, rs, base, start, more, left, short, end, r, rn, qn, c, i = (t.tmp(x) for x in (
            "q0", "r0", "q", "rs", "rowbase", "start", "more", "left", "short", "rend", "r", "rnext", "qnext", "c",
            "i"))
        t.emit(f"br label %{pre}")
        t.start_block(pre)
        n = t.v(extent)
        if extent.op is not Op.CONST:  # a run-time extent below 1 means no iterations: never divide by it
            small, n1 = t.tmp("small"), t.tmp("n")
            t.emit(f"{small} = icmp slt {ty} {n}, 1")
            t.emit(f"{n1} = select i1 {small}, {ty} 1, {ty} {n}")
            n = n1
        t.emit(f"{q0} = udiv {ty} {lo}, {n}")  # chunk bounds are never negative
        t.emit(f"{r0} = urem {ty} {lo}, {n}")
        t.emit(f"br label %{ohead}")
        t.start_block(ohead)
        t.emit(f"{q} = phi {ty} [{q0}, %{pre}], [{qn}, %{olatch}]")
        t.emit(f"{rs} = phi {ty} [{r0}, %{pre}], [0, %{olatch}]")
        t.emit(f"{base} = mul nuw nsw {ty} {q}, {n}")
        t.emit(f"{start} = add nuw nsw {ty} {base}, {rs}")
        t.emit(f"{more} = icmp slt {ty} {start}, {hi}")
        t.emit(f"br i1 {more}, label %{obody}, label %{done}")
        t.start_block(obody)
        t.emit(f"{left} = sub nsw {ty} {hi}, {base}")
        t.emit(f"{short} = icmp slt {ty} {left}, {n}")
        t.emit(f"{end} = select i1 {short}, {ty} {left}, {ty} {n}")
        if div is not None:
            t.names[div] = q
            t.bound.add(id(div))
        t.bound.add(id(mod))
        middle = _column_split(s, mod, extent)
        after = ihead  # where the edge loop's latch goes
        if middle is None:
            t.emit(f"br label %{ihead}")
            t.start_block(ihead)
            t.emit(f"{r} = phi {ty} [{rs}, %{obody}], [{rn}, %{ilatch}]")
            t.emit(f"{c} = icmp slt {ty} {r}, {end}")
            t.emit(f"br i1 {c}, label %{ibody}, label %{olatch}")
        else:  # r runs [rs, A) and [B, end) here, and [A, B) in the inner loop that `edge` leaves to
            a, b, facts = middle
            stop, second, rb, sb, secb = (t.tmp(x) for x in ("stop", "second", "rb", "sb", "secb"))
            eback = t.label("edgeback")
            edge, mhead, mbody, mlatch, mdone = (t.label(x) for x in ("edge", "midhead", "midbody", "midlatch",
                                                                       "middone"))
            e1, m0, m1, s3 = (t.tmp(x) for x in ("e1", "m0", "m1", "s3"))
            for fn in ("smin", "smax"):
                self.module.declare(f"declare {ty} @llvm.{fn}.{ty}({ty}, {ty})")
            t.emit(f"{e1} = call {ty} @llvm.smin.{ty}({ty} {end}, {ty} {a})")
            t.emit(f"{m0} = call {ty} @llvm.smax.{ty}({ty} {rs}, {ty} {a})")
            t.emit(f"{m1} = call {ty} @llvm.smin.{ty}({ty} {end}, {ty} {b})")
            t.emit(f"{s3} = call {ty} @llvm.smax.{ty}({ty} {rs}, {ty} {b})")
            t.emit(f"br label %{ihead}")
            t.start_block(ihead)
            t.emit(f"{r} = phi {ty} [{rs}, %{obody}], [{rb}, %{eback}]")
            t.emit(f"{stop} = phi {ty} [{e1}, %{obody}], [{sb}, %{eback}]")
            t.emit(f"{second} = phi i1 [false, %{obody}], [{secb}, %{eback}]")
            t.emit(f"{c} = icmp slt {ty} {r}, {stop}")
            t.emit(f"br i1 {c}, label %{ibody}, label %{edge}")
            t.start_block(edge)
            t.emit(f"br i1 {second}, label %{olatch}, label %{mhead}")
            rm, rmn, cm, im = (t.tmp(x) for x in ("rm", "rmnext", "cm", "im"))
            t.start_block(mhead)
            t.emit(f"{rm} = phi {ty} [{m0}, %{edge}], [{rmn}, %{mlatch}]")
            t.emit(f"{cm} = icmp slt {ty} {rm}, {m1}")
            t.emit(f"br i1 {cm}, label %{mbody}, label %{mdone}")
            t.start_block(mbody)
            t.emit(f"{im} = add nuw nsw {ty} {base}, {rm}")
            t.names[s], t.names[mod] = im, rm
            for x, value in facts:  # the comparisons of r that are constant on [A, B)
                t.names[x] = str(value)
                t.bound.add(id(x))
            self.loop_body(t, s, done, mlatch)
            for x, _value in facts:
                t.bound.discard(id(x))
            t.emit(f"{rmn} = add nuw nsw {ty} {rm}, 1")
            t.emit(f"br label %{mhead}{self.parallel_loop_id(t) if s is t.loop else ''}")
            t.start_block(mdone)
            # the edge columns are few: their loop is not vectorised (nor unrolled), only the middle one
            k = 1000 + 2 * len(self.module.globals)
            self.module.globals += [f"!{k} = distinct !{{!{k}, !{k + 1}, !{k + 2}}}",
                                    f'!{k + 1} = !{{!"llvm.loop.vectorize.enable", i1 false}}',
                                    f'!{k + 2} = !{{!"llvm.loop.unroll.disable"}}']
            t.emit(f"br label %{eback}")
            t.start_block(eback)
            t.emit(f"{rb} = phi {ty} [{rn}, %{ilatch}], [{s3}, %{mdone}]")
            t.emit(f"{sb} = phi {ty} [{stop}, %{ilatch}], [{end}, %{mdone}]")
            t.emit(f"{secb} = phi i1 [{second}, %{ilatch}], [true, %{mdone}]")
            t.emit(f"br label %{ihead}, !llvm.loop !{k}")
            after = eback
        t.start_block(ibody)
        t.emit(f"{i} = add nuw nsw {ty} {base}, {r}")
        t.names[s], t.names[mod] = i, r
        self.loop_body(t, s, done, ilatch)
        t.emit(f"{rn} = add nuw nsw {ty} {r}, 1")
        # (split: the edge loop's latch goes to `eback`, whose branch carries its no-vectorise metadata)
        t.emit(f"br label %{after}{self.parallel_latch(t, s) if middle is None else ''}")
        t.start_block(olatch)
        t.emit(f"{qn} = add nuw nsw {ty} {q}, 1")
        t.emit(f"br label %{ohead}")
        t.start_block(done)


#: comparison -> whether `r + c op k` holds, and the r from which on it changes (a < b: the first r >= k - c)
_MONOTONE = {Op.LT: (lambda a, b: a < b, 0), Op.LE: (lambda a, b: a <= b, 1), Op.GT: (lambda a, b: a > b, 1),
             Op.GE: (lambda a, b: a >= b, 0)}
_SWAPPED = {Op.LT: Op.GT, Op.LE: Op.GE, Op.GT: Op.LT, Op.GE: Op.LE}
#: what a body holding them is not emitted twice for (each is one place in the program or the function)
_ONCE = {Op.RANGE_FOR, Op.WHILE, Op.PRINT, Op.ASSERT, Op.CALL, Op.TAPE_PUSH, Op.TAPE_POP, Op.TAPE_RESET,
         Op.SNODE_OP, Op.SPARSE_CELL, Op.SPARSE_ACTION, Op.CHECK_INDEX}
#: the shortest middle worth a second copy of the body
MIN_MIDDLE = 16


def _column_split(loop: Stmt, mod: Stmt, extent: Stmt) -> tuple[int, int, list[tuple[Stmt, int]]] | None:
    """(A, B, facts) when the body compares the column r = i % n plus a constant with constants (a periodic
    neighbour `jp = j + 1 if j + 1 < n else 0`, a boundary test `if 0 < j < n - 1`): on [A, B), the longest
    stretch of [0, n) that no comparison changes on, each is the constant in facts. The row loop then runs
    those columns with the comparisons folded, a second copy of the body whose neighbour addresses are
    affine in r: LLVM loads them as vectors, where the selects made it gather each (snow_phaseField's
    get_rate), and vectorises loops the branches kept it from. None when there is no such comparison,
    the stretch is short or the body may not be emitted twice."""
    if extent.op is not Op.CONST:
        return None
    n = int(extent.attrs["value"])
    cmps: list[tuple[Stmt, Op, int, int]] = []  # (statement, op, c, k): r + c op k
    for x in walk(loop.blocks[0]):
        if x.op in _ONCE:
            return None
        if x.op not in _MONOTONE and x.op not in (Op.EQ, Op.NE):
            continue
        for side, other, op in ((0, 1, x.op), (1, 0, _SWAPPED.get(x.op, x.op))):
            base, c = offset_form(x.operands[side])
            if base is mod and x.operands[other].op is Op.CONST and x.operands[side].type.is_signed:
                k = int(x.operands[other].attrs["value"])
                if abs(c) < 2 ** 30 and abs(k) < 2 ** 30:
                    cmps.append((x, op, c, k))
                break
    if not cmps:
        return None
    points = {0, n}
    for _x, op, c, k in cmps:
        for p in ((k - c + _MONOTONE[op][1],) if op in _MONOTONE else (k - c, k - c + 1)):
            if 0 < p < n:
                points.add(p)
    edges = sorted(points)
    a, b = max(zip(edges, edges[1:]), key=lambda e: e[1] - e[0])
    if b - a < MIN_MIDDLE:
        return None
    facts = []
    for x, op, c, k in cmps:
        holds = _MONOTONE[op][0](a + c, k) if op in _MONOTONE else (a + c == k) == (op is Op.EQ)
        facts.append((x, int(holds)))
    return a, b, facts


def _needs_atomics(loop: Stmt, copied: bool = True) -> bool:
    """Whether some update of the loop is an atomic read-modify-write across threads (atomic or paired; not the
    compare-and-swap loops of quant cells, which stay as they are); `copied=False`: not counting the updates of
    per-thread copies (`private|...`)."""
    return any(x.op is Op.ATOMIC and x.attrs.get("kind") != "cas"
               and (copied or not x.attrs.get("strategy", "").startswith(PRIVATE))
               and x.attrs.get("strategy", "").split("|")[-1] in ("atomic", "pair") for x in walk(loop.blocks[0]))


def _row_split(loop: Stmt) -> tuple[Stmt, Stmt | None, Stmt] | None:
    """(i % n, i / n or None, n) when the loop body's first level takes its index apart by n: a constant >= 2,
    or a value from before the loop (an ndarray's extent). Only the frontend's index decomposition makes
    RAW_MOD/RAW_DIV of the loop index (C remainder and division; the index is never negative)."""
    inside = {id(x) for x in walk(loop.blocks[0])}
    mods: dict[tuple, Stmt] = {}
    divs: dict[tuple, Stmt] = {}
    for x in loop.blocks[0].stmts:
        if x.op not in (Op.RAW_MOD, Op.RAW_DIV) or x.operands[0] is not loop:
            continue
        n = x.operands[1]
        key = ("c", n.attrs["value"]) if n.op is Op.CONST else ("s", id(n))  # equal constants: distinct statements
        if (n.op is Op.CONST and int(n.attrs["value"]) >= 2) or (n.op is not Op.CONST and id(n) not in inside):
            (mods if x.op is Op.RAW_MOD else divs).setdefault(key, x)
    for key, mod in mods.items():
        return mod, divs.get(key), mod.operands[1]
    return None


def _private_root(t: FunctionText, region: Region, slot: int, map_slot: int) -> None:
    """Point the region's updates at this thread's zeroed copy (closure slot `slot`), shifted so that
    the fields' usual byte offsets land inside it, and their page marks at this thread's map (all threads'
    maps from closure slot `map_slot`; codegen/privatize.py)."""
    q, buf, t64, off, base, root, mq, maps, mrow, mine = (t.tmp("pr") for _ in range(10))
    lines = [f"{q} = getelementptr i64, ptr %clo, i64 {slot}", f"{buf} = load ptr, ptr {q}",
             f"{t64} = zext i32 %tid to i64"]
    _size, _pages, stride, map_stride = copy_layout(lines, lambda: t.tmp("rb"), t.array_shape, region)
    lines += [f"{off} = mul i64 {t64}, {stride}", f"{base} = getelementptr inbounds i8, ptr {buf}, i64 {off}",
              f"{mq} = getelementptr i64, ptr %clo, i64 {map_slot}", f"{maps} = load ptr, ptr {mq}",
              f"{mrow} = mul i64 {t64}, {map_stride}", f"{mine} = getelementptr inbounds i8, ptr {maps}, i64 {mrow}"]
    neg = "0"
    if region.array is not None:  # the whole array: its offsets land in the copy as they are
        root = base
    else:
        shift = slice_shift(lines, lambda: t.tmp("sh"), t.v, region)
        neg = t.tmp("pr")
        lines += [f"{neg} = sub i64 {-region.lo}, {shift}", f"{root} = getelementptr i8, ptr {base}, i64 {neg}"]
    t.prologue += ["  " + line for line in lines]
    t.private_marks[root] = None if t.serial else (mine, neg)  # (alone on one thread: no sum to mark pages for)
    for tid, key in region.keys:
        t.private_roots[(tid, key)] = root
        t.private_prefix[tid] = len(key)  # every update of a field uses the same number of prefix axes


def _free_values(loop: Stmt) -> list[Stmt]:
    """Values used inside `loop` but defined outside it (constants excepted), in first-use order."""
    inside = {id(s) for s in walk(loop.blocks[0])}
    inside.add(id(loop))
    seen: dict[int, Stmt] = {}
    for s in walk(loop.blocks[0]):
        for o in s.operands:
            if id(o) not in inside and o.op is not Op.CONST and id(o) not in seen:
                seen[id(o)] = o
    return list(seen.values())
