"""Expand every element access into address arithmetic in the IR: the last pass before codegen.

A GLOBAL_PTR names an element by its indices (what autodiff and the parallel analyses reason about).
This pass appends the element's byte offset, computed in IR, as the GLOBAL_PTR's last operand and marks
it `lowered`; codegen then only adds the offset to the tree's root (or to a thread's private copy, or to
an ndarray's base). A dense field's offset is `((I[axis] // divisor) % modulus) * stride` per layout term.
A field under sparse SNodes is walked level by level from the tree's root instead (TREE_ROOT, then per
level a dense offset or a SPARSE_CELL lookup that activates when the access writes), and its GLOBAL_PTR
gets the absolute address (attrs `absolute`); ti.activate & co. (SNODE_OP) become the same walk ending
in a SPARSE_ACTION.

- Affine addressing: when the indices are digits of the enclosing parallel loop's flat index L plus
  constants, or loop-invariant (`p[t - 1, i + 1, j]` in `for i, j in g`, laid out in that order), the
  offset is `L * stride` plus invariant terms and a constant, with no division, so LLVM sees an affine
  address and vectorises the loop.
- An offset whose indices are all loop-invariant is computed before the parallel loop, so the task
  captures it (the per-thread sums of a `total[None] += v` add into that place after the loop).
- A struct-for over a pointer (or bitmasked) node with a dense block below (`pointer(ti.ijk, n).dense(ti.ijk,
  4)`, mgpcg's grids) runs a loop over each listed block's cells: an access to the loop's own cell of a field
  under that node starts from the block's cell, looked up once per block before the cell loop (`OwnBlock`).
  A neighbour read `z[i + 1, j, k]` (one axis off) selects between that cell and the cell of the block beside,
  looked up once too, so a stencil's cell loop reads no pointer table at all; a block whose side is off the
  grid runs a copy of the cell loop that branches instead (inside the block: its cell, else the full walk from
  the root, as before). Diagonal neighbours branch that way in both. A short cell loop (UNROLL_CELLS,
  UNROLL_STMTS) is marked `unroll`: LLVM unrolls it whole and every cell's digits fold.
- Debug mode: each index is checked against its extent first (CHECK_INDEX: a located IndexError and
  index 0 instead of a wild access).
Offsets are u64 arithmetic marked `nowrap` (an in-bounds offset cannot wrap): LLVM gets nuw/nsw.
"""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.builder import Builder, clone
from simgrad.ir.fieldref import ArrayRef, FieldRef
from simgrad.ir.nodes import Block, Kernel, Stmt, offset_form, walk
from simgrad.ir.ops import Op
from simgrad.passes.digits import digit_chain

_NOWRAP = {"nowrap": True}
#: a block's cell loop of at most so many cells and statements is unrolled whole (OwnBlock.finish): each copy's
#: cell digits are constants, so the in-block tests, selects and offsets fold (mgpcg's 4^3 blocks: smooth 7x)
UNROLL_CELLS = 64
UNROLL_STMTS = 200


def lower_access(kernel: Kernel, debug: bool = False) -> bool:
    written = {id(s.operands[0]) for s in walk(kernel.body)
               if s.op in (Op.GLOBAL_STORE, Op.ATOMIC) and s.operands[0].op is Op.GLOBAL_PTR}
    # a block looked up once must stay put while its cells run: not where the kernel may free one
    frees = debug or any(s.op is Op.SNODE_OP and s.attrs["op"] == "deactivate" for s in walk(kernel.body))
    return _lower_block(kernel.body, None, set(), None, debug, written, None if frees else False)


