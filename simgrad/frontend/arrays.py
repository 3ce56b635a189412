"""How a kernel under compilation sees an ndarray parameter (a numpy array or CPU torch tensor passed by
reference, any dtype/ndim): its components are the targets of GLOBAL_PTRs, its shape is read at run time."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.frontend.refs import GlobalRef, MatrixRef
from simgrad.ir import context
from simgrad.ir.ops import Op
from simgrad.lang.expr import Expr


class ArrayComp:
    """One scalar component of an ndarray argument's elements (the target of a GLOBAL_PTR)."""

    def __init__(self, arg: ArrayArg, comp: int):
        self.arg, self.comp = arg, comp
        self.name = arg.name
        self.dtype = arg.dtype

    def ir_name(self) -> str:
        return f"arg{self.arg.slot}.{self.comp}" if self.arg.num_components > 1 else f"arg{self.arg.slot}"


class ArrayArg:
    """How a kernel sees an ndarray parameter while it is compiled."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, ndim: int, element_shape: tuple = ()):
        self.name, self.slot, self.dtype, self.ndim = name, slot, dtype, ndim
        self.element_shape = element_shape
        self.num_components = 1
        for n in element_shape:
            self.num_components *= n
        self.comps = [ArrayComp(self, c) for c in range(self.num_components)]

    @property
    def num_slots(self) -> int:
        return 1 + self.ndim

    def shape_expr(self, dim: int) -> Expr:
        return Expr(context.builder().emit(Op.ARRAY_SHAPE, dt.i32, (), {"arg": self, "dim": dim}))

    @property
    def shape(self) -> tuple:
        return tuple(self.shape_expr(k) for k in range(self.ndim))

    def ir_name(self) -> str:
        return f"arg{self.slot}"

    def ref(self, indices):
        refs = [GlobalRef(c, indices, self.dtype) for c in self.comps]
        if not self.element_shape:
            return refs[0]
        n = self.element_shape[0]
        m = self.element_shape[1] if len(self.element_shape) > 1 else 0
        return MatrixRef(refs, n, m)
