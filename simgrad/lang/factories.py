"""Field constructors (ti.field, ti.Vector.field, ti.Matrix.field) and `ti.root`."""

from __future__ import annotations

import linecache
import os
import re
import sys
from types import FrameType

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import SimgradRuntimeError, SimgradSyntaxError, SimgradValueError, caller_loc
from simgrad.lang import snode as sn
from simgrad.lang.field import Field, MatrixField, ScalarField
from simgrad.lang.program import get_program, require_init
from simgrad.lang.quant import is_quant
from simgrad.lang.types import MatrixType

_counter = [0]


_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
# frames between the user's call and _name: ti.field, ti.types..., ti.Vector.field/ti.Matrix.field (matrix.py)
_FACTORY_FILES = {__file__, *(os.path.join(os.path.dirname(__file__), f)
                              for f in ("types.py", "matrix.py", "struct.py"))}
_ASSIGNED = re.compile(r"^\s*([A-Za-z_][\w.]*)\s*(?::[^=]*)?=\s*[\w.]+\(")


def _name(name) -> tuple[str, bool]:
    """(name, whether a kernel may still rename it): the given name, else the variable the caller assigns
    the new field to (`x = ti.field(...)` names it `x`, as Taichi infers it), else field<N>."""
    if name:
        return name, False
    frame: FrameType | None = sys._getframe(1)
    while frame is not None and frame.f_code.co_filename in _FACTORY_FILES:
        frame = frame.f_back
    if frame is not None and not frame.f_code.co_filename.startswith(_PACKAGE):  # the user's own line
        m = _ASSIGNED.match(linecache.getline(frame.f_code.co_filename, frame.f_lineno))
        if m:
            return m.group(1), False
    _counter[0] += 1
    return f"field{_counter[0]}", True


def _check_shape(shape):
    """A shape of non-negative integers, refused (located at the caller) before numpy sees it."""
    if shape is None:
        return None
    dims = (shape,) if isinstance(shape, (int, np.integer)) else tuple(shape)
    for d in dims:
        if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 0:
            raise SimgradValueError(f"field shape must be non-negative integers, got {shape!r}", caller_loc())
    return tuple(int(d) for d in dims)


def _axes(ndim: int):
    return sn.axes(*range(ndim))


def _order(shape, order) -> list[int] | None:
    """The axes of `order` ("ji": axis j outermost in memory) checked as Taichi checks them; None: row-major."""
    if order is None:
        return None
    if shape is None:
        raise SimgradSyntaxError("shape cannot be None when order is set", caller_loc())
    if len(order) != len(shape):
        raise SimgradSyntaxError(f"The dimensionality of shape and order must be the same ({len(shape)} != "
                                 f"{len(order)})", caller_loc())
    if len(set(order)) != len(order):
        raise SimgradSyntaxError("The axes in order must be different", caller_loc())
    axes = [ord(ch) - ord("i") for ch in order]
    for ch, a in zip(order, axes):
        if not 0 <= a < len(shape):
            raise SimgradSyntaxError(f"Invalid axis {ch}", caller_loc())
    return axes


def _place_new(f: Field, shape, offset, needs_grad: bool, order=None, layout=None):
    """`ti.field(shape=...)`: its own SNode tree, dense over the shape, gradient beside it. With `order`, one dense
    node per axis, outermost first (Taichi's layout: `order="ji"` puts j outermost); with ti.Layout.SOA a
    vector/matrix field's entries each get their own node, one after another."""
    from simgrad.lang.types import Layout

    if offset is not None:
        if shape is None:
            raise SimgradSyntaxError("shape cannot be None when offset is set", caller_loc())
        off = (offset,) if isinstance(offset, int) else tuple(offset)
        if len(off) != len(shape):
            raise SimgradSyntaxError(f"The dimensionality of shape and offset must be the same: shape {shape}, "
                                     f"offset {off}", caller_loc())
    axes = _order(shape, order)
    if shape is None:
        f._needs_grad = needs_grad  # the user places it, and its gradient (or ti.root.lazy_grad() does)
        return _pending(f)  # to be placed by the user with ti.root...place()
    tree = sn.new_tree(get_program())

    def place(g: Field) -> None:
        for part in (g._components() if layout == Layout.SOA and isinstance(g, MatrixField) else [g]):
            if axes is None:
                node = tree.root.dense(_axes(len(shape)), shape) if shape else tree.root
            else:
                node = tree.root
                for a in axes:
                    node = node.dense(sn.axes(a), shape[a])
            node.place(part, offset=offset)

    place(f)
    f._needs_grad = needs_grad  # after placing: the gradient gets its own dense node (Taichi's layout)
    dual = getattr(f, "_needs_dual", False)
    for wanted, g in ((needs_grad, f.grad), (dual, getattr(f, "dual", None)),
                      (needs_grad and dual, getattr(f.grad, "dual", None) if f.grad is not None else None)):
        if wanted and g is not None and g.snode is None:
            place(g)
    return f