def _lower_block(block: Block, loop: Stmt | None, inside: set, before: list[Stmt] | None, debug: bool,
                 written: set, own) -> bool:
    """Lower the accesses of `block`; `loop` is the parallel loop the block is in (None outside one),
    `inside` the ids of its statements, `before` what goes ahead of it; `written`: ids of the GLOBAL_PTRs
    stored or atomically updated through (a sparse element is activated there); `own`: the OwnBlock of the
    struct-for the block is in, None where there is none or it may not be used, False outside loops."""
    changed = False
    out: list[Stmt] = []
    for s in block.stmts:
        if loop is None and s.op is Op.RANGE_FOR and s.attrs.get("parallel"):
            ahead: list[Stmt] = []
            mine = OwnBlock.of(s) if own is False else None
            if mine is not None:
                mine.copy_cell_loop(written)
            changed |= _lower_block(s.blocks[0], s, {id(x) for x in walk(s.blocks[0])} | {id(s)}, ahead, debug,
                                    written, mine)
            for x in ahead:
                x.block = block
            out += ahead
        else:
            for b in s.blocks:
                changed |= _lower_block(b, loop, inside, before, debug, written, own)
        if own and s is own.cell_loop:  # the block's lookups, once, ahead of its cells
            s = own.finish(s, lambda b, o: _lower_block(b, loop, inside | {id(x) for x in walk(b)} | {id(b.parent)},
                                                        before, debug, written, o))
            for x in own.prelude:
                x.block = block
            s.block = block
            out += own.prelude
        if s.op is Op.SNODE_OP:  # becomes the SPARSE_ACTION at the end of its walk
            out += _lower_snode_op(s)
            changed = True
            continue
        if s.op is Op.GLOBAL_PTR and not s.attrs.get("lowered"):
            target = s.attrs["target"]
            if isinstance(target, FieldRef) and target.sparse:
                mode = "write" if id(s) in written else "read"
                lowered = own.lower(s, target, mode, block) if own else None
                out += lowered if lowered is not None else _lower_sparse(s, target, mode, debug)
                changed = True
                out.append(s)
                continue
            invariant = before is not None and not debug and all(id(o) not in inside for o in s.operands)
            offset_stmts = _lower_one(s, loop, inside, debug)
            for x in offset_stmts:
                x.block = None if invariant else block
            (before if invariant and before is not None else out).extend(offset_stmts)
            changed = True
        out.append(s)
    block.stmts = out
    return changed


def _walk_levels(b: Builder, tree_id: int, levels: tuple, idx: list, mode: str) -> Stmt:
    """The u64 address of a cell of the last of `levels` (the tree's root when there are none), from the
    root down: a dense level adds its cell's offset, a sparse one looks the cell up (SPARSE_CELL, `mode`)."""
    return _walk_from(b, b.emit(Op.TREE_ROOT, dt.u64, (), {"tree": tree_id}), levels, idx, mode)


def _walk_from(b: Builder, addr: Stmt, levels, idx: list, mode: str) -> Stmt:
    """_walk_levels from `addr`, the address of a cell of the level above `levels`."""
    for level in levels:
        container = _add(b, addr, b.const(level.offset, dt.u64))
        cell = _cell_number(b, level, idx)
        if level.kind == "dense":
            addr = _add(b, container, _mul(b, cell, level.cell_size))
        else:
            addr = b.emit(Op.SPARSE_CELL, dt.u64, (container, cell), {"level": level, "mode": mode})
    return addr


def _cell_number(b: Builder, level, idx: list) -> Stmt:
    return _terms_sum(b, b.const(0, dt.u64), level.terms, idx)


def _terms_sum(b: Builder, start: Stmt, terms, idx: list) -> Stmt:
    """start + sum of ((idx[axis] // divisor) % modulus) * stride over layout terms (u64)."""
    total = start
    for t in terms:
        d = idx[t.axis]
        if t.divisor != 1:
            d = _digit(b, Op.RAW_DIV, d, t.divisor)
        if t.modulus:
            d = _digit(b, Op.RAW_MOD, d, t.modulus)
        total = _add(b, total, _mul(b, d, t.stride))
    return total


def _indices(b: Builder, s: Stmt, name: str, shape: tuple, debug: bool) -> list:
    idx = [_u64(b, o) for o in s.operands]
    if debug:
        text = str(tuple(shape))
        idx = [_checked(b, s, name, k, i, b.const(shape[k], dt.u64), text) for k, i in enumerate(idx)]
    return idx


def _lower_sparse(s: Stmt, target: FieldRef, mode: str, debug: bool) -> list[Stmt]:
    """A GLOBAL_PTR into a field under sparse SNodes: its absolute address (attrs `absolute`). Reads look
    every level up without activating (an inactive one gives its zero block); writes activate every level
    (adjoints too: the gradient of a read of an inactive cell lands there, as a dense field's would)."""
    scratch = Block()
    b = Builder(scratch)
    b.loc = s.loc
    idx = _indices(b, s, target.name, target.shape, debug)
    addr = _walk_levels(b, target.layout[0], target.levels, idx, mode)
    addr = _add(b, addr, b.const(target.value_offset, dt.u64))
    s.operands = (*s.operands, addr)
    s.attrs["lowered"] = True
    s.attrs["absolute"] = True
    return scratch.stmts


