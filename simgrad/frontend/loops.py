"""For loops: ti.static unrolling, range-for, ti.ndrange, struct-for over fields, ti.grouped.

Every run-time loop becomes one RANGE_FOR over a flat index; multi-dimensional loops recover their
indices by division, so the outermost loop of a kernel is always one parallel range."""

from __future__ import annotations

import ast
import contextlib

from simgrad import dtypes as dt
from simgrad.errors import SimgradSyntaxError
from simgrad.frontend.frames import RangeSpec
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.field import Field
from simgrad.lang.loops import grouped, ndrange, static
from simgrad.lang.matrix import Matrix
from simgrad.lang.snode import SNode


def _is_static_call(comp, node) -> bool:
    if not isinstance(node, ast.Call):
        return False
    try:
        fn = comp.eval(node.func)
    except Exception:
        return False
    return fn is static


def lower_for(comp, node: ast.For) -> None:
    if _is_static_call(comp, node.iter):
        inner = node.iter.args[0] if isinstance(node.iter, ast.Call) and len(node.iter.args) == 1 else None
        if _is_static_call(comp, inner):
            raise SimgradSyntaxError("'ti.static' cannot be nested", comp.loc(node.iter))
        if isinstance(inner, ast.Call):
            group = comp.eval(inner)
            if isinstance(group, grouped) and not isinstance(group.target, ndrange):  # Taichi's rule
                raise SimgradSyntaxError("Only 'ti.ndrange' is allowed in 'ti.static(ti.grouped(...))': a field's "
                                         "indices are unrolled by a struct-for", comp.loc(node.iter))
        _unroll(comp, node)
        return
    it = comp.eval(node.iter)
    if isinstance(it, RangeSpec):
        _range_for(comp, node, it)
    elif isinstance(it, ndrange):
        _nd_for(comp, node, it.bounds, grouped_=False)
    elif isinstance(it, grouped):
        t = it.target
        cells = _sparse_node(t)
        if cells is not None:
            _sparse_for(comp, node, cells, _offset_of(t), grouped_=True)
            return
        bounds = t.bounds if isinstance(t, ndrange) else _bounds_of(comp, t, node)
        _nd_for(comp, node, bounds, grouped_=True)
    elif _sparse_node(it) is not None:
        _sparse_for(comp, node, _sparse_node(it), _offset_of(it), grouped_=False)  # type: ignore[arg-type]
    elif isinstance(it, SNode):
        _nd_for(comp, node, [(0, n) for n in it.shape], grouped_=False)
    elif isinstance(it, Field) or _is_array(it):
        _nd_for(comp, node, _bounds_of(comp, it, node), grouped_=False)
    elif isinstance(it, Expr):
        raise SimgradSyntaxError(f"cannot loop over a run-time {it.dtype} value; use range() over it",
                                 comp.loc(node.iter))
    else:
        raise SimgradSyntaxError(
            f"cannot loop over a {type(it).__name__} at run time; wrap Python sequences in ti.static(...) "
            "to unroll the loop", comp.loc(node.iter))


def _is_array(v) -> bool:
    from simgrad.frontend.arrays import ArrayArg

    return isinstance(v, ArrayArg)


def _bounds_of(comp, target, node):
    """(begin, end) per axis of a struct-for: a field with an offset is visited at its offset indices."""
    shape = _shape_of(comp, target, node)
    offset = target._components()[0].offset if isinstance(target, Field) else None
    return [(o, o + n) for o, n in zip(offset, shape)] if offset else [(0, n) for n in shape]


def _sparse_node(target) -> SNode | None:
    """The node whose active cells a struct-for over `target` visits, when sparse SNodes are on its path:
    a field's cells (the node its value is placed under) or an SNode's own."""
    if isinstance(target, Field):
        target._ensure()
        node = target.snode.parent()
    elif isinstance(target, SNode):
        node = target
        if node.tree is not None:
            node.tree.materialize()
    else:
        return None
    return node if node is not None and node.has_sparse_path() else None


def _offset_of(target):
    return target._components()[0].offset if isinstance(target, Field) else None


def _sparse_for(comp, node: ast.For, cells: SNode, offset, grouped_: bool) -> None:
    """`for i, j in x` / `for I in ti.grouped(x)` over a field or SNode with sparse nodes on its path."""
    bind = _binder(comp, node, len({a for n in cells.path() for a in n.axes}), grouped_)
    active_cells_loop(comp, cells, offset, _visit(comp, node, bind))


