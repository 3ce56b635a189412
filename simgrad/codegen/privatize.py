"""Scatter privatisation, CPU side: the per-thread copies of the regions passes/privatize.py chose.

The generated entry decides at run time from the trip count whether the copies pay off
(`emit_private_launch`); otherwise the usual atomic task runs. Summing per-thread partials reorders float
additions, which atomics already leave unordered. An ndarray's region is sized at launch from its extents
(`region_bytes`): its copies grow when a larger array comes.
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


def region_bytes(lines: list, tmp, shape, r: Region) -> str:
    """The bytes of one copy of the region (i64; an ndarray's from the launch's extents, `shape(arg, dim)` naming
    one); appends the computation to `lines`."""
    if r.array is None:
        return str(r.hi - r.lo)
    total = str(r.array.num_components * r.dtype.nbytes)
    for k in range(r.array.ndim):
        m = tmp()
        lines.append(f"{m} = mul i64 {total}, {shape(r.array, k)}")
        total = m
    return total


def _bytes(f, r: Region) -> str:
    lines: list[str] = []
    n = region_bytes(lines, lambda: f.tmp("rb"), f.array_shape, r)
    for line in lines:
        f.emit(line)
    return n


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
                        private_task: str, pfor: str, nthreads: str, begin: str, end: str, grain: int,
                        alone_task: str) -> None:
    """Caller side: run `private_task` over per-thread zeroed copies of the regions and add them into the
    fields when the loop's updates cost more as atomics than the copies cost to zero and sum (see
    ATOMIC_COST); else run the atomic `task`. When the pool will run the whole loop on this thread (one
    thread, or no more iterations than a grain: simgrad_parallel_for's serial path; launches never overlap),
    `alone_task` (the private task, or its variant whose other updates are plain too) runs with the fields
    themselves as thread 0's copies: plain updates, nothing to sum."""
    sizes = [_bytes(f, r) for r in regions]  # one copy of each region, in bytes
    work, need, big, ok = (f.tmp("pv") for _ in range(4))
    iters, alone = emit_runs_alone(f, nthreads, begin, end, grain)
    direct, decide = f.label("direct"), f.label("decide")
    f.emit(f"br i1 {alone}, label %{direct}, label %{decide}")
    f.start_block(direct)
    for k, r in enumerate(regions):
        slot = f.tmp("pslot")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {first_slot + k}")
        f.emit(f"store ptr {_field_slice(f, r)}, ptr {slot}")
    f.emit(f"call void {pfor}(ptr @{alone_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    done = f.label("scatterdone")
    f.emit(f"br label %{done}")
    f.start_block(decide)
    elems = _sum_of(f, [_elements(f, r, n) for r, n in zip(regions, sizes)])
    f.emit(f"{work} = mul i64 {iters}, {weight * ATOMIC_COST}")
    f.emit(f"{need} = mul i64 {nthreads}, {elems}")
    f.emit(f"{big} = icmp sge i64 {work}, {need}")  # (several threads here: one took the direct path)
    nbytes, fits = f.tmp("pv"), f.tmp("pv")
    f.emit(f"{nbytes} = mul i64 {nthreads}, {_sum_of(f, sizes)}")
    f.emit(f"{fits} = icmp ule i64 {nbytes}, {MAX_COPY_BYTES}")
    f.emit(f"{ok} = and i1 {big}, {fits}")
    for r, n in zip(regions, sizes):
        if r.array is not None:  # an empty ndarray: no copy to make (the loop cannot update it)
            some, both = f.tmp("pv"), f.tmp("pv")
            f.emit(f"{some} = icmp sgt i64 {n}, 0")
            f.emit(f"{both} = and i1 {ok}, {some}")
            ok = both
    plain, alloc, run = f.label("atomic"), f.label("alloc"), f.label("private")
    f.emit(f"br i1 {ok}, label %{alloc}, label %{plain}")
    f.start_block(alloc)
    bufs = []
    got = "true"
    for k, n in enumerate(sizes):
        buf, slot, nonnull, all_ok = _copies(f, nthreads, n), f.tmp("pslot"), f.tmp("pnn"), f.tmp("pok")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {first_slot + k}")
        f.emit(f"store ptr {buf}, ptr {slot}")
        f.emit(f"{nonnull} = icmp ne ptr {buf}, null")
        f.emit(f"{all_ok} = and i1 {got}, {nonnull}")
        got = all_ok
        bufs.append(buf)
    f.emit(f"br i1 {got}, label %{run}, label %{plain}")  # out of memory: the atomic task needs none
    f.start_block(run)
    f.emit(f"call void {pfor}(ptr @{private_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    for k, (r, buf, n) in enumerate(zip(regions, bufs, sizes)):
        _emit_sum_into(f, r, buf, n, nthreads, pfor, f"{private_task}_sum{k}")
    f.emit(f"br label %{done}")
    f.start_block(plain)
    f.emit(f"call void {pfor}(ptr @{task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    f.emit(f"br label %{done}")
    f.start_block(done)


def _elements(f, r: Region, nbytes: str) -> str:
    """The elements of one copy of the region (i64)."""
    if r.array is None:
        return str(r.count)
    n = f.tmp("pv")
    f.emit(f"{n} = udiv exact i64 {nbytes}, {r.dtype.nbytes}")
    return n


def _sum_of(f, terms: list[str]) -> str:
    """The i64 sum of `terms` (constants folded)."""
    const = sum(int(t) for t in terms if not t.startswith("%"))
    total = str(const)
    for t in terms:
        if t.startswith("%"):
            nxt = f.tmp("pv")
            f.emit(f"{nxt} = add i64 {total}, {t}")
            total = nxt
    return total


def _copies(f, nthreads: str, nbytes: str) -> str:
    """Every thread's zeroed copy of `nbytes` bytes (null when out of memory). The copies persist between launches
    in a holder the launcher owns ({pointer, capacity in bytes}; its context slot holds the holder's address, so a
    copied context, lang/graph.py's replay, shares them): allocated zeroed on first use, zeroed again as the final
    sum reads them, so a launch neither allocates nor clears (that was a serial memset of every thread's copy per
    launch). A larger ndarray than the holder's capacity replaces them (calloc: still zero). The launcher frees
    them (runtime/launch.py)."""
    f.gen.module.declare("declare noalias ptr @calloc(i64, i64)")
    f.gen.module.declare("declare void @free(ptr)")
    hslot, holder, have, capp, cap, need, enough = (f.tmp("ph") for _ in range(7))
    f.emit(f"{hslot} = getelementptr i64, ptr %ctx, i64 {f.gen.private_slot()}")
    f.emit(f"{holder} = load ptr, ptr {hslot}")
    f.emit(f"{have} = load ptr, ptr {holder}")
    f.emit(f"{capp} = getelementptr i64, ptr {holder}, i64 1")
    f.emit(f"{cap} = load i64, ptr {capp}")
    f.emit(f"{need} = mul i64 {nthreads}, {nbytes}")
    f.emit(f"{enough} = icmp uge i64 {cap}, {need}")
    fresh, ready = f.label("pfresh"), f.label("pready")
    f.emit(f"br i1 {enough}, label %{ready}, label %{fresh}")
    f.start_block(fresh)
    new, isnull, newcap = f.tmp("pnew"), f.tmp("pnull"), f.tmp("pcap")
    f.emit(f"call void @free(ptr {have})")
    f.emit(f"{new} = call ptr @calloc(i64 {nthreads}, i64 {nbytes})")
    f.emit(f"store ptr {new}, ptr {holder}")
    f.emit(f"{isnull} = icmp eq ptr {new}, null")
    f.emit(f"{newcap} = select i1 {isnull}, i64 0, i64 {need}")
    f.emit(f"store i64 {newcap}, ptr {capp}")
    f.emit(f"br label %{ready}")
    f.start_block(ready)
    buf = f.tmp("priv")
    f.emit(f"{buf} = load ptr, ptr {holder}")
    return buf


def _field_slice(f, r: Region) -> str:
    """The address of the region's bytes in the field itself (the slice its prefix indices pick), or the
    ndarray's data."""
    if r.array is not None:
        return f.array_base(r.array)
    lines: list[str] = []
    shift = slice_shift(lines, lambda: f.tmp("sh"), f.v, r)
    for line in lines:
        f.emit(line)
    real, at = f.tmp("real"), f.tmp("real")
    f.emit(f"{at} = getelementptr i8, ptr {f.root(r.tree_id)}, i64 {shift}")
    f.emit(f"{real} = getelementptr i8, ptr {at}, i64 {r.lo}")
    return real


def _emit_sum_into(f, r: Region, buf: str, nbytes: str, nthreads: str, pfor: str, name: str) -> None:
    """Add every thread's copy into the field, split across the pool by element ranges (task `name`)."""
    real, clo = _field_slice(f, r), f.tmp("sclo")
    count = _elements(f, r, nbytes)
    f.prologue.append(f"  {clo} = alloca [4 x i64], align 8")
    for k, (ty, v) in enumerate((("ptr", buf), ("ptr", real), ("i64", nthreads), ("i64", count))):
        slot = f.tmp("sslot")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {k}")
        f.emit(f"store {ty} {v}, ptr {slot}")
    f.emit(f"call void {pfor}(ptr @{name}, ptr {clo}, i64 0, i64 {count}, i64 {SUM_GRAIN})")
    # After Ctrl-C the pool hands out no more chunks: the sum runs here whole (the copies persist, so partials left
    # in them would go into the next launch's results). A part the pool did sum left zeros: summing it again is
    # a no-op.
    stopped = f.cancelled()
    here, on = f.label("psumhere"), f.label("psumdone")
    f.emit(f"br i1 {stopped}, label %{here}, label %{on}")
    f.start_block(here)
    f.emit(f"call void @{name}(ptr {clo}, i64 0, i64 {count}, i32 0)")
    f.emit(f"br label %{on}")
    f.start_block(on)
    f.gen.module.functions.append(_sum_task(name, r.dtype, None if r.array is not None else r.count))


SUM_GRAIN = 8192  # elements per chunk of the final sum


def _sum_task(name: str, dtype, n: int | None) -> str:
    """field[k] += copy_t[k] for k in [lo, hi) and every thread's copy t, in thread order, leaving the copy
    zero for the next launch. A zero partial leaves the element untouched: bytes of other fields in the
    copied range stay as they are, and an element no iteration updated keeps even the sign of a zero.
    `n`: the elements of one copy, None when the closure's fourth word holds it (an ndarray's)."""
    ty = dtype.llvm
    count = str(n) if n is not None else "%n"
    load_n = "" if n is not None else "  %np = getelementptr i64, ptr %clo, i64 3\n  %n = load i64, ptr %np\n"
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
{load_n}  br label %thead
thead:
  %t = phi i64 [0, %entry], [%tnext, %kdone]
  %tc = icmp slt i64 %t, %nt
  br i1 %tc, label %tbody, label %done
tbody:
  %base = mul i64 %t, {count}
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
