"""Decide how parallel loops update memory, before any code is emitted.

Every top-level parallel RANGE_FOR gets `attrs["strategy"]`, a `LoopStrategy` (which places it sums per
thread, which regions it may copy per thread), and every ATOMIC gets `attrs["strategy"]`, the cheapest
form that is still correct:

- `plain`: a read-modify-write without atomic instructions: serial code, a local of the iteration, or an
  element the iteration owns (its indices an injective function of the loop index, and no other iteration
  writes that field at elements it does not own);
- `reduce`: an add into one loop-invariant place (`total[None] += v`, `s += v` on a kernel-scope local),
  summed per thread first and added once per chunk;
- `pair`: two neighbouring f32 components updated together (`grid_v[I] += v` on a 2-vector field), one
  64-bit compare-and-swap (both statements of the pair carry it);
- `atomic`: a real atomic instruction;
- `private|atomic`, `private|pair`: the field is added into a per-thread copy when the target decides the
  copies pay off (see passes/privatize.py), else the form after the bar.

Targets emit what is written here; none of this depends on how a target runs a parallel loop.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from simgrad import dtypes as dt
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, offset_form, walk
from simgrad.ir.ops import Op
from simgrad.passes.digits import invariant_chain, invariant_digit
from simgrad.passes.privatize import Region, access_key, private_regions

PLAIN, REDUCE, PAIR, ATOMIC, PRIVATE = "plain", "reduce", "pair", "atomic", "private|"


@dataclass
class LoopStrategy:
    """What a parallel loop's tasks set up: per-thread sums and per-thread copies."""

    # {place key: (the pointer statement, [the ATOMIC statements adding into it])}
    reductions: dict[tuple, tuple[Stmt, list[Stmt]]] = field(default_factory=dict)
    regions: list[Region] = field(default_factory=list)  # candidates for per-thread copies
    weight: int = 0  # updates per iteration into the regions (serial loops of constant trip multiply)
    #: iterations a thread takes at a time: ~4096 statements' worth of the body (a user's block_dim wins)
    grain: int = 1
    #: no iteration stores to a field element that another reads or stores (`_independent`): the target may tell
    #: its compiler the loop's iterations are independent
    independent: bool = False

    def ir_name(self) -> str:
        """The IR printer's text: `tasks(grain=64, reduce=[%7], private=[tree 2 [0, 4096) prefix 1], weight=9)`."""
        parts = [f"grain={self.grain}"]
        if self.reductions:
            parts.append("reduce=[" + ", ".join(f"%{place.id}" for place, _ in self.reductions.values()) + "]")
        if self.regions:
            parts.append("private=[" + ", ".join(r.ir_name() for r in self.regions) + f"], weight={self.weight}")
        return "tasks(" + ", ".join(parts) + ")"


def parallel_strategy(kernel: Kernel, debug: bool = False) -> bool:
    """Annotate every parallel loop and every atomic of the kernel. In debug mode no pairs (each update
    is bounds-checked on its own), no slices of copies (an out-of-bounds slice index must be reported,
    not summed into) and no per-thread sums of indexed field elements (the final add addresses the element after
    the loop, where its checked offset, computed in the loop, is not defined: LLVM's verifier refused it)."""
    uses: dict[int, int] = {}
    for x in walk(kernel.body):
        for o in x.operands:
            uses[id(o)] = uses.get(id(o), 0) + 1
    _serial(kernel.body, uses, debug)
    return False


def _serial(block: Block, uses: dict, debug: bool) -> None:
    """Code outside parallel loops: every atomic is plain; parallel loops are decided on their own."""
    for s in block.stmts:
        if s.op is Op.RANGE_FOR and s.attrs.get("parallel"):
            _loop(s, uses, debug)
            continue
        if s.op is Op.ATOMIC:
            s.attrs["strategy"] = PLAIN
        for b in s.blocks:
            _serial(b, uses, debug)