def _binder(comp, node: ast.For, nd: int, grouped_: bool):
    """The function binding a loop's targets to its nd indices: one name per index, or one vector name for
    a grouped loop (checked here, at the loop's line)."""
    names = _target_names(comp, node.target)
    if grouped_ and len(names) != 1:
        raise SimgradSyntaxError("a grouped loop takes exactly one loop variable", comp.loc(node.target))
    if not grouped_ and len(names) != nd:
        what = "Ndrange" if isinstance(node.iter, ast.Call) and getattr(node.iter.func, "attr", "") == "ndrange" \
            else "This"
        raise SimgradSyntaxError(f"{what} for loop with number of the loop variables not equal to the dimension of "
                                 f"the {'ndrange' if what == 'Ndrange' else 'loop'} is not supported: it has {nd} "
                                 f"indices but {len(names)} loop variable(s)", comp.loc(node.target))

    def bind(idx):
        if grouped_:
            comp.bind(names[0], Matrix(idx))
        else:
            for name, v in zip(names, idx):
                comp.bind(name, v)

    return bind


def active_cells_loop(comp, cells: SNode, offset, body) -> None:
    """Loops over the active cells of `cells`, calling `body(indices)` inside: nested loops down the SNode
    path, one per run of levels that ends at a sparse node, each entered only where that node's cell is
    active (a dynamic node's loop runs to its list's length). The outermost loop (the levels down to the
    first sparse node, flattened) is the parallel one; the indices are built digit by digit in `cells`'
    index space."""
    axes = sorted({a for n in cells.path() for a in n.axes})
    groups: list[list[SNode]] = [[]]
    for n in cells.path()[1:]:
        if n.kind == "dynamic" and groups[-1]:
            groups.append([])
        groups[-1].append(n)
        if n.is_sparse:
            groups.append([])
    if not groups[-1]:
        groups.pop()

    def bind(coords):
        idx = [coords[a] for a in axes]
        if offset:
            idx = [operators.add(i, o) for i, o in zip(idx, offset)]
        if all(isinstance(i, Expr) and i.stmt.op is not Op.CONST for i in idx):
            for k, i in enumerate(idx):  # the cell's indices: each iteration owns its cell (parallel_strategy)
                i.stmt.attrs["cell_index"] = k
        body(idx)

    def level(k: int, coords: dict) -> None:
        if k == len(groups):
            bind(coords)
            return
        group = groups[k]
        if group[0].kind == "dynamic":
            dyn = group[0]
            ax = dyn.axes[0]
            base = {a: operators.mul(v, dyn.sizes[0]) if a == ax else v for a, v in coords.items()}
            base.setdefault(ax, 0)
            count = _node_op("length", dyn, base, axes)

            def inner(i):
                level(k + 1, {**base, ax: operators.add(base[ax], i)})

            _emit_loop(comp, 0, count, inner)
            return
        digits = [(n, a, size) for n in group for a, size in zip(n.axes, n.sizes)]
        total = 1
        for _n, _a, size in digits:
            total *= size

        def cell_coords(flat) -> dict:
            new = dict(coords)
            rest = flat
            values: list = []
            for _n, _a, size in reversed(digits):
                values.append(_raw(Op.RAW_MOD, rest, size) if len(values) < len(digits) - 1 else rest)
                rest = _raw(Op.RAW_DIV, rest, size)
            values.reverse()
            for (_n, a, size), v in zip(digits, values):
                new[a] = operators.add(operators.mul(new[a], size), v) if a in new else v
            return new

        if k == 0 and group[-1].is_sparse and _is_top(comp):
            _listed_loop(comp, group[-1], total, cell_coords, axes, lambda new: level(1, new))
            return

        def body(flat):
            new = cell_coords(flat)
            last = group[-1]
            if not last.is_sparse:
                level(k + 1, new)
                return
            with _if_active(comp, last, new, axes):
                level(k + 1, new)

        _emit_loop(comp, 0, total, body)

    level(0, {})


