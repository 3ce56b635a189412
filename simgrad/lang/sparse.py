"""SNode operations as Taichi names them: ti.activate / deactivate / is_active / append / length inside
kernels (each emits one SNODE_OP that passes/lower_access.py expands), deactivate_all in Python scope (a
compiled struct-for over the node, lang/scope_hooks.py), and ti.get_addr (an element's address)."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.errors import SimgradError, SimgradSyntaxError, caller_loc
from simgrad.ir import context
from simgrad.ir.fieldref import SNodeRef
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.snode import SNode


def _node(x, what: str) -> SNode:
    """An SNode argument: the node itself, or a field (Taichi accepts `x` for `x.snode` in some places)."""
    from simgrad.lang.field import Field

    if isinstance(x, Field):
        x = x.snode
    if not isinstance(x, SNode):
        raise SimgradSyntaxError(f"ti.{what} expects an SNode (e.g. x.snode.parent()), got {type(x).__name__}",
                                 context.current_loc())
    return x


def snode_ref(node: SNode) -> SNodeRef:
    """The IR's record of a (materialised) SNode."""
    tree = node.tree
    assert tree is not None
    tree.materialize()
    if not isinstance(node._ref, SNodeRef):
        node._ref = SNodeRef(_name(node), tree.id, node.levels(), len(node.shape))
    return node._ref


def _name(node: SNode) -> str:
    fields = [n.field.name for n in node._walk() if n.kind == "place" and n.field is not None]
    return f"{node.kind}({', '.join(fields[:3])}{', ...' if len(fields) > 3 else ''})"


def _as_list(indices) -> list:
    """Indices as given: a vector, a list/tuple, or one scalar."""
    from simgrad.lang.matrix import Matrix

    if isinstance(indices, Matrix):
        return list(indices.entries)
    return list(indices) if isinstance(indices, (list, tuple)) else [indices]


def _indices(node: SNode, indices, what: str, dims: int) -> list[Expr]:
    indices = _as_list(indices)
    if len(indices) != dims:
        raise SimgradSyntaxError(f"ti.{what}: this {node.kind} node takes {dims} index(es), got {len(indices)}",
                                 context.current_loc())
    return [operators.cast_expr(operators.to_expr(i, dt.i32), dt.i32) for i in indices]


def _emit(op: str, node: SNode, idx: list[Expr]) -> Expr:
    if not node.is_sparse and op in ("activate", "deactivate"):
        return Expr(operators.to_expr(0, dt.i32).stmt)  # as Taichi: a dense cell is always active, nothing to do
    if not node.is_sparse:
        raise SimgradSyntaxError(f"ti.{_PUBLIC[op]} works on pointer, bitmasked and dynamic SNodes, not on a "
                                 f"{node.kind} node", context.current_loc())
    ref = snode_ref(node)
    return Expr(context.builder().emit(Op.SNODE_OP, dt.i32, tuple(i.stmt for i in idx), {"op": op, "snode": ref}))


_PUBLIC = {"activate": "activate", "deactivate": "deactivate", "is_active": "is_active", "length": "length",
           "append_slot": "append"}


def _in_kernel(what: str) -> None:
    if context.current() is None:
        raise SimgradError(f"ti.{what} can only be called inside a kernel (in Python scope use "
                           "snode.deactivate_all() or write the field)", caller_loc())


def activate(node, indices) -> None:
    """Activate the cell of `node` at `indices` (its own index space, e.g. block coordinates)."""
    _in_kernel("activate")
    n = _node(node, "activate")
    _emit("activate", n, _cell_indices(n, indices, "activate"))


def deactivate(node, indices) -> None:
    """Deactivate a cell: a pointer's block goes back to its pool zeroed, a bitmasked cell's bit is cleared
    (its data stays, as in Taichi), a dynamic list becomes empty."""
    _in_kernel("deactivate")
    n = _node(node, "deactivate")
    _emit("deactivate", n, _cell_indices(n, indices, "deactivate"))


def is_active(node, indices):
    _in_kernel("is_active")
    n = _node(node, "is_active")
    return _emit("is_active", n, _cell_indices(n, indices, "is_active"))


def _cell_indices(n: SNode, indices, what: str) -> list[Expr]:
    """The indices of a cell of `n`; a dynamic node's list may be named by its parent's indices alone."""
    if n.kind == "dynamic" and len(_as_list(indices)) == len(n.shape) - 1:
        return _list_indices(n, indices, what)
    return _indices(n, indices, what, len(n.shape))