class Pending:
    """A field made without a shape, until the next kernel compile checks it as Taichi's materialisation does
    (lang/program.py check_pending_fields): where it was made, and what may be missing."""

    HEADERS = {
        "field": "These field(s) are not placed:",
        "grad": "These field(s) requrie `needs_grad=True`, however their grad field(s) are not placed:",
        "dual": "These field(s) requrie `needs_dual=True`, however their dual field(s) are not placed:",
        "shape": "Members of the following field have different shapes:",
    }
    HINTS = {
        "field": "Place them (ti.root.dense(ti.i, n).place(x)) or give them a shape: x = ti.field(float, shape=(2, 3))",
        "grad": "Place the gradients (ti.root.dense(ti.i, n).place(x.grad), or ti.root.lazy_grad()) or give the "
                "fields a shape: x = ti.field(float, shape=(2, 3), needs_grad=True)",
        "dual": "Place the duals (ti.root.dense(ti.i, n).place(x.dual), or ti.root.lazy_dual()) or give the "
                "fields a shape: x = ti.field(float, shape=(2, 3), needs_dual=True)",
        "shape": "Place every entry of a vector/matrix field under nodes of one shape",
    }

    def __init__(self, f: Field):
        self.field = f
        self.loc = caller_loc()

    def _comps(self) -> list:
        return [c for p in self.field.placeable() for c in p._components()]

    def problem(self, kind: str) -> bool:
        comps = self._comps()
        if kind == "field":
            return any(c.snode is None for c in comps)
        if kind == "grad":
            return any(getattr(p, "_needs_grad", False) and c.grad is not None and c.grad.snode is None
                       for p in self.field.placeable() for c in p._components())
        if kind == "dual":
            return any(getattr(p, "_needs_dual", False) and getattr(getattr(c, "dual", None), "snode", 0) is None
                       for p in self.field.placeable() for c in p._components())
        return any(isinstance(p, MatrixField) and len({c.shape for c in p._components()}) > 1
                   for p in self.field.placeable())

    def message(self, kind: str, bad: list) -> str:
        lines = [self.HEADERS[kind]]
        for p in bad:
            where = f" (made at {p.loc})" if p.loc is not None else ""
            shapes = f" {[c.shape for c in p._comps()]}" if kind == "shape" else ""
            lines.append(f"  {p.field.name}{shapes}{where}")
        return "\n".join(lines + [self.HINTS[kind]])


def _pending(f):
    get_program().pending_fields.append(Pending(f))
    return f


def _with_grad(make, needs_grad: bool, needs_dual: bool = False):
    """Every real field carries an (unplaced) gradient field, placed by needs_grad or ti.root.lazy_grad()."""
    f = make("")
    if not f.dtype.is_float:
        if needs_grad or needs_dual:  # was an AttributeError on the missing gradient (Taichi refuses it too)
            raise SimgradRuntimeError(f"{f.dtype} is not supported for field with `needs_grad=True` or "
                                      "`needs_dual=True`. (Gradients need a floating-point type.)")
        return f
    grad = _companion(make, f, ".grad", "grad")
    # and an (unplaced) dual for forward mode, placed by needs_dual or ti.root.lazy_dual()
    _companion(make, f, ".dual", "dual")
    # the gradient's own dual: forward mode over an adjoint (Hessian-vector products) writes d(grad) there
    _companion(make, grad, ".grad.dual", "dual")
    f._needs_dual = needs_dual
    return f


def _companion(make, of: Field, suffix: str, attr: str) -> Field:
    """A gradient or dual field of `of` (`attr` "grad" or "dual"), linked to it component by component."""
    made = make(suffix)
    dual = attr == "dual"
    for c, d in zip(of._components(), made._components()):
        setattr(c, attr, d)
        d.is_primal, d.is_dual = False, dual
    made.is_primal, made.is_dual = False, dual
    setattr(of, attr, made)
    return made