def _node_op(op: str, node: SNode, coords: dict, axes: list) -> Expr:
    """ti.<op>(node, ...) at the struct-for's coordinates so far (those of node's axes), as i32."""
    from simgrad.lang import sparse

    return sparse._emit(op, node, [operators.cast_expr(operators.to_expr(coords[a], dt.i32), dt.i32) for a in axes
                                   if a in coords])


def _if_active(comp, node: SNode, coords: dict, axes: list):
    """Emit `if ti.is_active(node, coords):` and return the context in which its body is emitted."""
    active = _node_op("is_active", node, coords, axes)
    guard = comp.builder.emit(Op.IF, None, (operators.ne(active, 0).stmt,), nblocks=2)
    return comp.dynamic(guard.blocks[0])


def _is_top(comp) -> bool:
    """Whether a loop emitted now is a kernel's top-level (parallel) loop; as in _emit_loop."""
    return comp.depth == 0 and not comp.loop_stack and not any(f.real for f in comp.frames)


def _listed_loop(comp, node: SNode, total: int, cell_coords, axes, inner) -> None:
    """The outermost loop of a top-level sparse struct-for, as Taichi runs it: a pass lists the active cells
    of `node` (the first sparse node, with its dense ancestors flattened; serial, or parallel with
    `comp.parallel_listgen`), then the parallel loop runs over that list. Cells the loop activates itself (an
    adjoint's scatter into neighbours) are not visited, and the parallel loop does no work for inactive cells."""
    from simgrad.lang import sparse
    from simgrad.runtime.sparse import MAX_LISTS

    lists = comp.__dict__.setdefault("sparse_lists", {})
    list_id = lists.get(id(node), 0)
    if list_id >= MAX_LISTS:
        from simgrad.ir import context

        raise SimgradSyntaxError(f"more than {MAX_LISTS} struct-fors over one sparse node in a kernel",
                                 context.current_loc())
    lists[id(node)] = list_id + 1
    b = comp.builder
    count = b.emit(Op.ALLOCA, dt.i32)
    b.emit(Op.LOCAL_STORE, None, (count, b.const(0, dt.i32)))
    ref = sparse.snode_ref(node)

    def scan(flat):
        with _if_active(comp, node, cell_coords(flat), axes):
            bb = comp.builder
            one = bb.const(1, dt.i32)
            if comp.parallel_listgen:  # each active cell takes the next entry
                n = bb.emit(Op.ATOMIC, dt.i32, (count, one), {"kind": "add"})
            else:
                n = bb.emit(Op.LOCAL_LOAD, dt.i32, (count,))
                bb.emit(Op.LOCAL_STORE, None, (count, bb.binary(Op.ADD, n, one)))
            bb.emit(Op.SNODE_OP, dt.i32, (n, flat.stmt), {"op": "list_set", "snode": ref, "list": list_id})

    user_config, comp.next_loop_config = comp.next_loop_config, {"serialize": not comp.parallel_listgen,
                                                                 "listgen": True}
    _emit_loop(comp, 0, total, scan)
    n = Expr(comp.builder.emit(Op.LOCAL_LOAD, dt.i32, (count,)))
    comp.next_loop_config = user_config  # ti.loop_config(...) meant the loop over the cells

    def body(k):
        k.stmt.attrs["cells"] = len(axes)  # a struct-for: its cell_index statements name distinct cells
        flat = Expr(comp.builder.emit(Op.SNODE_OP, dt.i32, (k.stmt,), {"op": "list_get", "snode": ref,
                                                                         "list": list_id}))
        inner(cell_coords(flat))

    _emit_loop(comp, 0, n, body)


def _shape_of(comp, target, node):
    if isinstance(target, Field):
        target._ensure()
        return list(target.shape)
    if _is_array(target):
        return [target.shape_expr(k) for k in range(target.ndim)]
    raise SimgradSyntaxError(f"ti.grouped() expects a field or ti.ndrange, got {type(target).__name__}",
                             comp.loc(node))


class StaticJump(Exception):
    """A break/continue met directly in a ti.static loop's body (no run-time loop or if in between):
    it ends the unrolling, or this unrolled iteration, at compile time."""

    def __init__(self, is_break: bool):
        self.is_break = is_break


