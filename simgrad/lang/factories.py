"""Field constructors (ti.field, ti.Vector.field, ti.Matrix.field) and `ti.root`."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.errors import SimgradRuntimeError
from simgrad.lang import snode as sn
from simgrad.lang.field import Field, MatrixField, ScalarField
from simgrad.runtime.program import get_program

_counter = [0]


def _name(name):
    if name:
        return name
    _counter[0] += 1
    return f"field{_counter[0]}"


def _axes(ndim: int):
    return sn.axes(*range(ndim))


def _place_new(f: Field, shape, offset, needs_grad: bool):
    """`ti.field(shape=...)`: its own SNode tree, dense over the shape, gradient beside it."""
    if shape is None:
        f._needs_grad = needs_grad  # place() puts the gradient beside it, as Taichi's lazy_grad does
        return f  # to be placed by the user with ti.root...place()
    tree = get_program().new_tree()
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    node = tree.root.dense(_axes(len(shape)), shape) if shape else tree.root
    node.place(f, offset=offset)
    f._needs_grad = needs_grad  # after placing: the gradient gets its own dense node (Taichi's layout)
    if needs_grad and f.grad is not None and f.grad.snode is None:
        gnode = tree.root.dense(_axes(len(shape)), shape) if shape else tree.root
        gnode.place(f.grad, offset=offset)
    return f


def _with_grad(make, needs_grad: bool, needs_dual: bool = False):
    """Every real field carries an (unplaced) gradient field, placed by needs_grad or ti.root.lazy_grad()."""
    f = make("")
    if not f.dtype.is_float:
        if needs_grad or needs_dual:  # was an AttributeError on the missing gradient (Taichi refuses it too)
            raise SimgradRuntimeError(f"{f.dtype} is not supported for a field with needs_grad=True or "
                                      "needs_dual=True: gradients need a floating-point type")
        return f
    f.grad = make(".grad")
    for c, g in zip(f._components(), f.grad._components()):
        c.grad = g
        g.is_primal = False
    f.grad.is_primal = False
    if needs_dual:
        f.dual = make(".dual")
        for c, d in zip(f._components(), f.dual._components()):
            c.dual = d
    return f


def field(dtype, shape=None, name: str = "", offset=None, needs_grad: bool = False, needs_dual: bool = False,
          order=None, layout=None):
    from simgrad.lang.types import MatrixType

    if isinstance(dtype, MatrixType):
        return _matrix_field(dtype.n, dtype.m, dtype.dtype, shape, name, offset, needs_grad, needs_dual)
    t = dt.from_any(dtype)
    base = _name(name)
    f = _with_grad(lambda suffix: ScalarField(t, base + suffix), needs_grad, needs_dual)
    f._auto_name = not name
    return _place_new(f, shape, offset, needs_grad)


def _matrix_field(n, m, dtype, shape, name, offset, needs_grad, needs_dual):
    t = dt.from_any(dtype) if dtype is not None else dt.Defaults.fp
    base = _name(name)
    f = _with_grad(lambda suffix: MatrixField(n, m, t, base + suffix), needs_grad, needs_dual)
    f._auto_name = not name
    return _place_new(f, shape, offset, needs_grad)


def vector_field(n, dtype=None, shape=None, name="", offset=None, needs_grad=False, needs_dual=False, **kw):
    return _matrix_field(n, 0, dtype, shape, name, offset, needs_grad, needs_dual)


def matrix_field(n, m, dtype=None, shape=None, name="", offset=None, needs_grad=False, needs_dual=False, **kw):
    return _matrix_field(n, m, dtype, shape, name, offset, needs_grad, needs_dual)


class _Root:
    """`ti.root`: forwards to the root of the tree currently being built."""

    def __getattr__(self, name):
        return getattr(get_program().root_tree.root, name)

    def __repr__(self):
        return "ti.root"


root = _Root()


class FieldsBuilder:
    """`ti.FieldsBuilder()`: an explicit SNode tree; `finalize()` materialises it."""

    def __init__(self):
        self.tree = get_program().new_tree()
        self.root = self.tree.root

    def dense(self, indices, dimensions):
        return self.root.dense(indices, dimensions)

    def place(self, *fields, offset=None):
        return self.root.place(*fields, offset=offset)

    def lazy_grad(self):
        self.root.lazy_grad()

    def finalize(self, raise_warning=True):
        self.tree.materialize()
        return self.tree
