# mypy: disable-error-code="valid-type, index"
"""The 1-D fields and ndarrays ti.algorithms works on: what one is (length, index offset, element type, a
gradient), a scratch ndarray of the same element type, copies between them, and where the helpers may run.
Fields are `ti.template()` arguments and ndarrays `ti.types.ndarray()` ones, so every kernel that touches a
user's container comes in both kinds."""

import simgrad as ti
from simgrad import errors
from simgrad.errors import SimgradNotSupportedError, SimgradSyntaxError, SimgradTypeError, caller_loc
from simgrad.lang import ad_hooks


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

    def has_gradient(self) -> bool:
        """Whether the container carries a gradient (a placed one for a field, needs_grad for an ndarray)."""
        if self.kind == "ndarray":
            return getattr(self.obj, "grad", None) is not None
        comp = self.obj._components()[0] if isinstance(self.obj, ti.MatrixField) else self.obj
        g = getattr(comp, "grad", None)
        return g is not None and (g.layout is not None or bool(getattr(comp, "_needs_grad", False)))

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


def not_on_a_tape(name: str, *arrays: "Array1D | None") -> None:
    """Refuse permuting or scanning a container with a gradient while a ti.ad.Tape records: the kernels'
    adjoints would not carry the gradient back through the permutation (the result would be silently wrong;
    Taichi's are too). Containers without gradients (integer keys, index values) are fine on a Tape."""
    if ad_hooks.recorder is None:
        return
    for a in arrays:
        if a is not None and a.has_gradient():
            what = f"field {a.obj.name}" if a.kind == "field" else "an ndarray"
            raise SimgradNotSupportedError(
                f"ti.algorithms.{name} on a ti.ad.Tape is not differentiated, and {what} has a gradient: call it "
                "outside the Tape, or sort indices (keys without gradients, values = indices) and gather the "
                "differentiable data in a kernel", caller_loc())
