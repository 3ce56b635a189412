"""Scatter privatisation: which fields a parallel loop may accumulate into through per-thread copies.

A particle-to-grid scatter (`grid[base + offset] += w`) or the adjoint of a gather (`density.grad[i] += g`)
spends most of its time in lock-prefixed read-modify-writes. When a loop only *adds* into a field (never
reads it, never stores to it, never uses an atomic's old value), each thread can add into a private,
zeroed copy of the field's memory with plain instructions, and the copies are summed into the field once
after the loop. That pays off when the loop does many more updates than the field has elements, which
the generated code decides at run time from the trip count (`emit_private_launch`); otherwise the usual
atomic task runs. Summing per-thread partials reorders float additions, which atomics already leave unordered.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simgrad.ir.nodes import Stmt
from simgrad.ir.ops import Op
from simgrad.lang.field import ScalarField

# One contended-or-not lock-prefixed update costs about as much as zeroing and summing this many elements
# of a copy (vectorised, mostly in cache): measured on the 3-D MPM p2g (110k cells, 4.5k particles).
ATOMIC_COST = 8
MAX_COPY_BYTES = 1 << 28  # all threads' copies together; a larger scatter keeps its atomics


@dataclass
class Region:
    """The bytes [lo, hi) past a run-time slice base of one SNode tree, copied per thread. The base is
    the sum of `index * stride` over `prefix`: leading axes every update indexes with the same
    loop-invariant values (a time step `t` of `h.grad[t, i, j]`), so only that slice is copied."""

    tree_id: int
    lo: int
    hi: int
    dtype: object
    prefix: tuple  # ((index Stmt, stride in bytes), ...)
    keys: set = field(default_factory=set)  # (id(field), access_key) of the updates it takes

    @property
    def count(self) -> int:
        return (self.hi - self.lo) // self.dtype.nbytes


def _span(f: ScalarField, nprefix: int) -> tuple[int, int]:
    """[first byte, one past the last byte] of a dense field's elements in its tree, for fixed values of
    its first `nprefix` indices (their offset left out)."""
    _tree, const, terms, shape = f.layout
    top = const
    for t in terms:
        if t.axis < nprefix:
            continue
        digit = (shape[t.axis] - 1) // t.divisor
        if t.modulus:
            digit = min(digit, t.modulus - 1)
        top += digit * t.stride
    return const, top + f.dtype.nbytes


def _prefix_len(f: ScalarField, ptrs: list[Stmt], loop: Stmt, inside: set) -> int:
    """How many leading axes every update indexes with loop-invariant values, each a plain strided axis."""
    n = min(len(p.operands) for p in ptrs)
    for p in ptrs:
        k = 0
        while k < n and (p.operands[k].op is Op.CONST or (id(p.operands[k]) not in inside
                                                          and p.operands[k] is not loop)):
            k += 1
        n = k
    terms = f.layout[2]
    for a in range(n):
        own = [t for t in terms if t.axis == a]
        if len(own) != 1 or own[0].divisor != 1 or own[0].modulus:
            return a
    return n


def access_key(ptr: Stmt, nprefix: int) -> tuple:
    """Which slice an update goes to: its first `nprefix` index values (constants by value)."""
    return tuple(("c", o.attrs["value"]) if o.op is Op.CONST else id(o) for o in ptr.operands[:nprefix])


def _updates(block, uses: dict, times: int, adds: dict, others: dict) -> None:
    """Per field target: the unused-result atomic adds of a block with how often each runs per iteration
    (serial loops of constant trip multiply), and the pointers through which it is touched any other way."""
    for x in block.stmts:
        for k, o in enumerate(x.operands):
            if o.op is not Op.GLOBAL_PTR:
                continue
            target = o.attrs["target"]
            if x.op is Op.ATOMIC and k == 0 and x.attrs["kind"] == "add" and not uses.get(id(x)):
                adds.setdefault(id(target), []).append((x, times))
            else:
                others.setdefault(id(target), []).append(o)
        inner = times
        if x.op is Op.RANGE_FOR and all(o.op is Op.CONST for o in x.operands[:2]):
            inner = times * max(0, x.operands[1].attrs["value"] - x.operands[0].attrs["value"])
        for b in x.blocks:
            _updates(b, uses, inner, adds, others)


def _offset_form(s: Stmt) -> tuple:
    """(base statement or None, constant) with s == base + constant, looking through +/- constants."""
    c = 0
    while True:
        if s.op is Op.CONST:
            return None, c + s.attrs["value"]
        if s.op in (Op.ADD, Op.SUB) and s.operands[1].op is Op.CONST:
            c += s.operands[1].attrs["value"] * (1 if s.op is Op.ADD else -1)
            s = s.operands[0]
        elif s.op is Op.ADD and s.operands[0].op is Op.CONST:
            c += s.operands[0].attrs["value"]
            s = s.operands[1]
        else:
            return s, c


def _other_slice(a: Stmt, b: Stmt, nprefix: int) -> bool:
    """True when two accesses of one field provably differ in one of its first `nprefix` indices
    (`p[t + 1, ...]` against `p[t, ...]`), so they never touch the same element."""
    for x, y in zip(a.operands[:nprefix], b.operands[:nprefix]):
        (bx, cx), (by, cy) = _offset_form(x), _offset_form(y)
        if bx is by and cx != cy:
            return True
    return False


def private_regions(loop: Stmt, inside: set, uses: dict, shared: set, reduced: set,
                    debug: bool) -> tuple[list[Region], int]:
    """Regions worth privatising in a parallel loop and the estimated updates per iteration into them.

    A field the loop also reads or stores qualifies only where those accesses provably hit another
    slice. `shared`: ids of targets some iteration updates at elements it does not own (the others need no
    atomics anyway); `reduced`: ids of targets the loop already sums per thread at fixed indices. A copy
    may span bytes of fields that are not privatised (interleaved layouts): they stay zero in it, and
    the final sum leaves an element alone where the copy holds zero. In debug mode slices are off (an
    out-of-bounds slice index must be reported, not summed into)."""
    adds: dict[int, list] = {}
    others: dict[int, list] = {}
    _updates(loop.blocks[0], uses, 1, adds, others)
    groups: dict[tuple, Region] = {}
    weight = 0
    for tid, updates in adds.items():
        f = updates[0][0].operands[0].attrs["target"]
        if tid not in shared or tid in reduced or not isinstance(f, ScalarField) \
                or f.layout is None or f.dtype.name not in ("f32", "f64", "i32", "i64"):
            continue
        ptrs = [a.operands[0] for a, _times in updates]
        if any(id(p) not in inside for p in ptrs):
            continue  # an address computed before the loop would still point into the field itself
        nprefix = 0 if debug else _prefix_len(f, ptrs, loop, inside)
        if any(not _other_slice(o, p, nprefix) for o in others.get(tid, ()) for p in ptrs):
            continue  # the loop reads (or stores) what it would add into a copy of
        strides = {t.axis: t.stride for t in f.layout[2]}
        lo, hi = _span(f, nprefix)
        for a, times in updates:
            ptr = a.operands[0]
            key = access_key(ptr, nprefix)
            prefix = tuple((ptr.operands[k], strides[k]) for k in range(nprefix))
            gkey = (f.layout[0], f.dtype.name, key, tuple(st for _o, st in prefix))
            r = groups.get(gkey)
            if r is None:
                r = groups[gkey] = Region(f.layout[0], lo, hi, f.dtype, prefix)
            r.lo, r.hi = min(r.lo, lo), max(r.hi, hi)
            r.keys.add((tid, key))
            weight += times
    return list(groups.values()), weight


def slice_shift(lines: list, tmp, value, region: Region) -> str:
    """Append to `lines` the computation of a region's slice base (bytes, i64); returns its name.
    `value(stmt)` names an index value in the function at hand, `tmp()` makes a fresh name."""
    total = "0"
    for stmt, stride in region.prefix:
        v = value(stmt)
        if stmt.type.llvm != "i64":
            w = tmp()
            lines.append(f"{w} = sext {stmt.type.llvm} {v} to i64")
            v = w
        m, a = tmp(), tmp()
        lines.append(f"{m} = mul i64 {v}, {stride}")
        lines.append(f"{a} = add i64 {total}, {m}")
        total = a
    return total


def emit_private_launch(f, regions: list[Region], weight: int, clo: str, first_slot: int, task: str,
                        private_task: str, pfor: str, nthreads: str, begin: str, end: str, grain: int) -> None:
    """Caller side: run `private_task` over per-thread zeroed copies of the regions and add them into the
    fields when the loop's updates cost more as atomics than the copies cost to zero and sum (see
    ATOMIC_COST); else run the atomic `task`."""
    elems = sum(r.count for r in regions)
    iters, work, need, big, multi, ok = (f.tmp("pv") for _ in range(6))
    f.emit(f"{iters} = sub i64 {end}, {begin}")
    f.emit(f"{work} = mul i64 {iters}, {weight * ATOMIC_COST}")
    f.emit(f"{need} = mul i64 {nthreads}, {elems}")
    f.emit(f"{big} = icmp sge i64 {work}, {need}")
    f.emit(f"{multi} = icmp sgt i64 {nthreads}, 1")
    nbytes, fits, worth = f.tmp("pv"), f.tmp("pv"), f.tmp("pv")
    f.emit(f"{nbytes} = mul i64 {nthreads}, {sum(r.hi - r.lo for r in regions)}")
    f.emit(f"{fits} = icmp ule i64 {nbytes}, {MAX_COPY_BYTES}")
    f.emit(f"{worth} = and i1 {big}, {multi}")
    f.emit(f"{ok} = and i1 {worth}, {fits}")
    plain, alloc, run, done = f.label("atomic"), f.label("alloc"), f.label("private"), f.label("scatterdone")
    f.emit(f"br i1 {ok}, label %{alloc}, label %{plain}")
    f.start_block(alloc)
    f.gen.module.declare("declare noalias ptr @calloc(i64, i64)")
    f.gen.module.declare("declare void @free(ptr)")
    bufs = []
    got = "true"
    for k, r in enumerate(regions):
        buf, slot, nonnull, all_ok = f.tmp("priv"), f.tmp("pslot"), f.tmp("pnn"), f.tmp("pok")
        f.emit(f"{buf} = call ptr @calloc(i64 {nthreads}, i64 {r.hi - r.lo})")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {first_slot + k}")
        f.emit(f"store ptr {buf}, ptr {slot}")
        f.emit(f"{nonnull} = icmp ne ptr {buf}, null")
        f.emit(f"{all_ok} = and i1 {got}, {nonnull}")
        got = all_ok
        bufs.append(buf)
    nomem = f.label("nomem")
    f.emit(f"br i1 {got}, label %{run}, label %{nomem}")
    f.start_block(nomem)  # out of memory: the atomic task needs none
    for buf in bufs:
        f.emit(f"call void @free(ptr {buf})")
    f.emit(f"br label %{plain}")
    f.start_block(run)
    f.emit(f"call void {pfor}(ptr @{private_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    for k, (r, buf) in enumerate(zip(regions, bufs)):
        _emit_sum_into(f, r, buf, nthreads, pfor, f"{private_task}_sum{k}")
        f.emit(f"call void @free(ptr {buf})")
    f.emit(f"br label %{done}")
    f.start_block(plain)
    f.emit(f"call void {pfor}(ptr @{task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    f.emit(f"br label %{done}")
    f.start_block(done)


def _emit_sum_into(f, r: Region, buf: str, nthreads: str, pfor: str, name: str) -> None:
    """Add every thread's copy into the field, split across the pool by element ranges (task `name`)."""
    lines: list[str] = []
    shift = slice_shift(lines, lambda: f.tmp("sh"), f.v, r)
    for line in lines:
        f.emit(line)
    real, at, clo = f.tmp("real"), f.tmp("real"), f.tmp("sclo")
    f.emit(f"{at} = getelementptr i8, ptr {f.root(r.tree_id)}, i64 {shift}")
    f.emit(f"{real} = getelementptr i8, ptr {at}, i64 {r.lo}")
    f.prologue.append(f"  {clo} = alloca [3 x i64], align 8")
    for k, (ty, v) in enumerate((("ptr", buf), ("ptr", real), ("i64", nthreads))):
        slot = f.tmp("sslot")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {k}")
        f.emit(f"store {ty} {v}, ptr {slot}")
    f.emit(f"call void {pfor}(ptr @{name}, ptr {clo}, i64 0, i64 {r.count}, i64 {SUM_GRAIN})")
    f.gen.module.functions.append(_sum_task(name, r.dtype, r.count))


