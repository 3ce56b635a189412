"""Type annotations and constructors: ti.template(), ti.types.ndarray/vector/matrix, ti.math.vec3 ..."""

from __future__ import annotations

from collections.abc import Callable
from enum import Enum

from simgrad import dtypes as dt
from simgrad.errors import SimgradTypeError
from simgrad.lang.quant import quant as quant_types


class Template:
    """`ti.template()`: the argument is a compile-time value (a field, a Python number, a function)."""

    def __init__(self, tensor=None, dim=None):
        pass

    def __repr__(self):
        return "template()"


template = Template


def is_template(ann) -> bool:
    return isinstance(ann, Template) or ann is Template


class RefType:
    """`ti.ref(ti.f32)`: a real function's parameter passed by reference (assigning it assigns the caller's
    variable), as a local passed for a ti.template() parameter is."""

    def __init__(self, dtype=None):
        self.dtype = dtype


def ref(dtype=None) -> RefType:
    return RefType(dtype)


def by_reference(ann) -> bool:
    """Whether a ti.func parameter with this annotation takes a caller's local variable itself."""
    return is_template(ann) or isinstance(ann, RefType)


class _Shape(tuple):
    """A matrix type's shape: a tuple, and callable as Taichi's TensorType.shape() (a list)."""

    def __call__(self) -> list[int]:
        return list(self)


class MatrixType:
    """`ti.types.vector(3, ti.f32)` / `ti.types.matrix(2, 2, ti.f64)`; callable to build a value."""

    def __init__(self, n: int, m: int, dtype=None):
        self.n, self.m = n, m
        self._dtype = dtype

    @property
    def dtype(self) -> dt.DataType:
        return dt.from_any(self._dtype) if self._dtype is not None else dt.Defaults.fp

    @property
    def num_entries(self) -> int:
        return self.n * max(self.m, 1)

    @property
    def shape(self):
        return _Shape((self.n,) if self.m == 0 else (self.n, self.m))

    def element_type(self) -> dt.DataType:
        """The scalar type of the entries (Taichi's TensorType.element_type(), e.g. of `ndarray.element_type`)."""
        return self.dtype

    def to_string(self) -> str:
        """Taichi's text of the type: `VectorType[3, f32]`, `MatrixType[2,3, f32]`."""
        if self.m == 0:
            return f"VectorType[{self.n}, {self.dtype.name}]"
        return f"MatrixType[{self.n},{self.m}, {self.dtype.name}]"

    def make(self, value):
        from simgrad.lang.matrix import Matrix

        if isinstance(value, Matrix):
            return value.cast(self.dtype)
        if isinstance(value, (list, tuple)):
            return Matrix(list(value), dt=self.dtype)
        return Matrix(n=self.n, m=self.m, _entries=[value] * self.num_entries).cast(self.dtype)

    def __call__(self, *args):
        """`vec3(0, 1, 2)`, `vec3([0, 1, 2])`, `mat3(row, row, row)`, `mat3(np_3x3)`, `mat4x3(v1, v2, v3, v4)`,
        `mat4x3(1)` (every entry), `mat2x6(m4x3)` (the same 12 entries, in row order), as Taichi accepts them."""
        from simgrad.lang.matrix import Matrix

        def flatten(a) -> list:
            if isinstance(a, Matrix):
                return list(a.entries)
            if isinstance(a, (list, tuple)):
                return [x for e in a for x in flatten(e)]
            if hasattr(a, "shape") and hasattr(a, "reshape") and getattr(a, "ndim", 0) > 0:  # numpy arrays
                return [x.item() if hasattr(x, "item") else x for x in a.reshape(-1)]
            return [a]

        flat = [x for a in args for x in flatten(a)]
        if len(flat) == 1 and self.num_entries != 1:
            flat = flat * self.num_entries
        if len(flat) != self.num_entries:
            raise ValueError(f"{self} takes {self.num_entries} entries, got {len(flat)}")
        if self.m == 0:
            return Matrix(flat, dt=self.dtype)
        return Matrix([flat[r * self.m:(r + 1) * self.m] for r in range(self.n)], dt=self.dtype)

    def field(self, shape=None, **kw):
        from simgrad.lang.factories import field

        return field(self, shape=shape, **kw)

    def __repr__(self):
        return f"vector({self.n}, {self._dtype})" if self.m == 0 else f"matrix({self.n}, {self.m}, {self._dtype})"


def vector(n=None, dtype=None) -> MatrixType:
    """`ti.types.vector(n, dtype)`; without n (an ndarray annotation) any length, from the argument."""
    return MatrixType(n, 0, dtype)