def field(dtype, shape=None, name: str = "", offset=None, needs_grad: bool = False, needs_dual: bool = False,
          order=None, layout=None):
    from simgrad.lang.types import MatrixType

    require_init("field")
    if isinstance(dtype, MatrixType):
        return _matrix_field(dtype.n, dtype.m, dtype.dtype, shape, name, offset, needs_grad, needs_dual, order,
                             layout)
    if is_quant(dtype):
        return _quant_field(lambda base: ScalarField(dtype.compute, base), [dtype], shape, name, needs_grad,
                            needs_dual)
    t = dt.from_any(dtype)
    shape = _check_shape(shape)
    base, auto = _name(name)
    f = _with_grad(lambda suffix: ScalarField(t, base + suffix), needs_grad, needs_dual)
    f._auto_name = auto
    return _place_new(f, shape, offset, needs_grad, order)


def _quant_field(make, qtypes: list, shape, name, needs_grad: bool, needs_dual: bool) -> Field:
    """A field of ti.types.quant types (lang/quant.py; one per component): computes in their compute type,
    placed by the user in a ti.BitpackedFields or under ti.root.quant_array. No gradient (as in Taichi)."""
    what = repr(qtypes[0]) if len(set(qtypes)) == 1 else "[" + ", ".join(map(repr, qtypes)) + "]"
    if needs_grad or needs_dual:
        raise SimgradRuntimeError(f"a field of quant type {what} cannot have needs_grad=True or needs_dual=True: "
                                  "quantized values are not differentiated (as in Taichi)", caller_loc())
    if shape is not None:
        raise SimgradSyntaxError(f"a field of quant type {what} takes no shape: place it in a "
                                 "ti.BitpackedFields or under ti.root.quant_array(...)", caller_loc())
    base, auto = _name(name)
    f = make(base)
    comps = f._components()
    for c, q in zip(comps, qtypes * len(comps) if len(qtypes) == 1 else qtypes):
        c.quant_type = q
    f.quant_type = qtypes[0]
    f._auto_name = auto
    f._needs_grad = False
    return _pending(f)


def _entry_types(n: int, m: int, dtype) -> tuple[list, dt.DataType]:
    """`ti.Matrix.field(n, m, dtype=[[...], ...])`: one type per entry (quant types, say), all of one compute
    type as Taichi requires; returns (entry types, compute type)."""
    flat: list = []

    def walk(x):
        for t in x:
            if isinstance(t, (list, tuple)):
                walk(t)
            else:
                flat.append(t)

    walk(dtype)
    if len(flat) != n * max(m, 1):
        raise SimgradValueError(f"a matrix field of {n}x{max(m, 1)} entries got {len(flat)} entry types", caller_loc())
    computes = {t.compute if is_quant(t) else dt.from_any(t) for t in flat}
    if len(computes) != 1 or len({is_quant(t) for t in flat}) != 1:
        raise SimgradRuntimeError("Member fields of a matrix field must have the same compute type", caller_loc())
    return flat, computes.pop()


def _matrix_field(n, m, dtype, shape, name, offset, needs_grad, needs_dual, order=None, layout=None):
    require_init("field")
    if isinstance(dtype, (list, tuple)):
        types, compute = _entry_types(n, m, dtype)
        if not is_quant(types[0]):
            return _matrix_field(n, m, compute, shape, name, offset, needs_grad, needs_dual, order, layout)
        return _quant_field(lambda base: MatrixField(n, m, compute, base), types, shape, name, needs_grad,
                            needs_dual)
    if is_quant(dtype):
        return _quant_field(lambda base: MatrixField(n, m, dtype.compute, base), [dtype], shape, name, needs_grad,
                            needs_dual)
    t = dt.from_any(dtype) if dtype is not None else dt.Defaults.fp
    shape = _check_shape(shape)
    base, auto = _name(name)
    f = _with_grad(lambda suffix: MatrixField(n, m, t, base + suffix), needs_grad, needs_dual)
    f._auto_name = auto
    return _place_new(f, shape, offset, needs_grad, order, layout)


def vector_field(n, dtype=None, shape=None, order=None, name="", offset=None, needs_grad=False,
                 needs_dual=False, layout=None):
    _check_layout(layout)
    return _matrix_field(n, 0, dtype, shape, name, offset, needs_grad, needs_dual, order, layout)


def matrix_field(n, m, dtype=None, shape=None, order=None, name="", offset=None, needs_grad=False,
                 needs_dual=False, layout=None):
    _check_layout(layout)
    return _matrix_field(n, m, dtype, shape, name, offset, needs_grad, needs_dual, order, layout)