class OwnBlock:
    """A top-level struct-for whose listed node (a pointer or bitmasked node, the first sparse one) has a loop
    over each block's cells nested in it, the cell indices `X * c + v` (X: the block's index along the axis,
    in the listed loop; v: the cell loop's digit, 0 <= v < c). Every cell of a block has the same cell at the
    listed node, since each layout term down to it divides the index by a multiple of c: that cell is looked
    up (SPARSE_CELL, read: the block is listed, so active) once per block, ahead of the cell loop, from the
    indices `X * c`. An access of a field under that node whose index on every axis is the cell's own index
    plus a constant d (|d| < c) starts from it: the own cell always, a neighbour (reads only) when every
    `v + d` stays in [0, c), tested at run time, the full walk otherwise."""

    def __init__(self, node, cell_loop: Stmt, cells: list):
        self.node = node  # the listed node (its SNodeRef: tree_id, levels)
        self.cell_loop = cell_loop
        self.cells = cells  # per axis: (cell index statement, X, c, v)
        self.prelude: list[Stmt] = []
        self.base: dict = {}  # a field's levels down to the listed node -> the block's cell there
        self.sides = True  # neighbours off the block by a select of the block beside (else a branch)
        self.on_grid: list[Stmt] = []  # the tests of the blocks beside used, all true in the fast loop
        self.slow: Stmt | None = None  # the cell loop's copy for blocks at the grid's edge
        self.ahead: list[Stmt] = []  # the lookups of the blocks beside, ahead of the fast loop

    @staticmethod
    def of(loop: Stmt) -> OwnBlock | None:
        n = loop.attrs.get("cells")
        body = loop.blocks[0].stmts
        get = next((x for x in body if x.op is Op.SNODE_OP and x.attrs["op"] == "list_get"), None)
        inner = [x for x in body if x.op is Op.RANGE_FOR]
        if not n or get is None or len(inner) != 1:
            return None
        cell_loop = inner[0]
        in_cells = {id(x) for x in walk(cell_loop.blocks[0])}
        found: dict = {}
        for x in walk(cell_loop.blocks[0]):
            axis = x.attrs.get("cell_index")
            if axis is None or x.op is not Op.ADD or axis in found:
                continue
            m, v = x.operands
            if m.op is not Op.MUL or m.operands[1].op is not Op.CONST or id(m.operands[0]) in in_cells:
                return None
            found[axis] = (x, m.operands[0], m.operands[1].attrs["value"], v)
        if sorted(found) != list(range(n)) or any(c < 1 for _x, _X, c, _v in found.values()):
            return None
        return OwnBlock(get.attrs["snode"], cell_loop, [found[k] for k in range(n)])

    def _block_cell(self, levels: tuple) -> Stmt:
        """The address of the block's cell at the last of `levels` (a field's levels down to the listed
        node: the node's own levels count in its index space, a field's in the field's), walked once."""
        if levels not in self.base:
            scratch = Block()
            b = Builder(scratch)
            b.loc = self.cell_loop.loc
            idx = [_mul(b, _u64(b, X), c) for _x, X, c, _v in self.cells]
            self.base[levels] = _walk_levels(b, self.node.tree_id, levels, idx, "read")
            self.prelude += scratch.stmts
        return self.base[levels]

    def finish(self, fast: Stmt, lower) -> Stmt:
        """The cell loop to place after the prelude: `fast` (already lowered) when it took no block beside this
        one, else `if every block beside is on the grid: fast else: the slow copy` (lowered by `lower` with
        branches instead of selects, so an index off the grid walks from the root exactly as before)."""
        lo, hi = fast.operands
        if lo.op is Op.CONST and hi.op is Op.CONST and hi.attrs["value"] - lo.attrs["value"] <= UNROLL_CELLS \
                and sum(1 for _ in walk(fast.blocks[0])) <= UNROLL_STMTS:
            fast.attrs["unroll"] = True  # the cell's digits become constants: tests and offsets fold away
        if not self.on_grid or self.slow is None:
            return fast
        slow_own = OwnBlock(self.node, self.slow, self.slow_cells)
        slow_own.base, slow_own.prelude, slow_own.sides = self.base, self.prelude, False
        lower(self.slow.blocks[0], slow_own)
        scratch = Block()
        b = Builder(scratch)
        b.loc = fast.loc
        ok = self.on_grid[0]
        for flag in self.on_grid[1:]:
            ok = b.binary(Op.BIT_AND, ok, flag)
        self.prelude += scratch.stmts
        branch = Builder.detached(Op.IF, None, (ok,), loc=fast.loc, nblocks=2)
        branch.blocks[0].stmts = [*self.ahead, fast]
        branch.blocks[1].stmts = [self.slow]
        for part in branch.blocks:
            for x in part.stmts:
                x.block = part
        return branch

    def copy_cell_loop(self, written: set) -> None:
        """Keep an unlowered copy of the cell loop (its GLOBAL_PTRs written where the original's are)."""
        own = [x for x, _X, _c, _v in self.cells]
        for x in walk(self.cell_loop.blocks[0]):  # a block beside may be activated in the loop: look it up then
            target = x.attrs.get("target") if x.op is Op.GLOBAL_PTR else None
            if x.op is Op.SNODE_OP or (id(x) in written and isinstance(target, FieldRef) and self.under(target)
                                       and list(x.operands) != own):
                self.sides = False
                return
        if any(x.op is Op.ATOMIC and x.attrs.get("strategy") not in ("plain", "atomic")
               for x in walk(self.cell_loop.blocks[0])):
            self.sides = False  # per-thread sums and copies name their statements: keep one loop, branches
            return
        mapping: dict = {}
        self.slow = clone(self.cell_loop, mapping, None)
        for old in list(mapping):
            if old in written:
                written.add(id(mapping[old]))
        self.slow_cells = [(mapping[id(x)], X, c, mapping[id(v)]) for x, X, c, v in self.cells]

    def _side_cell(self, levels: tuple, target: FieldRef, shifts: list) -> tuple[Stmt, Stmt] | None:
        """For a neighbour off the block along one axis: (whether the block beside this one on that side is on
        the grid, its cell there), once per block and side; the cell is looked up in the branch that runs the
        fast loop, taken only when every block beside that the loop uses is on the grid."""
        axis = next(k for k, (_v, _c, d) in enumerate(shifts) if d)
        _cell, X, c, _v = self.cells[axis]
        sign = 1 if shifts[axis][2] > 0 else -1
        blocks = target.shape[axis] // c if axis < len(target.shape) else 0
        if blocks < 2:
            return None
        key = (levels, axis, sign)
        if key not in self.base:
            scratch = Block()
            b = Builder(scratch)
            b.loc = self.cell_loop.loc
            if sign > 0:
                on_grid = b.binary(Op.LT, X, b.const(blocks - 1, X.vtype))
            else:
                on_grid = b.binary(Op.GE, X, b.const(1, X.vtype))
            self.prelude += scratch.stmts
            scratch = Block()  # looked up in the fast branch only, where every block beside is on the grid
            b = Builder(scratch)
            b.loc = self.cell_loop.loc
            corner = [_mul(b, _u64(b, Y), k) for _x, Y, k, _w in self.cells]
            corner[axis] = _mul(b, _u64(b, b.binary(Op.ADD, X, b.const(sign, X.vtype))), c)
            self.base[key] = (on_grid, _walk_levels(b, self.node.tree_id, levels, corner, "read"))
            self.ahead += scratch.stmts
        return self.base[key]

    def under(self, target: FieldRef) -> bool:
        """Whether `target` is a field under the listed node."""
        n = len(self.node.levels)
        levels = tuple(target.levels[:n])
        return (target.sparse and target.layout[0] == self.node.tree_id and len(levels) == n
                and all(_node_of(a) == _node_of(b) for a, b in zip(levels, self.node.levels)))

    def lower(self, s: Stmt, target: FieldRef, mode: str, block: Block) -> list[Stmt] | None:
        """The statements computing `s`'s address from the block's cell, or None when it is not one of the
        accesses described above."""
        levels = tuple(target.levels[:len(self.node.levels)])
        if not self.under(target) or len(s.operands) != len(self.cells):
            return None  # a field under another node
        if any(t.divisor % self.cells[t.axis][2] for level in levels for t in level.terms):
            return None  # the cell at the listed node would depend on v
        shifts = []
        for o, (cell, _X, c, v) in zip(s.operands, self.cells):
            base, d = offset_form(o)
            if base is not cell or abs(d) >= c:
                return None
            shifts.append((v, c, d))
        near = [(v, c, d) for v, c, d in shifts if d]
        if near and mode != "read":
            return None
        own = self._block_cell(levels)
        scratch = Block()
        b = Builder(scratch)
        b.loc = s.loc
        idx = [_u64(b, o) for o in s.operands]
        if near:  # the neighbour's block is this one when every v + d stays in [0, c)
            inside = None
            for v, c, d in near:
                if d > 0:
                    test = b.binary(Op.LT, v, b.const(c - d, v.vtype))
                else:
                    test = b.binary(Op.GE, v, b.const(-d, v.vtype))
                inside = test if inside is None else b.binary(Op.BIT_AND, inside, test)
            assert inside is not None
            side = self._side_cell(levels, target, shifts) if len(near) == 1 and self.sides else None
            if side is not None:  # in the fast loop the block beside is on the grid: a select, no branch
                on_grid, beside = side
                if all(flag is not on_grid for flag in self.on_grid):
                    self.on_grid.append(on_grid)
                cell = b.select(inside, own, beside)
            else:
                slot = b.emit(Op.ALLOCA, dt.u64)
                branch = b.emit(Op.IF, None, (inside,), nblocks=2)
                with b.inside(branch.blocks[0]):
                    b.emit(Op.LOCAL_STORE, None, (slot, own))
                with b.inside(branch.blocks[1]):
                    b.emit(Op.LOCAL_STORE, None, (slot, _walk_levels(b, target.layout[0], levels, idx, "read")))
                cell = b.emit(Op.LOCAL_LOAD, dt.u64, (slot,))
        else:
            cell = own
        addr = _walk_from(b, cell, target.levels[len(levels):], idx, mode)
        addr = _add(b, addr, b.const(target.value_offset, dt.u64))
        s.operands = (*s.operands, addr)
        s.attrs["lowered"] = True
        s.attrs["absolute"] = True
        for x in scratch.stmts:
            x.block = block
        return scratch.stmts


