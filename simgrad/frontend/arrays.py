"""How a kernel under compilation sees an ndarray parameter (a numpy array or CPU torch tensor passed by
reference, any dtype/ndim): each component of its elements is an ir.ArrayRef, the target of GLOBAL_PTRs;
its shape is read at run time. A sparse matrix builder parameter (BuilderArg) is four such arrays."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.errors import SimgradIndexError, SimgradSyntaxError, SimgradTypeError
from simgrad.frontend.refs import GlobalRef, MatrixRef
from simgrad.ir import context
from simgrad.ir.fieldref import ArrayRef
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix


class ElementShape(tuple):
    """An ndarray parameter's element shape: a tuple for simgrad's own use, and callable, since Taichi's
    kernel-scope ndarray has ``element_shape()`` giving a list (``ti.static(a.element_shape() == [2])``)."""

    def __call__(self) -> list:
        return list(self)


class ArrayArg:
    """How a kernel sees an ndarray parameter while it is compiled."""

    def __init__(self, name: str, slot: int, dtype: dt.DataType, ndim: int, element_shape: tuple = (),
                 boundary: str = "unsafe", grad: bool = False):
        self.boundary = boundary
        self.name, self.slot, self.dtype, self.ndim = name, slot, dtype, ndim
        self.element_shape = ElementShape(element_shape)
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
            indices = [operators.max(0, operators.min(i, self.shape_expr(k) - 1)) for k, i in enumerate(indices)]
        refs = [GlobalRef(c, indices, self.dtype) for c in self.comps]
        if not self.element_shape:
            return refs[0]
        n = self.element_shape[0]
        m = self.element_shape[1] if len(self.element_shape) > 1 else 0
        return MatrixRef(refs, n, m, clamp=self.boundary == "clamp")


class BuilderArg:
    """How a kernel sees a `ti.types.sparse_matrix_builder()` parameter while it is compiled: the builder's
    triplet storage as four 1-d ndarray arguments, each a base pointer and an extent in the context (8 slots):
    the triplet count (one i64), the rows and columns (i32) and the values (the builder's dtype). The extent of
    the rows is the capacity (max_num_triplets), read at run time, so one instantiation serves every builder
    of a dtype."""

    num_slots = 8

    def __init__(self, name: str, slot: int, dtype: dt.DataType):
        self.name, self.slot, self.dtype = name, slot, dtype
        self.count = ArrayArg(f"{name}.count", slot, dt.i64, 1)
        self.rows = ArrayArg(f"{name}.rows", slot + 2, dt.i32, 1)
        self.cols = ArrayArg(f"{name}.cols", slot + 4, dt.i32, 1)
        self.values = ArrayArg(f"{name}.values", slot + 6, dtype, 1)

    def ref(self, index, loc) -> BuilderRef:
        idx = index if isinstance(index, tuple) else (index,)
        if len(idx) != 2:
            raise SimgradIndexError(f"sparse matrix builder '{self.name}' takes two indices (A[i, j] += v), got "
                                    f"{len(idx)}", loc)
        exprs = []
        for i in idx:
            if isinstance(i, (float, Matrix)) or (isinstance(i, Expr) and i.dtype.is_float) \
                    or not isinstance(i, (int, Expr)):
                raise SimgradTypeError(f"the indices of sparse matrix builder '{self.name}' must be integer "
                                       f"scalars, got {i!r}", loc)
            e = operators.to_expr(i, dt.i32)
            exprs.append(e if e.dtype is dt.i32 else operators.cast_expr(e, dt.i32))
        return BuilderRef(self, exprs, loc)


class BuilderRef:
    """`A[i, j]` of a sparse matrix builder: only `+=` and `-=` apply to it. Each appends one triplet: an atomic
    add on the count gives the triplet's index k; when k is below the capacity, (i, j, v) is stored at k. A
    count past the capacity is reported after the launch (runtime/launch.py), never dropped silently."""

    def __init__(self, arg: BuilderArg, indices: list[Expr], loc):
        self.arg, self.indices, self.loc = arg, indices, loc

    @property
    def dtype(self) -> dt.DataType:
        return self.arg.dtype

    def load(self):
        raise SimgradSyntaxError(f"the entries of sparse matrix builder '{self.arg.name}' cannot be read in a "
                                 "kernel: only A[i, j] += v and A[i, j] -= v are supported", self.loc)

    def store(self, value) -> None:
        raise SimgradSyntaxError(f"the entries of sparse matrix builder '{self.arg.name}' cannot be assigned: "
                                 "only A[i, j] += v and A[i, j] -= v are supported", self.loc)

    def atomic(self, kind: str, value) -> None:
        if kind not in ("add", "sub"):
            raise SimgradSyntaxError(f"only '+=' and '-=' are supported on sparse matrix builder "
                                     f"'{self.arg.name}'", self.loc)
        if isinstance(value, Matrix) or not isinstance(value, (int, float, Expr)):
            raise SimgradTypeError(f"a triplet added to sparse matrix builder '{self.arg.name}' must be a scalar, "
                                   f"got {type(value).__name__}", self.loc)
        a = self.arg
        v = operators.cast_expr(operators.to_expr(value, a.dtype), a.dtype)
        if kind == "sub":
            v = operators.neg(v)
        b = context.builder()
        k = GlobalRef(a.count.comps[0], [operators.to_expr(0, dt.i32)], dt.i64).atomic("add", 1)
        cap = operators.cast_expr(a.rows.shape_expr(0), dt.i64)
        fits = operators.ne(operators.lt(k, cap), 0)
        stmt = b.emit(Op.IF, None, (fits.stmt,), nblocks=2)
        with b.inside(stmt.blocks[0]):
            k32 = operators.cast_expr(k, dt.i32)
            GlobalRef(a.rows.comps[0], [k32], dt.i32).store(self.indices[0])
            GlobalRef(a.cols.comps[0], [k32], dt.i32).store(self.indices[1])
            GlobalRef(a.values.comps[0], [k32], a.dtype).store(v)