SUM_GRAIN = 8192  # elements per chunk of the final sum


def _sum_task(name: str, dtype, n: int) -> str:
    """field[k] += copy_t[k] for k in [lo, hi) and every thread's copy t, in thread order. A zero partial
    leaves the element untouched: bytes of other fields in the copied range stay as they are, and an
    element no iteration updated keeps even the sign of a zero."""
    ty = dtype.llvm
    if dtype.is_float:
        combine = (f"  %added = fadd {ty} %old, %part\n  %zero = fcmp oeq {ty} %part, 0.0\n"
                   f"  %new = select i1 %zero, {ty} %old, {ty} %added")
    else:
        combine = f"  %new = add {ty} %old, %part"
    return f"""define internal void @{name}(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {{
entry:
  %buf = load ptr, ptr %clo
  %realp = getelementptr i64, ptr %clo, i64 1
  %real = load ptr, ptr %realp
  %ntp = getelementptr i64, ptr %clo, i64 2
  %nt = load i64, ptr %ntp
  br label %thead
thead:
  %t = phi i64 [0, %entry], [%tnext, %kdone]
  %tc = icmp slt i64 %t, %nt
  br i1 %tc, label %tbody, label %done
tbody:
  %base = mul i64 %t, {n}
  %copy = getelementptr inbounds {ty}, ptr %buf, i64 %base
  br label %khead
khead:
  %k = phi i64 [%lo, %tbody], [%knext, %kbody]
  %kc = icmp slt i64 %k, %hi
  br i1 %kc, label %kbody, label %kdone
kbody:
  %src = getelementptr inbounds {ty}, ptr %copy, i64 %k
  %dst = getelementptr inbounds {ty}, ptr %real, i64 %k
  %part = load {ty}, ptr %src
  %old = load {ty}, ptr %dst
{combine}
  store {ty} %new, ptr %dst
  %knext = add i64 %k, 1
  br label %khead
kdone:
  %tnext = add i64 %t, 1
  br label %thead
done:
  ret void
}}"""
