"""Scatter privatisation: which fields a parallel loop may accumulate into through per-thread copies.

A particle-to-grid scatter (`grid[base + offset] += w`) or the adjoint of a gather (`density.grad[i] += g`)
spends most of its time in lock-prefixed read-modify-writes. When a loop only *adds* into a field (never
reads it, never stores to it, never uses an atomic's old value), each thread can add into a private,
zeroed copy of the field's memory with plain instructions, and the copies are summed into the field once
after the loop. That pays off when the loop does many more updates than the field has elements, which
the generated code decides at run time from the trip count (`worth_it`); otherwise the usual atomic task
runs. Summing per-thread partials reorders float additions, which atomics already leave unordered.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simgrad.ir.nodes import Stmt
from simgrad.ir.ops import Op
from simgrad.lang.field import ScalarField


@dataclass
class Region:
    """A byte range of one SNode tree holding only privatised fields of one dtype."""

    tree_id: int
    lo: int  # first byte
    hi: int  # one past the last byte
    dtype: object
    targets: set = field(default_factory=set)  # id() of the ScalarFields in it

    @property
    def count(self) -> int:
        return (self.hi - self.lo) // self.dtype.nbytes


def _span(f: ScalarField) -> tuple[int, int]:
    """[first byte, one past the last byte] that a dense field's elements occupy in its tree."""
    _tree, const, terms, shape = f.layout
    top = const
    for t in terms:
        digit = (shape[t.axis] - 1) // t.divisor
        if t.modulus:
            digit = min(digit, t.modulus - 1)
        top += digit * t.stride
    return const, top + f.dtype.nbytes


def _tree_fields(f: ScalarField) -> list[ScalarField]:
    node = f.snode
    while node.parent is not None:
        node = node.parent
    return [n.field for n in node._walk() if n.kind == "place" and n.field.layout is not None]


def _updates(block, uses: dict, times: int, adds: dict, spoiled: set) -> None:
    """Per field target: the unused-result atomic adds of a block with how often each runs per iteration
    (serial loops of constant trip multiply), and the targets touched any other way."""
    for x in block.stmts:
        for k, o in enumerate(x.operands):
            if o.op is not Op.GLOBAL_PTR:
                continue
            target = o.attrs["target"]
            if x.op is Op.ATOMIC and k == 0 and x.attrs["kind"] == "add" and not uses.get(id(x)):
                adds.setdefault(id(target), []).append((x, times))
            else:
                spoiled.add(id(target))
        inner = times
        if x.op is Op.RANGE_FOR and all(o.op is Op.CONST for o in x.operands[:2]):
            inner = times * max(0, x.operands[1].attrs["value"] - x.operands[0].attrs["value"])
        for b in x.blocks:
            _updates(b, uses, inner, adds, spoiled)


def private_regions(loop: Stmt, uses: dict, shared: set, reduced: set) -> tuple[list[Region], int]:
    """Regions worth privatising in a parallel loop, and the estimated updates per iteration into them.

    `shared`: ids of targets some iteration updates at elements it does not own (the others need no
    atomics anyway); `reduced`: ids of targets the loop already sums per thread at fixed indices."""
    adds: dict[int, list] = {}
    spoiled: set[int] = set()
    _updates(loop.blocks[0], uses, 1, adds, spoiled)
    chosen = {t: a for t, a in adds.items() if t in shared and t not in spoiled and t not in reduced}
    by_tree: dict[int, list[ScalarField]] = {}
    for stmts in chosen.values():
        f = stmts[0][0].operands[0].attrs["target"]
        if isinstance(f, ScalarField) and f.layout is not None:
            by_tree.setdefault(f.layout[0], []).append(f)
    regions = []
    weight = 0
    for tree_id, fields in by_tree.items():
        dtypes = {f.dtype.name for f in fields}
        if len(dtypes) != 1 or fields[0].dtype.name not in ("f32", "f64", "i32", "i64"):
            continue
        lo = min(_span(f)[0] for f in fields)
        hi = max(_span(f)[1] for f in fields)
        mine = {id(f) for f in fields}
        if any(id(g) not in mine and _span(g)[0] < hi and lo < _span(g)[1] for g in _tree_fields(fields[0])):
            continue  # another field lives inside the range
        size = fields[0].dtype.nbytes
        if lo % size or hi % size:
            continue
        regions.append(Region(tree_id, lo, hi, fields[0].dtype, mine))
        weight += sum(times for f in fields for _a, times in chosen[id(f)])
    return regions, weight


