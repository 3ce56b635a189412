"""Scatter privatisation analysis: which fields a parallel loop may accumulate into through per-thread
copies (the emission of the copies is the CPU target's, codegen/privatize.py).

A particle-to-grid scatter (`grid[base + offset] += w`) or the adjoint of a gather (`density.grad[i] += g`)
spends most of its time in lock-prefixed read-modify-writes. When a loop only *adds* into a field (never
reads it, never stores to it, never uses an atomic's old value), each thread can add into a private,
zeroed copy of the field's memory with plain instructions, and the copies are summed into the field once
after the loop. Which regions qualify, and how many updates per iteration go into them, is decided here.
An ndarray argument qualifies the same way (mpm88_graph's P2G into grid ndarrays): its region is the
whole array, every component, sized only at launch from the extents in the context.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from simgrad.dtypes import DataType
from simgrad.ir.fieldref import ArrayRef, FieldRef
from simgrad.ir.nodes import Stmt, offset_form
from simgrad.ir.ops import Op

PAGE_SHIFT = 12  # the pages of a copy that each thread marks as updated, and the final sum visits


@dataclass
class Region:
    """The bytes [lo, hi) past a run-time slice base of one SNode tree, copied per thread. The base is
    the sum of `index * stride` over `prefix`: leading axes every update indexes with the same
    loop-invariant values (a time step `t` of `h.grad[t, i, j]`), so only that slice is copied."""

    tree_id: int
    lo: int
    hi: int
    dtype: DataType
    prefix: tuple  # ((index Stmt, stride in bytes), ...)
    keys: set = field(default_factory=set)  # (id(field), access_key) of the updates it takes
    #: an ndarray argument's data instead of a tree's bytes (any of its components; tree_id, lo, hi unused):
    #: the whole array, its size read from the launch's extents
    array: ArrayRef | None = None

    @property
    def count(self) -> int:
        return (self.hi - self.lo) // self.dtype.nbytes

    def ir_name(self) -> str:
        if self.array is not None:
            return f"{self.array.name} (ndarray)"
        return f"tree {self.tree_id} [{self.lo}, {self.hi}) prefix {len(self.prefix)}"


def _span(f: FieldRef, nprefix: int) -> tuple[int, int]:
    """[first byte, one past the last byte] of a dense field's elements in its tree, for fixed values of
    its first `nprefix` indices (their offset left out)."""
    assert f.layout is not None  # kernels compile after their fields' trees are materialised
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


def _prefix_len(f: FieldRef, ptrs: list[Stmt], loop: Stmt, inside: set) -> int:
    """How many leading axes every update indexes with loop-invariant values, each a plain strided axis."""
    n = min(len(p.operands) for p in ptrs)
    for p in ptrs:
        k = 0
        while k < n and (p.operands[k].op is Op.CONST or (id(p.operands[k]) not in inside
                                                          and p.operands[k] is not loop)):
            k += 1
        n = k
    assert f.layout is not None
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


def _other_slice(a: Stmt, b: Stmt, nprefix: int) -> bool:
    """True when two accesses of one field provably differ in one of its first `nprefix` indices
    (`p[t + 1, ...]` against `p[t, ...]`), so they never touch the same element."""
    for x, y in zip(a.operands[:nprefix], b.operands[:nprefix]):
        (bx, cx), (by, cy) = offset_form(x), offset_form(y)
        if bx is by and cx != cy:
            return True
    return False


def private_regions(loop: Stmt, inside: set, uses: dict, shared: set, reduced: set,
                    debug: bool) -> tuple[list[Region], int]:
    """Regions worth privatising in a parallel loop and the estimated updates per iteration into them.

    A field the loop also reads or stores qualifies only where those accesses provably hit another
    slice; an ndarray component only when the loop neither reads nor stores it. Other components of the
    array may be read, stored or updated atomically: their partials stay zero, and zero partials are left
    alone by the final sum. `shared`: ids of targets some iteration updates at elements it does not own (the
    others need no atomics anyway); `reduced`: ids of targets the loop already sums per thread at fixed indices. A copy
    may span bytes of fields that are not privatised (interleaved layouts): they stay zero in it, and
    the final sum leaves an element alone where the copy holds zero. In debug mode slices are off (an
    out-of-bounds slice index must be reported, not summed into)."""
    adds: dict[int, list] = {}
    others: dict[int, list] = {}
    _updates(loop.blocks[0], uses, 1, adds, others)
    groups: dict[tuple, Region] = {}  # keyed by (tree, dtype, slice key, strides) or ("array", slot, dtype)
    weight = 0
    for tid, updates in adds.items():
        f = updates[0][0].operands[0].attrs["target"]
        if tid not in shared or tid in reduced or f.dtype.name not in ("f32", "f64", "i32", "i64"):
            continue
        ptrs = [a.operands[0] for a, _times in updates]
        if any(id(p) not in inside for p in ptrs):
            continue  # an address computed before the loop would still point into the field itself
        if isinstance(f, ArrayRef):
            if others.get(tid):
                continue  # the loop reads (or stores) the component it would add into a copy of
            akey = ("array", f.slot, f.dtype.name)
            r = groups.get(akey)
            if r is None:
                r = groups[akey] = Region(-1, 0, 0, f.dtype, (), array=f)
            for a, times in updates:
                r.keys.add((tid, access_key(a.operands[0], 0)))
                weight += times
            continue
        if not isinstance(f, FieldRef) or f.sparse or f.layout is None:
            continue
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