def _list_axis(n: SNode) -> int:
    """Where a dynamic node's own axis sits among its indices."""
    return sorted({a for m in n.path() for a in m.axes}).index(n.axes[0])


def _list_indices(n: SNode, indices, what: str) -> list[Expr]:
    """A dynamic node's list is named by the indices of its parent's cell; its own axis is added as 0."""
    if n.kind != "dynamic":
        raise SimgradSyntaxError(f"ti.{what} works on dynamic SNodes, not on a {n.kind} node",
                                 context.current_loc())
    idx = _indices(n, indices, what, len(n.shape) - 1)
    ax = _list_axis(n)
    return idx[:ax] + [operators.to_expr(0, dt.i32)] + idx[ax:]


def length(node, indices):
    """The number of elements in a dynamic node's list."""
    _in_kernel("length")
    n = _node(node, "length")
    return _emit("length", n, _list_indices(n, indices, "length"))


def append(node, indices, value):
    """Append `value` to a dynamic list; returns the index it went to (the old length). An append past
    the node's size stores nothing (the length still counts it; ti.length reports at most the size)."""
    _in_kernel("append")
    n = _node(node, "append")
    idx = _list_indices(n, indices, "append")
    k = _emit("append_slot", n, idx)
    fields = [m.field for m in n.children if m.kind == "place" and m.field is not None and m.field.is_primal]
    values = _leaves(value)
    if len(values) != len(fields):
        raise SimgradSyntaxError(f"ti.append: this dynamic node holds {len(fields)} value(s) per element (the "
                                 f"fields placed under it), got {len(values)}", context.current_loc())
    ax = _list_axis(n)
    full = idx[:ax] + [k] + idx[ax + 1:]
    b = context.builder()
    guard = b.emit(Op.IF, None, (operators.lt(k, n.sizes[0]).stmt,), nblocks=2)
    with context.current().dynamic(guard.blocks[0]):
        for field, v in zip(fields, values):
            ptr = b.emit(Op.GLOBAL_PTR, field.dtype, tuple(i.stmt for i in full), {"target": field.ref()})
            value = operators.cast_expr(operators.to_expr(v, field.dtype), field.dtype)
            b.emit(Op.GLOBAL_STORE, None, (ptr, value.stmt))
    return k


def _leaves(value) -> list:
    """The scalars of an appended value in placement order: a struct's members, a matrix's entries."""
    from simgrad.lang.matrix import Matrix
    from simgrad.lang.struct import Struct

    if isinstance(value, Struct):
        return [leaf for _k, v in value.items() for leaf in _leaves(v)]
    if isinstance(value, Matrix):
        return list(value.entries)
    return [value]


class DynamicList:
    """`w[i]` of a field under a dynamic node, indexed by its parent's indices: the list's methods."""

    def __init__(self, node: SNode, indices: list):
        self.node, self.indices = node, list(indices)

    def load(self):  # the frontend loads what a subscript names; the list is its own value
        return self

    def append(self, value):
        return append(self.node, self.indices, value)

    def length(self):
        return length(self.node, self.indices)

    def deactivate(self):
        return deactivate(self.node, self.indices)


def deactivate_all_snodes() -> None:
    """Deactivate every cell of every sparse node of the program (Taichi's ti.deactivate_all_snodes)."""
    from simgrad.lang.program import get_program

    for tree in get_program().trees:
        tree.root.deactivate_all()


def get_addr(f, indices):
    """The address (u64) of the element of field `f` (or of its place SNode, `f.snode`) at `indices`, in
    this process's memory (a device address on the GPU): differences between addresses show the layout."""
    from simgrad.lang.field import Field, ScalarField

    if context.current() is None:
        raise SimgradError("ti.get_addr can only be called inside a kernel", caller_loc())
    node = f.snode if isinstance(f, Field) else f
    field = node.field if isinstance(node, SNode) and node.kind == "place" else None
    if not isinstance(field, ScalarField):
        raise SimgradSyntaxError(f"ti.get_addr expects a scalar field or its place SNode (x.snode), got "
                                 f"{type(f).__name__}", context.current_loc())
    field.check_alive(context.current_loc())
    idx = _indices(node, indices, "get_addr", len(field.shape))
    if field.offset:
        idx = [operators.sub(i, o) for i, o in zip(idx, field.offset)]
    b = context.builder()
    ptr = b.emit(Op.GLOBAL_PTR, field.dtype, tuple(i.stmt for i in idx), {"target": field.ref()})
    return Expr(b.emit(Op.BITCAST, dt.u64, (ptr,)))