def _loop(loop: Stmt, uses: dict, debug: bool) -> None:
    inside = {id(x) for x in walk(loop.blocks[0])}
    shared = _shared_targets(loop, inside)
    reductions = _reductions(loop, inside, uses, debug)
    reduced = {key[0] for key in reductions}
    regions, weight = private_regions(loop, inside, uses, shared, reduced, debug)
    grain = loop.attrs.get("block_dim") or max(1, 4096 // max(1, sum(1 for _ in walk(loop.blocks[0]))))
    loop.attrs["strategy"] = LoopStrategy(reductions, regions, weight, grain, _independent(loop, inside))
    reducing = {id(a) for _place, adds in reductions.values() for a in adds}
    private = {k for r in regions for k in r.keys}  # (id(field), slice key) of the updates copied
    nprefix = {tid: len(key) for tid, key in private}  # every update of a field has as many prefix axes
    for x in walk(loop.blocks[0]):
        if x.op is not Op.ATOMIC:
            continue
        p = x.operands[0]
        if x.attrs["kind"] == "cas":  # a quant cell's compare-and-swap (passes/quant.py): cells are shared
            form = ATOMIC
        elif id(x) in reducing:
            form = REDUCE
        elif p.op is Op.ALLOCA:  # a local: shared only when declared outside the loop
            form = ATOMIC if id(p) not in inside else PLAIN
        elif p.op is Op.GLOBAL_PTR and id(p.attrs["target"]) not in shared and injective_in(loop, p, inside):
            form = PLAIN
        else:
            form = ATOMIC
        tid = id(p.attrs["target"]) if p.op is Op.GLOBAL_PTR else None
        if tid in nprefix and (tid, access_key(p, nprefix[tid])) in private:
            form = PRIVATE + form
        x.attrs["strategy"] = form
    if not debug:
        _pairs(loop.blocks[0], uses)


def _pairs(block: Block, uses: dict) -> None:
    """Mark `a; p2; b` sequences (ATOMIC, GLOBAL_PTR, ATOMIC) that one 64-bit compare-and-swap can do."""
    stmts = block.stmts
    for k in range(len(stmts) - 2):
        a, p2, b = stmts[k:k + 3]
        if _pairable(a, p2, b, uses):
            prefix = PRIVATE if a.attrs["strategy"].startswith(PRIVATE) else ""
            a.attrs["strategy"] = b.attrs["strategy"] = prefix + PAIR
    for s in stmts:
        for inner in s.blocks:
            _pairs(inner, uses)


def _pairable(a: Stmt, p2: Stmt, b: Stmt, uses: dict) -> bool:
    """`v[I] += w` on an f32 2-vector (or two neighbouring components): both atomic adds of unused
    result, 8-byte aligned neighbours of one tree, both really atomic (or both privatised)."""
    if a.op is not Op.ATOMIC or b.op is not Op.ATOMIC or b.operands[0] is not p2 or a.type is not dt.f32 \
            or b.type is not dt.f32:
        return False
    if a.attrs["kind"] != "add" or b.attrs["kind"] != "add" or uses.get(id(a)) or uses.get(id(b)):
        return False
    if a.attrs["strategy"] not in (ATOMIC, PRIVATE + ATOMIC) or b.attrs["strategy"] != a.attrs["strategy"]:
        return False
    p1 = a.operands[0]
    if p1.op is not Op.GLOBAL_PTR or p2.op is not Op.GLOBAL_PTR or p1.operands != p2.operands:
        return False
    t1, t2 = p1.attrs["target"], p2.attrs["target"]
    if not isinstance(t1, FieldRef) or not isinstance(t2, FieldRef) or t1.sparse or t2.sparse:
        return False
    (tree1, c1, terms1, _), (tree2, c2, terms2, _) = t1.layout, t2.layout
    return tree1 == tree2 and terms1 == terms2 and c2 == c1 + 4 and c1 % 8 == 0 \
        and all(t.stride % 8 == 0 for t in terms1)


def _shared_targets(loop: Stmt, inside: set) -> set[int]:
    """Ids of the fields (ndarray components) some iteration writes at an element it does not own: every
    update of them stays atomic. A target is owned when each of its written elements is an injective function
    of the loop index (injective_in) and all of them agree on every index that varies with the iteration
    (`_varying`): then only one iteration can write any element. `x[i]` and `x[i + 1]` are each injective, but
    iteration i + 1 writes what iteration i writes second; `x[i, 0]` and `x[i, 1]` agree where it matters."""
    writes: dict[int, list[Stmt]] = {}
    for x in walk(loop.blocks[0]):
        if x.op in (Op.ATOMIC, Op.GLOBAL_STORE) and x.operands[0].op is Op.GLOBAL_PTR:
            writes.setdefault(id(x.operands[0].attrs["target"]), []).append(x.operands[0])
    return {tid for tid, ptrs in writes.items() if not _owned(ptrs, ptrs, loop, inside)}


def _owned(written: list[Stmt], accessed: list[Stmt], loop: Stmt, inside: set) -> bool:
    """Whether each written element is an injective function of the loop index and every accessed one (the
    written among them) agrees with it on each index that varies with the iteration: no two iterations then
    touch one element."""
    return all(injective_in(loop, p, inside) for p in written) \
        and len({_varying(p, loop, inside) for p in accessed}) <= 1


def _independent(loop: Stmt, inside: set, stmts: Iterable[Stmt] | None = None) -> bool:
    """Whether the iterations share no element one of them stores to: every field the loop stores to is stored
    and read only at the element the iteration owns (injective stores, every access with the same varying
    indices), and the ndarrays count as one array (one may be passed twice). Taichi's rule calls any other
    sharing a race, but at one thread taichi runs such a loop in order (`x[i] = x[i - 1] + 1` counts up), and a
    target told the iterations are independent would reorder it. `stmts`: only these of the body's statements
    (passes/fission.py's part before the scatters)."""
    stores: dict[int, list[Stmt]] = {}
    reads: dict[int, list[Stmt]] = {}
    for x in (walk(loop.blocks[0]) if stmts is None else stmts):
        if x.op in (Op.GLOBAL_STORE, Op.ATOMIC, Op.GLOBAL_LOAD) and x.operands[0].op is Op.GLOBAL_PTR:
            p = x.operands[0]
            t = p.attrs["target"]
            key = id(t) if isinstance(t, FieldRef) else 0  # every ndarray the same array
            (reads if x.op is Op.GLOBAL_LOAD else stores).setdefault(key, []).append(p)
    return all(_owned(ptrs, ptrs + reads.get(key, []), loop, inside) for key, ptrs in stores.items())


def _varying(ptr: Stmt, loop: Stmt, inside: set) -> tuple:
    """The indices of an element that vary with the iteration, as (axis, base, constant) (offset_form),
    loop-invariant ones left out."""
    out = []
    for axis, o in enumerate(ptr.operands):
        if o.op is Op.CONST or (o is not loop and id(o) not in inside):
            continue
        base, c = offset_form(o)
        out.append((axis, id(base), c))
    return tuple(out)


def _digit_base(o: Stmt, loop: Stmt, inside: set) -> Stmt:
    """The digit `(index // d) % m` an index is a constant away from (`i + 1` in `for i, j in ti.ndrange((1,
    n - 1), ...)`), else the index itself: a constant shift keeps a chain of digits injective."""
    base, _c = offset_form(o)
    return base if base is not None and invariant_digit(base, loop, inside) is not None else o


def injective_in(loop: Stmt, ptr: Stmt, inside: set) -> bool:
    """True when the element's indices determine the loop index: apart from loop-invariant values they
    are digits `(index // d) % m` of it (d and m constants or values from before the loop: an ndarray's
    run-time extents in `for i, j in arr`), each plus a constant, that chain from d = 1 up to a digit without
    modulus; or, in a struct-for over sparse cells (loop attrs `cells`), they are the cell's own indices, every
    one."""
    ncells = loop.attrs.get("cells")
    if ncells and len(ptr.operands) == ncells and all(
            id(o) in inside and o.attrs.get("cell_index") == k for k, o in enumerate(ptr.operands)):
        return True
    idx = [_digit_base(o, loop, inside) for o in ptr.operands]
    if any(o.op is not Op.CONST and (o is loop or id(o) in inside) and invariant_digit(o, loop, inside) is None
           for o in idx):
        return False  # an index computed in the iteration some other way
    return invariant_chain(idx, loop, inside)


def _reductions(loop: Stmt, inside: set, uses: dict, debug: bool = False) -> dict:
    """Places a parallel loop only accumulates into: every access is an atomic add whose old value is
    unused, at loop-invariant indices (in debug mode locals and 0-D fields only). {key: (a pointer statement,
    [the ATOMIC statements])}."""
    groups: dict[tuple, tuple[Stmt, list[Stmt]]] = {}
    spoiled: set[int] = set()
    inside = inside | {id(loop)}  # the loop index varies too
    for x in walk(loop.blocks[0]):
        for k, o in enumerate(x.operands):
            is_place = (o.op is Op.ALLOCA and id(o) not in inside) or o.op is Op.GLOBAL_PTR
            if not is_place:
                continue
            key: tuple
            if o.op is Op.GLOBAL_PTR:
                # its address is computed in the loop: a sparse element's, or in debug mode an indexed element's
                # (its checked offset is; a 0-D field's offset is a constant)
                if (debug and o.operands) or getattr(o.attrs["target"], "sparse", False):
                    spoiled.add(id(o.attrs["target"]))
                    continue
                if any(i.op is not Op.CONST and id(i) in inside for i in o.operands):
                    spoiled.add(id(o.attrs["target"]))
                    continue
                key = (id(o.attrs["target"]), tuple(id(i) if i.op is not Op.CONST else ("c", i.attrs["value"])
                                                    for i in o.operands))
            else:
                key = (id(o),)
            reducing = x.op is Op.ATOMIC and k == 0 and x.attrs["kind"] == "add" and not uses.get(id(x))
            if not reducing:
                spoiled.add(key[0])
                continue
            place, adds = groups.setdefault(key, (o, []))
            adds.append(x)
    by_target: dict[int, list[tuple]] = {}
    for key in groups:
        by_target.setdefault(key[0], []).append(key)
    return {key: groups[key] for key in groups if key[0] not in spoiled and len(by_target[key[0]]) == 1}