def matrix(n=None, m=None, dtype=None) -> MatrixType:
    """`ti.types.matrix(n, m, dtype)`; without n and m (an ndarray annotation) any shape, from the argument."""
    return MatrixType(n, m, dtype)


class NdarrayType:
    """`ti.types.ndarray(dtype=None, ndim=None)`: a numpy array (or CPU torch tensor) passed by reference."""

    def __init__(self, dtype=None, ndim=None, element_dim=None, element_shape=None, field_dim=None,
                 needs_grad=None, boundary=None):
        self.dtype = dtype
        self.ndim = ndim if ndim is not None else field_dim
        # trailing axes that form each element (a vector or matrix): a count taken from the array, or a shape
        self.element_dim = element_dim
        self.element_shape = tuple(element_shape) if element_shape is not None else None
        # True/False: whether kernels see the argument's gradient; None: whenever the argument has one
        self.needs_grad = needs_grad
        if boundary not in (None, "unsafe", "clamp"):
            raise SimgradTypeError(f"ndarray boundary must be 'unsafe' or 'clamp', got {boundary!r}")
        # "clamp": every index is clamped into the array (an out-of-range read gets the edge element)
        self.boundary = boundary or "unsafe"

    def element_shape_of(self, shape: tuple) -> tuple:
        """The element shape of an array of `shape` passed for this parameter (() for scalars)."""
        if self.element_shape is not None:
            return self.element_shape
        if self.element_dim:
            return tuple(shape[len(shape) - self.element_dim:])
        return ()

    def __repr__(self):
        return f"ndarray(dtype={self.dtype}, ndim={self.ndim}, element_dim={self.element_dim})"


def ndarray(dtype=None, ndim=None, **kw) -> NdarrayType:
    return NdarrayType(dtype, ndim, **kw)


class sparse_matrix_builder:  # lower case: Taichi spells it so
    """`ti.types.sparse_matrix_builder()`: the parameter takes a ti.linalg.SparseMatrixBuilder; in the kernel
    `A[i, j] += v` (or `-=`) appends the triplet (i, j, v). Passed by reference as its triplet arrays."""

    def __repr__(self):
        return "sparse_matrix_builder()"


def is_sparse_matrix_builder(ann) -> bool:
    return isinstance(ann, sparse_matrix_builder) or ann is sparse_matrix_builder


class _PrimitiveTypes:
    """`ti.types.primitive_types`: the scalar types and Taichi's lists of them."""

    def __init__(self) -> None:
        for t in dt.ALL:
            setattr(self, t.name, t)
        self.real_types = [dt.f16, dt.f32, dt.f64, float]
        self.integer_types = [dt.i8, dt.i16, dt.i32, dt.i64, dt.u1, dt.u8, dt.u16, dt.u32, dt.u64, int, bool]
        self.all_types = self.real_types + self.integer_types

    def __getattr__(self, name):
        return getattr(dt, name)


def is_real(t) -> bool:
    return dt.from_any(t).is_float


def is_integral(t) -> bool:
    return not dt.from_any(t).is_float


def is_signed(t) -> bool:
    t = dt.from_any(t)
    return t.is_float or t.is_signed


def is_tensor(t) -> bool:
    return isinstance(t, MatrixType)


def _no_argpack(**members):
    raise RuntimeError("import simgrad first: it installs ti.types.argpack")


class _Types:
    """The `ti.types` namespace."""

    primitive_types = _PrimitiveTypes()
    is_real = staticmethod(is_real)
    is_integral = staticmethod(is_integral)
    is_signed = staticmethod(is_signed)
    is_tensor = staticmethod(is_tensor)

    template = staticmethod(template)
    ndarray = staticmethod(ndarray)
    sparse_matrix_builder = sparse_matrix_builder
    vector = staticmethod(vector)
    matrix = staticmethod(matrix)
    quant = quant_types
    argpack: Callable = _no_argpack  # ti.types.argpack, set by simgrad/__init__.py (lang/argpack.py is above)

    @staticmethod
    def struct(**members):
        """`ti.types.struct(pos=vec3, m=ti.f32)` (lang/struct.py); `__struct_methods={name: fn}` gives it methods
        as @ti.dataclass does (ti.funcs in kernels, plain functions on Python-scope values)."""
        from simgrad.lang.struct import struct_type

        return struct_type(members)

    def __getattr__(self, name):
        return getattr(dt, name)


types = _Types()
for _t in dt.ALL:
    setattr(_Types, _t.name, _t)


class Layout(Enum):
    """Memory layout of a vector/matrix field's components: side by side (AOS) or one array each (SOA)."""

    AOS = 0
    SOA = 1