def _unroll(comp, node: ast.For) -> None:
    seq = comp.eval(node.iter)
    frame = comp.frame
    comp.static_loops.append(comp.static_jump_target())
    try:
        with contextlib.ExitStack() as guards:
            for item in seq:
                returns = frame.dynamic_returns
                frame.scopes.append({})
                try:
                    if isinstance(node.target, ast.Name):
                        comp.bind(node.target.id, item)
                    else:
                        comp._bind_target(node.target, item)
                    comp.visit_block(node.body)
                except StaticJump as jump:
                    if jump.is_break:
                        break
                finally:
                    frame.scopes.pop()
                if frame.dynamic_returns != returns:  # this iteration may have returned: guard the next ones
                    guards.enter_context(comp.unless_returned())
    finally:
        comp.static_loops.pop()


_I32_MAX = (1 << 31) - 1


def _index_type(*vals) -> dt.DataType:
    """i32 as in Taichi, i64 when a bound needs it (a 64-bit value, or a count beyond 2**31 - 1)."""
    for v in vals:
        if isinstance(v, Expr) and v.dtype in (dt.i64, dt.u64):
            return dt.i64
        if isinstance(v, int) and not -_I32_MAX - 1 <= v <= _I32_MAX:
            return dt.i64
    return dt.i32


def _emit_loop(comp, begin, end, body) -> None:
    """One RANGE_FOR over [begin, end); parallel when it is the outermost loop of the kernel. `body(i)`
    binds the loop index and emits the loop's body."""
    cfg = comp.next_loop_config or {}
    comp.next_loop_config = None
    t = _index_type(begin, end)
    b = operators.cast_expr(operators.to_expr(begin, t), t)
    e = operators.cast_expr(operators.to_expr(end, t), t)
    top = comp.depth == 0 and not comp.loop_stack and not any(f.real for f in comp.frames)
    parallel = top and not cfg.get("serialize", False)
    attrs = {"parallel": parallel, "top": top}
    if cfg.get("block_dim"):
        attrs["block_dim"] = cfg["block_dim"]
    if cfg.get("vectorize") and not parallel:
        attrs["vectorize"] = True  # (codegen/llvm.py: llvm.loop.vectorize.enable)
    if cfg.get("listgen"):
        attrs["listgen"] = True  # lists a struct-for's cells: forward code even when parallel (autodiff/reverse.py)
    loop = comp.builder.emit(Op.RANGE_FOR, t, (b.stmt, e.stmt), attrs, nblocks=1)
    comp.loop_stack.append("parallel" if parallel else "serial")
    try:
        with comp.dynamic(loop.blocks[0]):
            body(Expr(loop))
    finally:
        comp.loop_stack.pop()


def _visit(comp, node, bind):
    """The loop body of a `for` statement: bind the target names, then visit the statements. A name already
    declared in the function is refused as a loop variable (Taichi's rule: the loop would shadow it)."""
    targets = node.target.elts if isinstance(node.target, (ast.Tuple, ast.List)) else [node.target]
    for t in targets:
        if isinstance(t, ast.Name) and any(t.id in scope for scope in comp.frame.scopes):
            raise SimgradSyntaxError(f"Variable '{t.id}' is already declared in the outer scope and cannot be used "
                                     "as loop variable", comp.loc(t))

    def body(i):
        bind(i)
        comp.visit_block(node.body)

    return body


def _range_for(comp, node, r) -> None:
    if not isinstance(node.target, ast.Name):
        raise SimgradSyntaxError("a range-for takes one loop variable", comp.loc(node.target))
    name = node.target.id
    if r.step == 1:
        _emit_loop(comp, r.start, r.stop, _visit(comp, node, lambda i: comp.bind(name, i)))
        return
    step = r.step
    count = operators.floordiv(operators.sub(r.stop, r.start) + (step - 1 if step > 0 else step + 1), step)
    count = operators.max(count, 0)
    _emit_loop(comp, 0, count,
               _visit(comp, node, lambda k: comp.bind(name, operators.add(r.start, operators.mul(k, step)))))


def _nd_for(comp, node, bounds, grouped_: bool) -> None:
    _nd_loop(comp, bounds, _visit(comp, node, _binder(comp, node, len(bounds), grouped_)))