def _check_layout(layout) -> None:
    """ti.Layout.AOS or SOA: where a vector's components sit in memory (side by side, or one array each: a field
    made with a shape places them so, lang/factories.py _place_new). Values and indexing are the same either way."""
    from simgrad.lang.types import Layout

    if layout is not None and not isinstance(layout, Layout):
        raise SimgradValueError(f"layout must be ti.Layout.AOS or ti.Layout.SOA, got {layout!r}", caller_loc())


class _Root:
    """`ti.root`: forwards to the root of the tree currently being built."""

    def __getattr__(self, name):
        return getattr(sn.root_tree(get_program()).root, name)

    def lazy_grad(self) -> None:
        """Place the gradient of every float field not yet in memory, beside its primal: the fields under
        ti.root and those made by ti.field(shape=...) (their own trees here; under ti.root in Taichi)."""
        for tree in get_program().trees:
            if not tree.materialized:
                tree.root.lazy_grad()

    def lazy_dual(self) -> None:
        """Place the dual (forward-mode tangent) of every float field not yet in memory, beside its primal."""
        for tree in get_program().trees:
            if not tree.materialized:
                tree.root.lazy_dual()

    def deactivate_all(self) -> None:
        """Every sparse cell of every tree (Taichi warns that this is what ti.root.deactivate_all() does)."""
        from simgrad.lang.sparse import deactivate_all_snodes

        deactivate_all_snodes()

    def __repr__(self):
        return "ti.root"


root = _Root()


class FieldsBuilder:
    """`ti.FieldsBuilder()`: an explicit SNode tree; `finalize()` materialises it."""

    def __init__(self):
        self.tree = sn.new_tree(require_init("a FieldsBuilder"))
        self.root = self.tree.root

    def dense(self, indices, dimensions):
        return self.root.dense(indices, dimensions)

    def pointer(self, indices, dimensions):
        return self.root.pointer(indices, dimensions)

    def bitmasked(self, indices, dimensions):
        return self.root.bitmasked(indices, dimensions)

    def quant_array(self, indices, dimensions, max_num_bits):
        return self.root.quant_array(indices, dimensions, max_num_bits)

    def dynamic(self, index, dimension, chunk_size=None):
        return self.root.dynamic(index, dimension, chunk_size)

    def place(self, *fields, offset=None):
        return self.root.place(*fields, offset=offset)

    def lazy_grad(self):
        self.root.lazy_grad()

    def lazy_dual(self):
        self.root.lazy_dual()

    def finalize(self, raise_warning=True):
        self.tree.materialize()
        return self.tree


def _struct_member(t, name: str, needs_grad: bool, needs_dual: bool) -> Field:
    from simgrad.lang.struct import StructType

    if isinstance(t, StructType):
        return _struct_field(t, name, needs_grad, needs_dual)
    is_float = (t.dtype if isinstance(t, MatrixType) else t).is_float
    # unlike Taichi, a struct's integer members are allowed beside needs_grad=True: they get no gradient
    grad, dual = needs_grad and is_float, needs_dual and is_float
    if isinstance(t, MatrixType):
        f = _with_grad(lambda suffix: MatrixField(t.n, t.m, t.dtype, name + suffix), grad, dual)
    else:
        f = _with_grad(lambda suffix: ScalarField(t, name + suffix), grad, dual)
    f._needs_grad = grad  # placed beside its member (place() does it)
    f._needs_dual = dual
    return f


def _struct_field(stype, name: str, needs_grad: bool, needs_dual: bool):
    from simgrad.lang.struct import StructField

    members = {k: _struct_member(t, f"{name}.{k}", needs_grad, needs_dual) for k, t in stype.members.items()}
    return StructField(stype, members, name)


def place_struct_field(stype, shape, name, offset, needs_grad: bool, needs_dual: bool):
    """`Type.field(shape=...)`: every member in one dense node of its own tree (Taichi places a struct's
    members together), gradients beside them; without a shape the user places it with ti.root."""
    require_init("field")
    shape = _check_shape(shape)
    base, auto = _name(name)
    f = _struct_field(stype, base, needs_grad, needs_dual)
    f._auto_name = auto
    if shape is None:
        return _pending(f)
    tree = sn.new_tree(get_program())
    node = tree.root.dense(_axes(len(shape)), shape) if shape else tree.root
    node.place(f, offset=offset)
    node.place_companions(f.placeable(), offset)
    return f
