"""Scatter privatisation, CPU side: the per-thread copies of the regions passes/privatize.py chose.

The generated entry decides at run time from the trip count whether the copies pay off
(`emit_private_launch`); otherwise the usual atomic task runs. Summing per-thread partials reorders float
additions, which atomics already leave unordered. An ndarray's region is sized at launch from its extents
(`region_bytes`): its copies grow when a larger array comes.

Each thread also marks the pages (PAGE_SHIFT) of its copy it updates, in a byte map per thread (a buffer of its
own, see copy_layout), and the final sum visits only marked pages: a particle scatter touches a small part of its grid
(diffmpm3d's p2g: the copy of a 14.7 MB grid region cost more to sum than the loop took).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from simgrad.passes.privatize import PAGE_SHIFT, Region

# One contended-or-not lock-prefixed update costs about as much as zeroing and summing this many elements
# of a copy (vectorised, mostly in cache): measured on the 3-D MPM p2g (110k cells, 4.5k particles).
ATOMIC_COST = 8
MAX_COPY_BYTES = 1 << 28  # all threads' copies together; a larger scatter keeps its atomics
# Before a sum has counted the marked pages, a loop is taken to touch at most this share of its copies' pages
# (diffmpm3d's robot, an MPM blob: ~1/10 of the grid); afterwards the last count decides, decaying by 1/64 a
# launch that keeps its atomics, so a scatter that spread out and came back gets its copies again.
FIRST_GUESS_SHARE = 8


LINE = 64  # each thread's copy and map start on a cache line of their own: no false sharing between threads


def line_padded(lines: list, tmp, n: str) -> str:
    """`n` (i64 bytes, constant folded) rounded up to whole cache lines: the distance between two threads'
    copies (or maps). A 124-byte copy of actuation.grad shared a line with the next thread's: diffmpm3d's
    p2g.grad took 6.1 ms a launch instead of 2.9 when calloc placed them so."""
    if not n.startswith("%"):
        return str(-(-int(n) // LINE) * LINE)
    up, r = tmp(), tmp()
    lines.append(f"{up} = add i64 {n}, {LINE - 1}")
    lines.append(f"{r} = and i64 {up}, {-LINE}")
    return r


def region_pages(lines: list, tmp, nbytes: str) -> str:
    """The pages of one copy of `nbytes` bytes (i64; constant folded); appends the computation to `lines`."""
    if not nbytes.startswith("%"):
        return str((int(nbytes) + (1 << PAGE_SHIFT) - 1) >> PAGE_SHIFT)
    up, n = tmp(), tmp()
    lines.append(f"{up} = add i64 {nbytes}, {(1 << PAGE_SHIFT) - 1}")
    lines.append(f"{n} = lshr i64 {up}, {PAGE_SHIFT}")
    return n


def copy_layout(lines: list, tmp, shape, r: Region) -> tuple[str, str, str, str]:
    """(bytes of one copy of the region, its pages, bytes from one thread's copy to the next, bytes from one
    thread's page map to the next), i64 values appended to `lines`: the one layout both the launch (which
    allocates and sums) and the task (which adds and marks) compute."""
    size = region_bytes(lines, tmp, shape, r)
    pages = region_pages(lines, tmp, size)
    return size, pages, line_padded(lines, tmp, size), line_padded(lines, tmp, pages)


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


def _emitted(f, build, *args) -> Any:
    """`build(lines, tmp, *args)`'s value, its lines emitted into `f` (the builders above serve the task's prologue
    too)."""
    lines: list[str] = []
    v = build(lines, lambda: f.tmp("pv"), *args)
    for line in lines:
        f.emit(line)
    return v


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
    """Caller side: run `private_task` over per-thread zeroed copies of the regions and add their marked pages
    into the fields when the loop's updates cost more as atomics than the copies cost to zero and sum (see
    ATOMIC_COST); else run the atomic `task`. When the pool will run the whole loop on this thread (one
    thread, or no more iterations than a grain: simgrad_parallel_for's serial path; launches never overlap),
    `alone_task` (the private task's variant without page marks, whose other updates are plain too) runs with the
    fields themselves as thread 0's copies: nothing to sum.
    Closure slots `first_slot + k` hold region k's copies, `first_slot + len(regions) + k` its page maps."""
    sizes, pages, strides, map_strides = zip(*(_emitted(f, copy_layout, f.array_shape, r) for r in regions))
    work, big, ok = (f.tmp("pv") for _ in range(3))
    iters, alone = emit_runs_alone(f, nthreads, begin, end, grain)
    direct, decide, plain = f.label("direct"), f.label("decide"), f.label("atomic")
    f.emit(f"br i1 {alone}, label %{direct}, label %{decide}")
    holders = [(f.gen.private_slot(), f.gen.private_slot()) for _ in regions]  # (copies, page maps)
    nmaps = len(regions)
    f.start_block(direct)
    for k, r in enumerate(regions):
        f.emit(f"store ptr {_field_slice(f, r)}, ptr {_slot(f, clo, first_slot + k)}")
    f.emit(f"call void {pfor}(ptr @{alone_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    done = f.label("scatterdone")
    f.emit(f"br label %{done}")
    f.start_block(decide)
    counts = [_marked_count(f, mh) for _, mh in holders]
    need = _sum_of(f, [_sum_guess(f, r, pg, nthreads, c) for r, pg, c in zip(regions, pages, counts)])
    f.emit(f"{work} = mul i64 {iters}, {weight * ATOMIC_COST}")
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
    alloc = f.label("alloc")
    f.emit(f"br i1 {ok}, label %{alloc}, label %{plain}")
    f.start_block(alloc)
    got, bufs, maps = "true", [], []
    for k, (n, pg, (ch, mh)) in enumerate(zip(strides, map_strides, holders)):
        buf, got = _hold(f, clo, first_slot + k, ch, nthreads, n, got)
        m, got = _hold(f, clo, first_slot + nmaps + k, mh, nthreads, pg, got)
        bufs.append(buf)
        maps.append(m)
    run = f.label("private")
    f.emit(f"br i1 {got}, label %{run}, label %{plain}")
    f.start_block(run)
    f.emit(f"call void {pfor}(ptr @{private_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    for k, (r, buf, m, c) in enumerate(zip(regions, bufs, maps, counts)):
        _emit_sum_into(f, r, buf, m, (sizes[k], strides[k]), (pages[k], map_strides[k]), nthreads, c, pfor,
                       f"{private_task}_sum{k}")
    f.emit(f"br label %{done}")
    f.start_block(plain)
    for c in counts:  # the count decays while the atomics run (-1, no count yet, stays)
        old, less, new = f.tmp("pc"), f.tmp("pc"), f.tmp("pc")
        f.emit(f"{old} = load i64, ptr {c}")
        f.emit(f"{less} = sdiv i64 {old}, 64")  # (-1 stays)
        f.emit(f"{new} = sub i64 {old}, {less}")
        f.emit(f"store i64 {new}, ptr {c}")
    f.emit(f"call void {pfor}(ptr @{task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    f.emit(f"br label %{done}")
    f.start_block(done)


def _holder(f, holder_slot: int) -> str:
    """The address of the holder {pointer, capacity in bytes, pages counted} whose address context slot
    `holder_slot` holds (runtime/launch.py `_holders`)."""
    hslot, holder = f.tmp("ph"), f.tmp("ph")
    f.emit(f"{hslot} = getelementptr i64, ptr %ctx, i64 {holder_slot}")
    f.emit(f"{holder} = load ptr, ptr {hslot}")
    return holder


def _marked_count(f, holder_slot: int) -> str:
    """The address of a page-map holder's count of the pages its last sum found marked (-1: no sum yet)."""
    c = f.tmp("ph")
    f.emit(f"{c} = getelementptr i64, ptr {_holder(f, holder_slot)}, i64 2")
    return c


def _sum_guess(f, r: Region, pages: str, nthreads: str, count: str) -> str:
    """The elements the final sum of a region will add (i64): its last count of marked pages, or before one
    FIRST_GUESS_SHARE of every thread's pages."""
    per = (1 << PAGE_SHIFT) // r.dtype.nbytes
    c, known, last, all_pages, share, guess = (f.tmp("pg") for _ in range(6))
    f.emit(f"{c} = load i64, ptr {count}")
    f.emit(f"{known} = icmp sge i64 {c}, 0")
    f.emit(f"{all_pages} = mul i64 {nthreads}, {pages}")
    f.emit(f"{share} = udiv i64 {all_pages}, {FIRST_GUESS_SHARE}")
    f.emit(f"{last} = select i1 {known}, i64 {c}, i64 {share}")
    f.emit(f"{guess} = mul i64 {last}, {per}")
    return guess


def _slot(f, clo: str, k: int) -> str:
    """The address of closure slot `k`."""
    slot = f.tmp("pslot")
    f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {k}")
    return slot


def _hold(f, clo: str, slot: int, holder_slot: int, nthreads: str, nbytes: str, got: str) -> tuple[str, str]:
    """(the persistent buffer, i1 `got` and it is there), its address stored in closure slot `slot`."""
    buf, nonnull, both = _held(f, holder_slot, nthreads, nbytes), f.tmp("pnn"), f.tmp("pok")
    f.emit(f"store ptr {buf}, ptr {_slot(f, clo, slot)}")
    f.emit(f"{nonnull} = icmp ne ptr {buf}, null")
    f.emit(f"{both} = and i1 {got}, {nonnull}")
    return buf, both


def _elements(f, r: Region, nbytes: str) -> str:
    """The elements in `nbytes` of the region's type (i64)."""
    if not nbytes.startswith("%"):
        return str(int(nbytes) // r.dtype.nbytes)
    n = f.tmp("pv")
    f.emit(f"{n} = udiv exact i64 {nbytes}, {r.dtype.nbytes}")
    return n


def _sum_of(f, terms: Sequence[str]) -> str:
    """The i64 sum of `terms` (constants folded)."""
    const = sum(int(t) for t in terms if not t.startswith("%"))
    total = str(const)
    for t in terms:
        if t.startswith("%"):
            nxt = f.tmp("pv")
            f.emit(f"{nxt} = add i64 {total}, {t}")
            total = nxt
    return total


def _held(f, holder_slot: int, nthreads: str, nbytes: str) -> str:
    """Every thread's zeroed `nbytes` bytes (a copy, or a page map), null when out of memory. They persist
    between launches in a holder the launcher owns ({pointer, capacity in bytes}; context slot `holder_slot`
    holds the holder's address, so a copied context, lang/graph.py's replay, shares them): allocated zeroed on
    first use, zeroed again as the final sum reads them, so a launch neither allocates nor clears (that was a
    serial memset of every thread's copy per launch). A larger ndarray than the holder's capacity replaces them
    (calloc: still zero). The launcher frees them (runtime/launch.py)."""
    f.gen.module.declare("declare noalias ptr @calloc(i64, i64)")
    f.gen.module.declare("declare void @free(ptr)")
    holder = _holder(f, holder_slot)
    have, capp, cap, need, enough = (f.tmp("ph") for _ in range(5))
    f.emit(f"{have} = load ptr, ptr {holder}")
    f.emit(f"{capp} = getelementptr i64, ptr {holder}, i64 1")
    f.emit(f"{cap} = load i64, ptr {capp}")
    f.emit(f"{need} = mul i64 {nthreads}, {nbytes}")
    f.emit(f"{enough} = icmp uge i64 {cap}, {need}")  # (allocated with a line more, to start on a line)
    fresh, ready = f.label("pfresh"), f.label("pready")
    f.emit(f"br i1 {enough}, label %{ready}, label %{fresh}")
    f.start_block(fresh)
    new, isnull, newcap, more = f.tmp("pnew"), f.tmp("pnull"), f.tmp("pcap"), f.tmp("pmore")
    f.emit(f"call void @free(ptr {have})")
    f.emit(f"{more} = add i64 {need}, {LINE}")
    f.emit(f"{new} = call ptr @calloc(i64 1, i64 {more})")
    f.emit(f"store ptr {new}, ptr {holder}")
    f.emit(f"{isnull} = icmp eq ptr {new}, null")
    f.emit(f"{newcap} = select i1 {isnull}, i64 0, i64 {need}")
    f.emit(f"store i64 {newcap}, ptr {capp}")
    f.emit(f"br label %{ready}")
    f.start_block(ready)
    raw, addr, up, line, buf = (f.tmp("priv") for _ in range(5))
    f.emit(f"{raw} = load ptr, ptr {holder}")
    f.emit(f"{addr} = ptrtoint ptr {raw} to i64")
    f.emit(f"{up} = add i64 {addr}, {LINE - 1}")
    f.emit(f"{line} = and i64 {up}, {-LINE}")
    f.emit(f"{buf} = inttoptr i64 {line} to ptr")  # (null stays null)
    return buf


def _field_slice(f, r: Region) -> str:
    """The address of the region's bytes in the field itself (the slice its prefix indices pick), or the
    ndarray's data."""
    if r.array is not None:
        return f.array_base(r.array)
    shift = _emitted(f, slice_shift, f.v, r)
    real, at = f.tmp("real"), f.tmp("real")
    f.emit(f"{at} = getelementptr i8, ptr {f.root(r.tree_id)}, i64 {shift}")
    f.emit(f"{real} = getelementptr i8, ptr {at}, i64 {r.lo}")
    return real


def _emit_sum_into(f, r: Region, buf: str, maps: str, copy: tuple[str, str], map_: tuple[str, str], nthreads: str,
                   marked: str, pfor: str, name: str) -> None:
    """Add every thread's copy into the field where its page map marks a page, split across the pool by page
    ranges (task `name`), counting the marked pages into the i64 at `marked`. `copy`: (bytes of a copy, bytes
    between two threads' copies); `map_`: (pages, bytes between two threads' maps)."""
    real, clo = _field_slice(f, r), f.tmp("sclo")
    count, stride = _elements(f, r, copy[0]), _elements(f, r, copy[1])
    pages = map_[0]
    f.emit(f"store i64 0, ptr {marked}")
    words = (("ptr", buf), ("ptr", real), ("i64", nthreads), ("i64", count), ("ptr", maps), ("i64", map_[1]),
             ("ptr", marked), ("i64", stride))
    f.prologue.append(f"  {clo} = alloca [{len(words)} x i64], align 8")
    for k, (ty, v) in enumerate(words):
        f.emit(f"store {ty} {v}, ptr {_slot(f, clo, k)}")
    f.emit(f"call void {pfor}(ptr @{name}, ptr {clo}, i64 0, i64 {pages}, i64 {SUM_GRAIN})")
    # After Ctrl-C the pool hands out no more chunks: the sum runs here whole (the copies persist, so partials left
    # in them would go into the next launch's results). A page the pool did sum is no longer marked.
    stopped = f.cancelled()
    here, on = f.label("psumhere"), f.label("psumdone")
    f.emit(f"br i1 {stopped}, label %{here}, label %{on}")
    f.start_block(here)
    f.emit(f"call void @{name}(ptr {clo}, i64 0, i64 {pages}, i32 0)")
    f.emit(f"br label %{on}")
    f.start_block(on)
    f.gen.module.functions.append(_sum_task(name, r.dtype))


SUM_GRAIN = 8  # pages per chunk of the final sum


def _sum_task(name: str, dtype) -> str:
    """field[k] += copy_t[k] over the pages [lo, hi) for every thread t whose map marks the page, in thread
    order, leaving the copy zero and the mark cleared for the next launch, and adds how many it summed to the
    count. A zero partial leaves the element untouched: bytes of other fields in the copied range stay as they
    are, and an element no iteration updated keeps even the sign of a zero. The closure: copies, field,
    threads, elements of a copy, maps, bytes between two threads' maps, count, elements between two threads'
    copies."""
    ty = dtype.llvm
    per = (1 << PAGE_SHIFT) // dtype.nbytes
    if dtype.is_float:
        combine = (f"  %added = fadd {ty} %old, %part\n  %zero = fcmp oeq {ty} %part, 0.0\n"
                   f"  %new = select i1 %zero, {ty} %old, {ty} %added\n  store {ty} 0.0, ptr %src")
    else:
        combine = f"  %new = add {ty} %old, %part\n  store {ty} 0, ptr %src"
    words = "\n".join(f"  %w{k}p = getelementptr i64, ptr %clo, i64 {k}\n  %w{k} = load {t}, ptr %w{k}p"
                       for k, t in enumerate(("ptr", "ptr", "i64", "i64", "ptr", "i64", "ptr", "i64")))
    return f"""define internal void @{name}(ptr %clo, i64 %lo, i64 %hi, i32 %tid) {{
entry:
{words}
  br label %phead
phead:
  %p = phi i64 [%lo, %entry], [%pnext, %tdone]
  %seen = phi i64 [0, %entry], [%seen.t, %tdone]
  %pc = icmp slt i64 %p, %hi
  br i1 %pc, label %pbody, label %done
pbody:
  %k0 = mul i64 %p, {per}
  %kend = add i64 %k0, {per}
  %kfull = icmp slt i64 %kend, %w3
  %k1 = select i1 %kfull, i64 %kend, i64 %w3
  br label %thead
thead:
  %t = phi i64 [0, %pbody], [%tnext, %tnext.from]
  %seen.t = phi i64 [%seen, %pbody], [%seen.n, %tnext.from]
  %tc = icmp slt i64 %t, %w2
  br i1 %tc, label %tbody, label %tdone
tbody:
  %mrow = mul i64 %t, %w5
  %mat = add i64 %mrow, %p
  %mp = getelementptr inbounds i8, ptr %w4, i64 %mat
  %mark = load i8, ptr %mp
  %marked = icmp ne i8 %mark, 0
  br i1 %marked, label %tsum, label %tnext.from
tsum:
  store i8 0, ptr %mp
  %seen.s = add i64 %seen.t, 1
  %base = mul i64 %t, %w7
  %copy = getelementptr inbounds {ty}, ptr %w0, i64 %base
  br label %khead
khead:
  %k = phi i64 [%k0, %tsum], [%knext, %kbody]
  %kc = icmp slt i64 %k, %k1
  br i1 %kc, label %kbody, label %tnext.from
kbody:
  %src = getelementptr inbounds {ty}, ptr %copy, i64 %k
  %dst = getelementptr inbounds {ty}, ptr %w1, i64 %k
  %part = load {ty}, ptr %src
  %old = load {ty}, ptr %dst
{combine}
  store {ty} %new, ptr %dst
  %knext = add i64 %k, 1
  br label %khead
tnext.from:
  %seen.n = phi i64 [%seen.t, %tbody], [%seen.s, %khead]
  %tnext = add i64 %t, 1
  br label %thead
tdone:
  %pnext = add i64 %p, 1
  br label %phead
done:
  %old.seen = atomicrmw add ptr %w6, i64 %seen monotonic
  ret void
}}"""
