"""Loop versions per value of a launch-wide index (the CPU's kernels): `v[i][k]` with `k` a kernel argument.

A vector component picked at run time (`phiRate[i, j][rk_loop] = rate`, `x = phiRate[I][rk_loop - 1]`) is a store
under `if k == c` per component (passes/store_select.py then makes each a load, select and store of the whole
vector) and a select over every loaded component for a read. When `k` is the same for every iteration of a
top-level parallel loop, this pass runs a copy of the loop per constant `k` is compared with, `k` replaced by it, so
that simplify leaves one store and one load per access; the original loop stays for every other value. Each copy
counts to the loop's end only for its value (`range(b, select(k == c, e, b))`), so all of them stay top-level
parallel loops, one of which runs: every later pass (strategies, lanes, fission) sees ordinary loops.
snow_phaseField's get_rate (two such accesses per cell) 2.2 -> 1.5 ms a call.

Only where it pays and stays small: at least two different constants compared with `k` in the loop (one access's
components), at most MAX_VERSIONS of them, and the copies together at most MAX_COPIED statements. Not on a GPU
(its kernels launch top-level loops as they are).
"""

from __future__ import annotations

from simgrad.dtypes import DataType
from simgrad.ir.builder import Builder, clone
from simgrad.ir.nodes import Kernel, Stmt, walk
from simgrad.ir.ops import PURE, Op

MAX_VERSIONS = 4
MAX_COPIED = 2000  # statements: bounds the compile time a kernel gains (snow_phaseField: 4 x ~400)


def unswitch(kernel: Kernel) -> bool:
    changed = False
    out: list[Stmt] = []
    for s in kernel.body.stmts:
        if s.op is Op.RANGE_FOR and s.attrs.get("parallel") and not s.attrs.get("cells") \
                and not s.attrs.get("listgen"):
            found = _launch_index(s, out)
            if found is not None:
                out += _versions(s, out, *found)
                changed = True
        out.append(s)
    kernel.body.stmts = out
    return changed


def _launch_index(loop: Stmt, before: list[Stmt]) -> tuple[Stmt, list[int], set, DataType] | None:
    """(k, the constants it is compared with, ids of the statements before the loop whose values the loop uses,
    directly or through others, the comparisons' boolean type) for the integer `k` defined before the loop that
    is compared for equality with the most constants there (passes/hoist.py has moved the comparisons out of the
    loop), or None."""
    size, used = 0, set[int]()
    for x in walk(loop.blocks[0]):
        size += 1
        used.update(id(o) for o in x.operands)
    used.update(id(o) for o in loop.operands)
    for x in reversed(before):
        if id(x) in used:
            used.update(id(o) for o in x.operands)
    seen: dict[int, tuple[Stmt, set, DataType]] = {}  # id(k) -> (k, constants, boolean type)
    for eq in before:
        if eq.op is not Op.EQ or id(eq) not in used or eq.type is None:
            continue
        a, b = eq.operands
        k, c = (a, b) if b.op is Op.CONST else (b, a) if a.op is Op.CONST else (None, None)
        if k is not None and c is not None and k.op is not Op.CONST and k.type is not None and not k.type.is_float:
            seen.setdefault(id(k), (k, set(), eq.type))[1].add(int(c.attrs["value"]))
    best = None
    for k, values, flag in seen.values():
        if 2 <= len(values) <= MAX_VERSIONS and size * len(values) <= MAX_COPIED:
            if best is None or len(values) > len(best[1]):
                best = (k, sorted(values), used, flag)
    return best


def _versions(loop: Stmt, before: list[Stmt], k: Stmt, values: list[int], used: set, flag: DataType) -> list[Stmt]:
    """The statements to add before `loop`: for each value v, the pure statements before the loop that depend on k
    and that it uses, again with k = v, then a copy of it over them that runs only when k == v; `loop` itself then
    runs only when k has none of the values."""
    begin, end = loop.operands
    ty = k.type
    assert ty is not None  # (an integer value: _launch_index)
    out: list[Stmt] = []
    rest = end
    for v in values:
        value = Builder.constant(v, ty)
        mapping = {id(k): value}
        for x in before:
            if id(x) in used and x.op in PURE and not x.blocks and any(id(o) in mapping for o in x.operands):
                out.append(clone(x, mapping, loop.block))
        hit = Builder.detached(Op.EQ, flag, (k, value), {}, loop.loc, loop.block)
        stop = Builder.detached(Op.SELECT, end.type, (hit, end, begin), {}, loop.loc, loop.block)
        copy = clone(loop, mapping, loop.block)
        copy.operands = (begin, stop)
        rest = Builder.detached(Op.SELECT, end.type, (hit, begin, rest), {}, loop.loc, loop.block)
        out += [hit, stop, copy, rest]
    loop.operands = (begin, rest)
    return out
