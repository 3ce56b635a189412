# mypy: disable-error-code="valid-type, index"
"""The 1-D fields and ndarrays ti.algorithms works on: what one is (length, index offset, element type), a
scratch ndarray of the same element type, and copies between them. Fields are `ti.template()` arguments and
ndarrays `ti.types.ndarray()` ones, so every kernel that touches a user's container comes in both kinds."""

import simgrad as ti
from simgrad import errors
from simgrad.errors import SimgradSyntaxError, SimgradTypeError, caller_loc


def python_scope(name: str) -> None:
    """Refuse a call made while a kernel compiles (it would launch kernels from inside one, as Taichi refuses)."""
    if errors.compiling():
        raise SimgradSyntaxError(f"ti.algorithms.{name} launches kernels: call it in Python scope, not inside a "
                                 "kernel or ti.func")


class Array1D:
    """A user's 1-D field or ndarray: `kind` ("field" or "ndarray"), `n` elements, `offset` (a field's
    first index), `dtype` and `entry_shape` (() for scalars, (n,) or (n, m) for vectors and matrices)."""

    def __init__(self, obj, what: str):
        if isinstance(obj, ti.Ndarray):
            self.kind, self.offset, self.entry_shape = "ndarray", 0, tuple(obj.element_shape)
        elif isinstance(obj, ti.MatrixField):
            self.kind, self.offset, self.entry_shape = "field", 0, tuple(obj.entry_shape)
        elif isinstance(obj, ti.ScalarField):
            self.kind, self.offset, self.entry_shape = "field", 0, ()
        else:
            raise SimgradTypeError(f"{what} must be a field or an ndarray of scalars, vectors or matrices, "
                                   f"got {type(obj).__name__}", caller_loc())
        if len(obj.shape) != 1:
            raise SimgradTypeError(f"{what} must be one-dimensional, got shape {tuple(obj.shape)}", caller_loc())
        if self.kind == "field":  # a matrix field's offset is its components'
            comps = obj._components() if isinstance(obj, ti.MatrixField) else [obj]
            self.offset = int((comps[0].offset or (0,))[0])
        self.obj, self.n, self.dtype = obj, int(obj.shape[0]), obj.dtype

    def scratch(self, n: int):
        """A new ndarray of n elements of this element type."""
        n = max(n, 1)
        if len(self.entry_shape) == 2:
            return ti.Matrix.ndarray(self.entry_shape[0], self.entry_shape[1], self.dtype, n)
        if len(self.entry_shape) == 1:
            return ti.Vector.ndarray(self.entry_shape[0], self.dtype, n)
        return ti.ndarray(self.dtype, n)


def annotation(kind: str):
    """The kernel parameter annotation of a container kind."""
    return ti.template() if kind == "field" else ti.types.ndarray()


_COPIES: dict = {}


def copy(src, src_offset: int, dst, dst_offset: int, n: int, src_kind: str, dst_kind: str) -> None:
    """dst[dst_offset + i] = src[src_offset + i] for i < n, by a parallel kernel."""
    key = (src_kind, dst_kind)
    if key not in _COPIES:
        _COPIES[key] = _copy_kernel(annotation(src_kind), annotation(dst_kind))
    if n > 0:
        _COPIES[key](src, src_offset, dst, dst_offset, n)


def _copy_kernel(src_ann, dst_ann):
    @ti.kernel
    def copy_kernel(src: src_ann, src_offset: ti.i32, dst: dst_ann, dst_offset: ti.i32, n: ti.i32):
        for i in range(n):
            dst[i + dst_offset] = src[i + src_offset]

    return copy_kernel