def _node_of(level) -> tuple:
    """What names a level's node on a path, whatever index space its terms count in."""
    return level.kind, level.offset, level.cell_size, level.ncells, level.pool


def _lower_snode_op(s: Stmt) -> list[Stmt]:
    """ti.activate / deactivate / is_active / length / append on a sparse node: walk to the container of
    the node's cell (activating the levels above only when the op activates), then act on it."""
    scratch = Block()
    b = Builder(scratch)
    b.loc = s.loc
    node = s.attrs["snode"]
    op = s.attrs["op"]
    if op in ("list_get", "list_set"):  # the loop's list of active cells: (entry[, value]), no walk
        s.op, s.attrs = Op.SPARSE_ACTION, {"level": node.levels[-1], "op": op, "list": s.attrs["list"]}
        return [s]
    idx = _indices(b, s, node.name, (), False)
    *above, last = node.levels
    mode = "write" if op in ("activate", "append_slot") else "read"
    addr = _walk_levels(b, node.tree_id, tuple(above), idx, mode)
    container = _add(b, addr, b.const(last.offset, dt.u64))
    cell = _cell_number(b, last, idx)
    s.op, s.operands, s.attrs = Op.SPARSE_ACTION, (container, cell), {"level": last, "op": op}
    scratch.stmts.append(s)
    return scratch.stmts