def _nd_loop(comp, bounds, body) -> None:
    """One flat loop over the box `bounds` ((begin, end) per axis); `body(indices)` emits the body. The
    flat index is i64 when the count exceeds i32 (ti.ndrange(70000, 70000)); the indices stay i32."""
    nd = len(bounds)
    extents = [operators.max(operators.sub(e, b), 0) if isinstance(e, Expr) or isinstance(b, Expr) else max(e - b, 0)
               for b, e in bounds]
    total = _count(extents)

    def flat_body(flat):
        idx = []
        rest = flat
        for k in range(nd - 1, -1, -1):
            if k == 0:
                digit = rest
            else:
                digit = _raw(Op.RAW_MOD, rest, extents[k])
                rest = _raw(Op.RAW_DIV, rest, extents[k])
            if isinstance(digit, Expr) and digit.dtype is dt.i64 and _fits_i32(extents[k]):
                digit = operators.cast_expr(digit, dt.i32)
            idx.append(operators.add(digit, bounds[k][0]) if not _is_zero(bounds[k][0]) else digit)
        idx.reverse()
        body(idx)

    _emit_loop(comp, 0, total, flat_body)


def _fits_i32(n) -> bool:
    return n <= _I32_MAX if isinstance(n, int) else n.dtype is dt.i32


def _count(extents):
    """The product of the extents. Known ones multiply in Python; run-time i32 ones multiply in i64 and
    a located check refuses a count beyond i32 rather than wrapping (the loop would run a wrong count)."""
    if len(extents) == 1 or all(isinstance(n, int) for n in extents):
        total = 1
        for n in extents:
            total = operators.mul(total, n)
        return total
    total = operators.to_expr(1, dt.i64)
    for n in extents:
        total = operators.mul(total, operators.cast_expr(operators.to_expr(n, dt.i64), dt.i64))
    if not all(_fits_i32(n) for n in extents):
        return total  # a 64-bit extent: a 64-bit loop
    from simgrad.ir import context

    context.builder().emit(Op.ASSERT, None, (operators.le(total, _I32_MAX).stmt,), {
        "message": "the loop's iteration count (the product of its extents) exceeds 2**31 - 1; give the "
                   "bounds an i64 type"})
    return operators.cast_expr(total, dt.i32)


def _raw(op: Op, a: Expr, n):
    from simgrad.ir import context

    if isinstance(n, int) and n == 1:
        return a if op is Op.RAW_DIV else operators.to_expr(0, a.dtype)
    n = operators.cast_expr(operators.to_expr(n, a.dtype), a.dtype)
    return Expr(context.builder().binary(op, a.stmt, n.stmt))


def _is_zero(v) -> bool:
    return isinstance(v, int) and v == 0


def _target_names(comp, target) -> list[str]:
    if isinstance(target, ast.Name):
        return [target.id]
    if isinstance(target, ast.Tuple):
        names = [e.id for e in target.elts if isinstance(e, ast.Name)]
        if len(names) == len(target.elts):
            return names
    raise SimgradSyntaxError("loop variables must be plain names", comp.loc(target))


def emit_fill(field, value) -> None:
    """`x.fill(v)` inside a kernel: one loop over all elements, storing `v` (a scalar broadcast to every
    entry, or a vector/matrix of the field's entry shape). Emitted into the kernel, so it runs at every
    launch and `v` may be a run-time value; at the top level of a kernel the loop is parallel."""
    from simgrad.frontend.refs import GlobalRef, MatrixRef
    from simgrad.ir import context
    from simgrad.lang.field import MatrixField

    comp = context.current()
    field._ensure()
    if isinstance(value, (list, tuple)):
        value = Matrix(list(value))
    if isinstance(value, Matrix) and not isinstance(field, MatrixField):
        raise SimgradSyntaxError(f"fill: field {field.name} holds scalars, got a {value.shape} matrix",
                                 context.current_loc())
    comps = field._components()

    def body(idx):
        idx = [operators.cast_expr(operators.to_expr(i, dt.i32), dt.i32) for i in idx]
        refs = [GlobalRef(c, idx, c.dtype) for c in comps]
        if isinstance(field, MatrixField):
            MatrixRef(refs, field.n, field.ncols).store(value)
        else:
            refs[0].store(value)

    cells = field._components()[0].snode.parent()
    if cells is not None and getattr(cells, "has_sparse_path", lambda: False)():
        active_cells_loop(comp, cells, None, body)  # as in Python scope: the active cells only (raw indices)
        return
    _nd_loop(comp, [(0, n) for n in field.shape], body)
