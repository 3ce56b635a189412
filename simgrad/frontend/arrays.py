"""How a kernel under compilation sees an ndarray parameter (a numpy array or CPU torch tensor passed by
reference, any dtype/ndim): each component of its elements is an ir.ArrayRef, the target of GLOBAL_PTRs;
its shape is read at run time."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.frontend.refs import GlobalRef, MatrixRef
from simgrad.ir import context
from simgrad.ir.fieldref import ArrayRef
from simgrad.ir.ops import Op
from simgrad.lang import ops
from simgrad.lang.expr import Expr


class ArrayArg:
    """How a kernel sees an ndarray parameter while it is compiled."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, ndim: int, element_shape: tuple = (),
                 boundary: str = "unsafe"):
        self.boundary = boundary
        self.name, self.slot, self.dtype, self.ndim = name, slot, dtype, ndim
        self.element_shape = element_shape
        self.comps = [ArrayRef(name, slot, dtype, ndim, element_shape, c)
                      for c in range(ArrayRef(name, slot, dtype, ndim, element_shape).num_components)]
        self.num_components = len(self.comps)

    @property
    def num_slots(self) -> int:
        return 1 + self.ndim

    def shape_expr(self, dim: int) -> Expr:
        return Expr(context.builder().emit(Op.ARRAY_SHAPE, dt.i32, (), {"arg": self.comps[0], "dim": dim}))

    @property
    def shape(self) -> tuple:
        return tuple(self.shape_expr(k) for k in range(self.ndim))

    def ir_name(self) -> str:
        return f"arg{self.slot}"

    def ref(self, indices):
        if self.boundary == "clamp":  # ti.types.ndarray(boundary="clamp")
            indices = [ops.max(0, ops.min(i, self.shape_expr(k) - 1)) for k, i in enumerate(indices)]
        refs = [GlobalRef(c, indices, self.dtype) for c in self.comps]
        if not self.element_shape:
            return refs[0]
        n = self.element_shape[0]
        m = self.element_shape[1] if len(self.element_shape) > 1 else 0
        return MatrixRef(refs, n, m)