def _lower_one(s: Stmt, loop: Stmt | None, inside: set, debug: bool) -> list[Stmt]:
    """The statements computing GLOBAL_PTR `s`'s byte offset, which becomes its last operand."""
    scratch = Block()
    b = Builder(scratch)
    b.loc = s.loc
    target = s.attrs["target"]
    if isinstance(target, FieldRef):
        offset = _field_offset(b, s, target, loop, inside, debug)
    elif isinstance(target, ArrayRef):
        offset = _array_offset(b, s, target, debug)
    else:
        raise AssertionError(f"internal: {s!r} points into {target!r}")
    s.operands = (*s.operands, offset)
    s.attrs["lowered"] = True
    return scratch.stmts


def _u64(b: Builder, v: Stmt) -> Stmt:
    return b.cast(v, dt.u64)


def _value(x: Stmt):
    return x.attrs["value"] if x.op is Op.CONST else None


def _add(b: Builder, x: Stmt, y: Stmt) -> Stmt:
    """x + y, folded when either is a known 0 or both are constants (constant indices, field offsets)."""
    vx, vy = _value(x), _value(y)
    if vx is not None and vy is not None:
        return b.const(vx + vy, dt.u64)
    if vx == 0:
        return y
    if vy == 0:
        return x
    return b.emit(Op.ADD, dt.u64, (x, y), dict(_NOWRAP))


def _mul(b: Builder, x: Stmt, k: int) -> Stmt:
    vx = _value(x)
    if vx is not None:
        return b.const(vx * k, dt.u64)
    if k == 1:
        return x
    return b.emit(Op.MUL, dt.u64, (x, b.const(k, dt.u64)), dict(_NOWRAP))


