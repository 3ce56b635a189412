"""Scatter privatisation, CPU side: the per-thread copies of the regions passes/privatize.py chose.

The generated entry decides at run time from the trip count whether the copies pay off
(`emit_private_launch`); otherwise the usual atomic task runs. Summing per-thread partials reorders float
additions, which atomics already leave unordered.
"""

from __future__ import annotations

from simgrad.passes.privatize import Region

# One contended-or-not lock-prefixed update costs about as much as zeroing and summing this many elements
# of a copy (vectorised, mostly in cache): measured on the 3-D MPM p2g (110k cells, 4.5k particles).
ATOMIC_COST = 8
MAX_COPY_BYTES = 1 << 28  # all threads' copies together; a larger scatter keeps its atomics


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


def emit_runs_alone(f, nthreads: str, begin: str, end: str, grain: int) -> tuple[str, str]:
    """(iterations, i1 whether the pool runs the loop on the calling thread alone): one pool thread, or at most
    a grain of iterations, simgrad_parallel_for's serial path (launches never overlap). Its tasks may then
    update without atomics."""
    iters, one, small, alone = (f.tmp("pv") for _ in range(4))
    f.emit(f"{iters} = sub i64 {end}, {begin}")
    f.emit(f"{one} = icmp sle i64 {nthreads}, 1")
    f.emit(f"{small} = icmp sle i64 {iters}, {grain}")
    f.emit(f"{alone} = or i1 {one}, {small}")
    return iters, alone


