"""How a kernel under compilation sees an ndarray parameter (a numpy array or CPU torch tensor passed by
reference, any dtype/ndim): each component of its elements is an ir.ArrayRef, the target of GLOBAL_PTRs;
its shape is read at run time."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.errors import SimgradTypeError
from simgrad.frontend.refs import GlobalRef, MatrixRef
from simgrad.ir import context
from simgrad.ir.fieldref import ArrayRef
from simgrad.ir.ops import Op
from simgrad.lang import ops
from simgrad.lang.expr import Expr


class ArrayArg:
    """How a kernel sees an ndarray parameter while it is compiled."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, ndim: int, element_shape: tuple = (),
                 boundary: str = "unsafe", grad: bool = False):
        self.boundary = boundary
        self.name, self.slot, self.dtype, self.ndim = name, slot, dtype, ndim
        self.element_shape = element_shape
        count = ArrayRef(name, slot, dtype, ndim, element_shape).num_components
        # with a gradient, its base pointer takes the slot after the extents (which it shares)
        self.grad_slot = slot + 1 + ndim if grad else -1
        self.comps = [ArrayRef(name, slot, dtype, ndim, element_shape, c,
                               grad=ArrayRef(f"{name}.grad", self.grad_slot, dtype, ndim, element_shape, c,
                                             shape_slot=slot) if grad else None)
                      for c in range(count)]
        self.num_components = len(self.comps)

    @property
    def num_slots(self) -> int:
        return 1 + self.ndim + (self.grad_slot >= 0)

    def shape_expr(self, dim: int) -> Expr:
        return Expr(context.builder().emit(Op.ARRAY_SHAPE, dt.i32, (), {"arg": self.comps[0], "dim": dim}))

    @property
    def shape(self) -> tuple:
        return tuple(self.shape_expr(k) for k in range(self.ndim))

    def ir_name(self) -> str:
        return f"arg{self.slot}"

    @property
    def grad(self) -> ArrayArg:
        """`x.grad` in a kernel: the argument's gradient array, read and written like any ndarray (an adjoint
        of a kernel that does so is refused: autodiff/validate.py)."""
        if self.grad_slot < 0:
            raise SimgradTypeError(f"ndarray argument '{self.name}' has no gradient (pass an ndarray created "
                                   "with needs_grad=True)")
        view = ArrayArg.__new__(ArrayArg)
        view.__dict__.update(self.__dict__)
        view.name, view.grad_slot = f"{self.name}.grad", -1
        view.comps = [c.grad for c in self.comps if c.grad is not None]
        return view

    def ref(self, indices):
        if self.boundary == "clamp":  # ti.types.ndarray(boundary="clamp")
            indices = [ops.max(0, ops.min(i, self.shape_expr(k) - 1)) for k, i in enumerate(indices)]
        refs = [GlobalRef(c, indices, self.dtype) for c in self.comps]
        if not self.element_shape:
            return refs[0]
        n = self.element_shape[0]
        m = self.element_shape[1] if len(self.element_shape) > 1 else 0
        return MatrixRef(refs, n, m)