def _digit(b: Builder, op: Op, x: Stmt, k: int) -> Stmt:
    vx = _value(x)
    if vx is not None:
        return b.const(vx // k if op is Op.RAW_DIV else vx % k, dt.u64)
    return b.binary(op, x, b.const(k, dt.u64))


def _checked(b: Builder, s: Stmt, name: str, axis: int, idx: Stmt, extent: Stmt, shape_text: str,
             offset: int = 0) -> Stmt:
    return b.emit(Op.CHECK_INDEX, dt.u64, (idx, extent),
                  {"field": name, "axis": axis, "shape": shape_text, "offset": offset})


def _field_offset(b: Builder, s: Stmt, target: FieldRef, loop: Stmt | None, inside: set, debug: bool) -> Stmt:
    """The byte offset of a field element from its tree's root, level by level (dense levels only today)."""
    _tree, const, terms, shape = target.layout
    form = None if debug or loop is None else _affine_form(s, terms, loop, inside)
    if form is not None and loop is not None:  # affine in the loop index: LLVM can vectorise
        unit, shift, invariant = form
        off = _mul(b, _u64(b, loop), unit)
        for o, stride in invariant:
            off = _add(b, off, _mul(b, _u64(b, o), stride))
        shift += const
        if shift < 0:  # `g[i - 1, j]`: subtract, so that no in-bounds partial sum wraps
            return b.emit(Op.SUB, dt.u64, (off, b.const(-shift, dt.u64)), dict(_NOWRAP))
        return _add(b, b.const(shift, dt.u64), off)
    idx = [_u64(b, o) for o in s.operands]
    if debug:
        offsets = target.offset or (0,) * len(shape)
        text = str(shape) + (f" with offset {tuple(offsets)}" if any(offsets) else "")
        idx = [_checked(b, s, target.name, k, i, b.const(shape[k], dt.u64), text, offsets[k])
               for k, i in enumerate(idx)]
    return _terms_sum(b, b.const(const, dt.u64), terms, idx)


def _array_offset(b: Builder, s: Stmt, arg: ArrayRef, debug: bool) -> Stmt:
    """The byte offset of an ndarray element from the array's base: C order, the element's components as
    trailing dimensions."""
    idx = [_u64(b, o) for o in s.operands]
    extents = [_u64(b, b.emit(Op.ARRAY_SHAPE, dt.i32, (), {"arg": arg, "dim": k})) for k in range(arg.ndim)]
    if debug:
        idx = [_checked(b, s, arg.name, k, i, extents[k], "ndarray") for k, i in enumerate(idx)]
    lin: Stmt = b.const(0, dt.u64)
    for k, i in enumerate(idx):
        if k:
            lin = b.emit(Op.MUL, dt.u64, (lin, extents[k]), dict(_NOWRAP))
        lin = _add(b, lin, i)
    if arg.num_components > 1:
        lin = _add(b, _mul(b, lin, arg.num_components), b.const(arg.comp, dt.u64))
    return _mul(b, lin, arg.dtype.nbytes)


def _affine_form(s: Stmt, terms, loop: Stmt, inside: set) -> tuple[int, int, list] | None:
    """(unit, shift, invariant) when the element's byte offset from the field's first byte is
    `L * unit + shift + sum(index * stride for index, stride in invariant)` for the parallel loop's index
    L: every axis is plainly strided, and its index is either loop-invariant or a digit `(L // d) % m`
    of the flattened loop plus a constant (`p[t, i + 1, j]` in `for i, j in g`), the digits together
    being all of L with strides that follow them (a dense field iterated in its own order). Else None."""
    if loop.operands[0].op is not Op.CONST or loop.operands[0].attrs["value"] != 0:
        return None
    if len(terms) != len(s.operands) or any(t.divisor != 1 or t.modulus for t in terms):
        return None
    strides = {t.axis: t.stride for t in terms}
    shift, invariant, digits, places = 0, [], [], []
    for axis, o in enumerate(s.operands):
        base, c = offset_form(o)
        if base is None:
            shift += c * strides[axis]
        elif id(base) not in inside:
            invariant.append((o, strides[axis]))
        else:
            digits.append(base)
            places.append(axis)
            shift += c * strides[axis]
    chain = digit_chain(digits, loop) if digits else None
    if chain is None or len(chain) != len(digits):  # every varying index one digit of the chain
        return None
    unit = strides[places[chain[0][0]]]
    if any(strides[places[k]] != divisor * unit for k, divisor, _mod in chain):
        return None
    return unit, shift, invariant