def emit_private_launch(f, regions: list[Region], weight: int, clo: str, first_slot: int, task: str,
                        private_task: str, pfor: str, nthreads: str, begin: str, end: str, grain: int) -> None:
    """Caller side: run `private_task` over per-thread zeroed copies of the regions and add them into the
    fields when the loop's updates cost more as atomics than the copies cost to zero and sum (see
    ATOMIC_COST); else run the atomic `task`. When the pool will run the whole loop on this thread (one
    thread, or no more iterations than a grain: simgrad_parallel_for's serial path; launches never overlap),
    `private_task` runs with the fields themselves as thread 0's copies: plain updates, nothing to sum."""
    elems = sum(r.count for r in regions)
    work, need, big, ok = (f.tmp("pv") for _ in range(4))
    iters, alone = emit_runs_alone(f, nthreads, begin, end, grain)
    direct, decide = f.label("direct"), f.label("decide")
    f.emit(f"br i1 {alone}, label %{direct}, label %{decide}")
    f.start_block(direct)
    for k, r in enumerate(regions):
        slot = f.tmp("pslot")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {first_slot + k}")
        f.emit(f"store ptr {_field_slice(f, r)}, ptr {slot}")
    f.emit(f"call void {pfor}(ptr @{private_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    done = f.label("scatterdone")
    f.emit(f"br label %{done}")
    f.start_block(decide)
    f.emit(f"{work} = mul i64 {iters}, {weight * ATOMIC_COST}")
    f.emit(f"{need} = mul i64 {nthreads}, {elems}")
    f.emit(f"{big} = icmp sge i64 {work}, {need}")  # (several threads here: one took the direct path)
    nbytes, fits = f.tmp("pv"), f.tmp("pv")
    f.emit(f"{nbytes} = mul i64 {nthreads}, {sum(r.hi - r.lo for r in regions)}")
    f.emit(f"{fits} = icmp ule i64 {nbytes}, {MAX_COPY_BYTES}")
    f.emit(f"{ok} = and i1 {big}, {fits}")
    plain, alloc, run = f.label("atomic"), f.label("alloc"), f.label("private")
    f.emit(f"br i1 {ok}, label %{alloc}, label %{plain}")
    f.start_block(alloc)
    f.gen.module.declare("declare noalias ptr @calloc(i64, i64)")
    # The copies persist in context slots between launches: allocated zeroed on first use, zeroed again as
    # the final sum reads them, so a launch neither allocates nor clears (that was a serial memset of every
    # thread's copy per launch). The launcher frees them (runtime/launch.py).
    bufs = []
    got = "true"
    for k, r in enumerate(regions):
        ctx_slot = f.tmp("pctx")
        f.emit(f"{ctx_slot} = getelementptr i64, ptr %ctx, i64 {f.gen.private_slot()}")
        have, fresh, ready = f.tmp("phave"), f.label("pfresh"), f.label("pready")
        f.emit(f"{have} = load ptr, ptr {ctx_slot}")
        isnull = f.tmp("pnull")
        f.emit(f"{isnull} = icmp eq ptr {have}, null")
        f.emit(f"br i1 {isnull}, label %{fresh}, label %{ready}")
        f.start_block(fresh)
        new = f.tmp("pnew")
        f.emit(f"{new} = call ptr @calloc(i64 {nthreads}, i64 {r.hi - r.lo})")
        f.emit(f"store ptr {new}, ptr {ctx_slot}")
        f.emit(f"br label %{ready}")
        f.start_block(ready)
        buf, slot, nonnull, all_ok = f.tmp("priv"), f.tmp("pslot"), f.tmp("pnn"), f.tmp("pok")
        f.emit(f"{buf} = load ptr, ptr {ctx_slot}")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {first_slot + k}")
        f.emit(f"store ptr {buf}, ptr {slot}")
        f.emit(f"{nonnull} = icmp ne ptr {buf}, null")
        f.emit(f"{all_ok} = and i1 {got}, {nonnull}")
        got = all_ok
        bufs.append(buf)
    f.emit(f"br i1 {got}, label %{run}, label %{plain}")  # out of memory: the atomic task needs none
    f.start_block(run)
    f.emit(f"call void {pfor}(ptr @{private_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    for k, (r, buf) in enumerate(zip(regions, bufs)):
        _emit_sum_into(f, r, buf, nthreads, pfor, f"{private_task}_sum{k}")
    f.emit(f"br label %{done}")
    f.start_block(plain)
    f.emit(f"call void {pfor}(ptr @{task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    f.emit(f"br label %{done}")
    f.start_block(done)


def _field_slice(f, r: Region) -> str:
    """The address of the region's bytes in the field itself (the slice its prefix indices pick)."""
    lines: list[str] = []
    shift = slice_shift(lines, lambda: f.tmp("sh"), f.v, r)
    for line in lines:
        f.emit(line)
    real, at = f.tmp("real"), f.tmp("real")
    f.emit(f"{at} = getelementptr i8, ptr {f.root(r.tree_id)}, i64 {shift}")
    f.emit(f"{real} = getelementptr i8, ptr {at}, i64 {r.lo}")
    return real


def _emit_sum_into(f, r: Region, buf: str, nthreads: str, pfor: str, name: str) -> None:
    """Add every thread's copy into the field, split across the pool by element ranges (task `name`)."""
    real, clo = _field_slice(f, r), f.tmp("sclo")
    f.prologue.append(f"  {clo} = alloca [3 x i64], align 8")
    for k, (ty, v) in enumerate((("ptr", buf), ("ptr", real), ("i64", nthreads))):
        slot = f.tmp("sslot")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {k}")
        f.emit(f"store {ty} {v}, ptr {slot}")
    f.emit(f"call void {pfor}(ptr @{name}, ptr {clo}, i64 0, i64 {r.count}, i64 {SUM_GRAIN})")
    f.gen.module.functions.append(_sum_task(name, r.dtype, r.count))


SUM_GRAIN = 8192  # elements per chunk of the final sum


def _sum_task(name: str, dtype, n: int) -> str:
    """field[k] += copy_t[k] for k in [lo, hi) and every thread's copy t, in thread order, leaving the copy
    zero for the next launch. A zero partial leaves the element untouched: bytes of other fields in the
    copied range stay as they are, and an element no iteration updated keeps even the sign of a zero."""
    ty = dtype.llvm
    if dtype.is_float:
        combine = (f"  %added = fadd {ty} %old, %part\n  %zero = fcmp oeq {ty} %part, 0.0\n"
                   f"  %new = select i1 %zero, {ty} %old, {ty} %added\n  store {ty} 0.0, ptr %src")
    else:
        combine = f"  %new = add {ty} %old, %part\n  store {ty} 0, ptr %src"
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