def emit_private_launch(f, regions: list[Region], weight: int, clo: str, first_slot: int, task: str,
                        private_task: str, pfor: str, nthreads: str, begin: str, end: str, grain: int) -> None:
    """Caller side: run `private_task` over per-thread zeroed copies of the regions and add them into the
    fields when the loop's updates outnumber the copies' elements; else run the atomic `task`."""
    elems = sum(r.count for r in regions)
    iters, work, need, big, multi, ok = (f.tmp("pv") for _ in range(6))
    f.emit(f"{iters} = sub i64 {end}, {begin}")
    f.emit(f"{work} = mul i64 {iters}, {weight}")
    f.emit(f"{need} = mul i64 {nthreads}, {elems}")
    f.emit(f"{big} = icmp sge i64 {work}, {need}")
    f.emit(f"{multi} = icmp sgt i64 {nthreads}, 1")
    f.emit(f"{ok} = and i1 {big}, {multi}")
    plain, alloc, run, done = f.label("atomic"), f.label("alloc"), f.label("private"), f.label("scatterdone")
    f.emit(f"br i1 {ok}, label %{alloc}, label %{plain}")
    f.start_block(alloc)
    f.gen.module.declare("declare noalias ptr @calloc(i64, i64)")
    f.gen.module.declare("declare void @free(ptr)")
    bufs = []
    got = "true"
    for k, r in enumerate(regions):
        buf, slot, nonnull, both = f.tmp("priv"), f.tmp("pslot"), f.tmp("pnn"), f.tmp("pok")
        f.emit(f"{buf} = call ptr @calloc(i64 {nthreads}, i64 {r.hi - r.lo})")
        f.emit(f"{slot} = getelementptr i64, ptr {clo}, i64 {first_slot + k}")
        f.emit(f"store ptr {buf}, ptr {slot}")
        f.emit(f"{nonnull} = icmp ne ptr {buf}, null")
        f.emit(f"{both} = and i1 {got}, {nonnull}")
        got = both
        bufs.append(buf)
    nomem = f.label("nomem")
    f.emit(f"br i1 {got}, label %{run}, label %{nomem}")
    f.start_block(nomem)  # out of memory: the atomic task needs none
    for buf in bufs:
        f.emit(f"call void @free(ptr {buf})")
    f.emit(f"br label %{plain}")
    f.start_block(run)
    f.emit(f"call void {pfor}(ptr @{private_task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    for r, buf in zip(regions, bufs):
        _emit_sum_into(f, r, buf, nthreads)
        f.emit(f"call void @free(ptr {buf})")
    f.emit(f"br label %{done}")
    f.start_block(plain)
    f.emit(f"call void {pfor}(ptr @{task}, ptr {clo}, i64 {begin}, i64 {end}, i64 {grain})")
    f.emit(f"br label %{done}")
    f.start_block(done)


def _emit_sum_into(f, r: Region, buf: str, nthreads: str) -> None:
    """field[k] += copy_t[k] for every thread's copy t, in thread order; a zero partial leaves the element
    untouched (so an element no iteration updated keeps even the sign of a zero)."""
    ty = r.dtype.llvm
    n = r.count
    real = f.tmp("real")
    f.emit(f"{real} = getelementptr i8, ptr {f.root(r.tree_id)}, i64 {r.lo}")
    pre, thead, tbody, khead, kbody, kdone, tdone = (f.label(h) for h in
                                                     ("sum", "sumt", "sumtb", "sumk", "sumkb", "sumkd", "sumtd"))
    f.emit(f"br label %{pre}")
    f.start_block(pre)
    f.emit(f"br label %{thead}")
    f.start_block(thead)
    t, tnext, tc = f.tmp("st"), f.tmp("stn"), f.tmp("stc")
    f.emit(f"{t} = phi i64 [0, %{pre}], [{tnext}, %{kdone}]")
    f.emit(f"{tc} = icmp slt i64 {t}, {nthreads}")
    f.emit(f"br i1 {tc}, label %{tbody}, label %{tdone}")
    f.start_block(tbody)
    base, copy = f.tmp("sb"), f.tmp("scopy")
    f.emit(f"{base} = mul i64 {t}, {n}")
    f.emit(f"{copy} = getelementptr inbounds {ty}, ptr {buf}, i64 {base}")
    f.emit(f"br label %{khead}")
    f.start_block(khead)
    k, knext, kc = f.tmp("sk"), f.tmp("skn"), f.tmp("skc")
    f.emit(f"{k} = phi i64 [0, %{tbody}], [{knext}, %{kbody}]")
    f.emit(f"{kc} = icmp slt i64 {k}, {n}")
    f.emit(f"br i1 {kc}, label %{kbody}, label %{kdone}")
    f.start_block(kbody)
    src, dst, part, old, new = f.tmp("ss"), f.tmp("sd"), f.tmp("sp"), f.tmp("so"), f.tmp("sn")
    f.emit(f"{src} = getelementptr inbounds {ty}, ptr {copy}, i64 {k}")
    f.emit(f"{dst} = getelementptr inbounds {ty}, ptr {real}, i64 {k}")
    f.emit(f"{part} = load {ty}, ptr {src}")
    f.emit(f"{old} = load {ty}, ptr {dst}")
    if r.dtype.is_float:
        added, zero = f.tmp("sa"), f.tmp("sz")
        f.emit(f"{added} = fadd {ty} {old}, {part}")
        f.emit(f"{zero} = fcmp oeq {ty} {part}, 0.0")
        f.emit(f"{new} = select i1 {zero}, {ty} {old}, {ty} {added}")
    else:
        f.emit(f"{new} = add {ty} {old}, {part}")
    f.emit(f"store {ty} {new}, ptr {dst}")
    f.emit(f"{knext} = add i64 {k}, 1")
    f.emit(f"br label %{khead}")
    f.start_block(kdone)
    f.emit(f"{tnext} = add i64 {t}, 1")
    f.emit(f"br label %{thead}")
    f.start_block(tdone)
