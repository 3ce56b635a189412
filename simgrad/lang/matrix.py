"""Small vectors and matrices (ti.Vector / ti.Matrix), the same class in Python scope and in kernels.

In kernels the entries are `Expr`s and every operation unrolls into scalar IR: matrices are small by
contract, so unrolling is what makes them free at run time (and differentiable entry by entry)."""

from __future__ import annotations

import itertools
import numbers

import numpy as np

from simgrad import dtypes as dt
from simgrad import errors
from simgrad.errors import (
    SimgradIndexError,
    SimgradSyntaxError,
    SimgradTypeError,
    SimgradValueError,
    TaichiRuntimeError,
    caller_loc,
)
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr

_SWIZZLE_GROUPS = ("xyzw", "rgba", "stpq")
_SWIZZLE = {c: i for g in _SWIZZLE_GROUPS for i, c in enumerate(g)}


def _swizzle_indices(name: str) -> list[int] | None:
    """Indices of a swizzle like "zyx" (letters of one group, Taichi's rule), or None."""
    if not 0 < len(name) <= 4:
        return None
    for g in _SWIZZLE_GROUPS:
        if all(c in g for c in name):
            return [g.index(c) for c in name]
    return None


def check_swizzle(name: str, idx: list[int], n: int, cls: type[Exception] | None = None) -> None:
    """A swizzle past the vector's length, in Taichi's words (a TaichiSyntaxError; reading one in Python scope is
    an AttributeError, so that hasattr() keeps working)."""
    if max(idx) >= n:
        group = next(g for g in _SWIZZLE_GROUPS if name[0] in g)
        text = f"vec{n} only has attributes={tuple(group[:n])}, got={tuple(name)}"
        if cls is not None:
            raise cls(text)
        raise SimgradSyntaxError(text, _loc())


def vector_key(key):
    """A vector used as an index (`m[I]`, I from `ti.static(ti.grouped(ti.ndrange(2, 3)))`) stands for its
    entries, as in Taichi."""
    if isinstance(key, Matrix) and key.m == 0:
        return tuple(key.entries)
    return key


_set_slot = object.__setattr__


class Matrix:
    """An n-vector (m == 0) or an n x m matrix of scalars (Python numbers or kernel values)."""

    __slots__ = ("entries", "n", "m")
    entries: list
    n: int
    m: int
    _is_matrix = True
    # numpy defers to Matrix's reflected operators (`np.cos(0) + v` is a Matrix, as in Taichi), rather than
    # treating it as a sequence
    __array_priority__ = 1000

    def __init__(self, arr=None, dt=None, n=None, m=None, *, _entries=None):
        if _entries is not None:
            entries = list(_entries)
        elif isinstance(arr, Matrix):
            entries, n, m = list(arr.entries), arr.n, arr.m
        else:
            if isinstance(arr, np.ndarray):
                arr = arr.tolist()
            if isinstance(arr, (numbers.Number, Expr)):
                arr = [arr]
            arr = list(arr)
            if arr and isinstance(arr[0], (list, tuple, np.ndarray, Matrix)):
                rows = [list(r.entries) if isinstance(r, Matrix) else list(r) for r in arr]
                n, m = len(rows), len(rows[0])
                if any(len(r) != m for r in rows):
                    raise ValueError("matrix rows must have equal lengths")
                entries = [e for r in rows for e in r]
            else:
                entries, n, m = arr, len(arr), 0
        if dt is not None:
            entries = [operators.cast(e, dt) for e in entries]
        _set_slot(self, "entries", entries)  # (past __setattr__'s swizzle handling: made often in Python scope)
        _set_slot(self, "n", n)
        _set_slot(self, "m", m)

    # -- shape -----------------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, ...]:
        return (self.n,) if self.m == 0 else (self.n, self.m)

    @property
    def is_vector(self) -> bool:
        return self.m == 0

    @property
    def ndim(self) -> int:
        return 1 if self.m == 0 else 2

    def get_shape(self) -> tuple[int, ...]:
        return self.shape

    def _like(self, entries: list) -> Matrix:
        like = object.__new__(Matrix)
        _set_slot(like, "entries", entries)
        _set_slot(like, "n", self.n)
        _set_slot(like, "m", self.m)
        return like

    @staticmethod
    def _map(fn, *args) -> Matrix:
        # a list, tuple or numpy array beside a matrix is a matrix of the same shape (`m == [[0, 1], [2, 3]]`),
        # never one scalar operand
        if not all(type(a) in _PLAIN_OPERANDS for a in args):  # (the common case skips the probing)
            args = tuple(Matrix(a.tolist() if hasattr(a, "tolist") else list(a))
                         if isinstance(a, (list, tuple)) or (hasattr(a, "ndim") and getattr(a, "ndim", 0) > 0
                                                              and not isinstance(a, Matrix)) else a
                         for a in args)
        mats = [a for a in args if isinstance(a, Matrix)]
        proto = mats[0]
        for a in mats[1:]:
            if a.n != proto.n or a.m != proto.m:
                shape = proto.shape
                # as Taichi: a TaichiTypeError in a kernel, numpy's ValueError in Python scope
                if errors.compiling():  # (Taichi's words first)
                    raise SimgradTypeError(f"Cannot broadcast tensor to tensor: matrix shapes {shape} and {a.shape} "
                                           "do not match")
                raise SimgradValueError(f"matrix shapes {shape} and {a.shape} do not match", caller_loc())
        cols = [a.entries if isinstance(a, Matrix) else itertools.repeat(a) for a in args]
        return proto._like(list(map(fn, *cols)))

    def __len__(self) -> int:
        return self.n

    def __iter__(self):
        if self.m == 0:
            return iter(self.entries)
        return iter(self._row(r) for r in range(self.n))

    def _row(self, r: int) -> Matrix:
        return Matrix(self.entries[r * self.m : (r + 1) * self.m])

    def _flat_index(self, key) -> int | None:
        key = key if isinstance(key, tuple) else (key,)
        if any(isinstance(k, Expr) for k in key):
            return None
        key = tuple(int(k) for k in key)
        if self.m == 0:
            if len(key) != 1:
                raise SimgradIndexError(f"Expected 1 indices, got {len(key)}: a vector takes one index", _loc())
            (i,) = key
            if not -self.n <= i < self.n:
                raise IndexError(f"index {i} out of range for a {self.n}-vector")
            return i % self.n
        if len(key) == 1:
            return None
        i, j = key
        if not (-self.n <= i < self.n and -self.m <= j < self.m):
            raise IndexError(f"index {key} out of range for a {self.n}x{self.m} matrix")
        return (i % self.n) * self.m + (j % self.m)

    def __call__(self, *key):
        """`v(0)`, `m(i, j)`: Taichi's older element syntax, the same as v[0], m[i, j]."""
        return self[key if len(key) > 1 else key[0]]

    def __getitem__(self, key):
        if type(key) is int and self.m == 0 and 0 <= key < self.n:  # v[0], the most common read
            return self.entries[key]
        key = vector_key(key)
        if isinstance(key, slice) or (isinstance(key, tuple) and any(isinstance(k, slice) for k in key)):
            return self._slice(key)
        idx = self._flat_index(key)
        if idx is not None:
            return self.entries[idx]
        key = key if isinstance(key, tuple) else (key,)
        if self.m and len(key) == 1 and _in_kernel():  # Taichi 1.7: m[i, j] only (numpy-like rows in Python)
            raise SimgradIndexError(f"Expected 2 indices, got 1: index a {self.n}x{self.m} matrix as m[i, j]",
                                    _loc())
        if self.m and len(key) == 1 and not isinstance(key[0], Expr):
            return self._row(int(key[0]))
        if len(key) != (1 if self.m == 0 else 2):
            raise SimgradIndexError(f"Expected {1 if self.m == 0 else 2} indices, got {len(key)}", _loc())
        return self._dynamic_get(key)

    def _slice(self, key):
        """Compile-time slices: v[1:], m[0, :], m[:2, 1:] (a vector when one index is an int)."""
        key = key if isinstance(key, tuple) else (key,)
        dims = (self.n,) if self.m == 0 else (self.n, self.m)
        if len(key) == 1 and self.m:
            key = (key[0], slice(None))
        if len(key) != len(dims):
            raise IndexError(f"{len(key)} indices for a matrix of shape {self.shape}")
        for k in key:
            if isinstance(k, slice) and any(isinstance(p, Expr) for p in (k.start, k.stop, k.step)):
                raise SimgradTypeError("slice bounds must be compile-time values (Taichi does not support "
                                       "variables in slice now)", _loc())
        if any(isinstance(k, Expr) for k in key):  # m[:, j] with a run-time j: each entry picked at run time
            rows = [list(range(*k.indices(d))) if isinstance(k, slice) else [k] for k, d in zip(key, dims)]
            picked = [self._dynamic_get((i, j)) for i in rows[0] for j in rows[1]]
            if all(isinstance(k, slice) for k in key):
                return Matrix([picked[r * len(rows[1]):(r + 1) * len(rows[1])] for r in range(len(rows[0]))])
            return Matrix(picked)
        ranges = [range(*k.indices(d)) if isinstance(k, slice) else [int(k) % d] for k, d in zip(key, dims)]
        if self.m == 0:
            return Matrix([self.entries[i] for i in ranges[0]])
        rows = [[self.entries[i * self.m + j] for j in ranges[1]] for i in ranges[0]]
        if all(isinstance(k, slice) for k in key):
            return Matrix(rows)
        return Matrix([e for r in rows for e in r])

    def _dynamic_get(self, key):
        """Index with kernel values: a chain of selects over the candidates (in debug mode an index out of
        range is a located error, not the last candidate)."""
        check_dynamic_index(key, (self.n,) if self.m == 0 or len(key) == 1 else (self.n, self.m))
        if self.m and len(key) == 1:
            rows = [self._row(r) for r in range(self.n)]
            out = rows[-1]
            for r in range(self.n - 2, -1, -1):
                out = operators.select(operators.eq(key[0], r), rows[r], out)
            return out
        flat = operators.mul(key[0], self.m) + key[1] if self.m else key[0]
        out = self.entries[-1]
        for c in range(len(self.entries) - 2, -1, -1):
            out = operators.select(operators.eq(flat, c), self.entries[c], out)
        return out

    def __setitem__(self, key, value):
        if type(key) is int and self.m == 0 and 0 <= key < self.n:
            self.entries[key] = value
            return
        key = vector_key(key)
        idx = self._flat_index(key)
        if idx is None:
            if self.m and not isinstance(key, tuple):
                for c, v in enumerate(value):
                    self.entries[int(key) * self.m + c] = v
                return
            raise IndexError("assigning through a kernel-value index is not supported on a temporary matrix")
        self.entries[idx] = value

    def _swizzle(self, name: str, reading: bool = False) -> list[int]:
        idx = _swizzle_indices(name)
        if idx is None or name.startswith("_"):
            raise AttributeError(f"'Matrix' object has no attribute '{name}'")
        if self.m != 0:
            raise AttributeError(f"a {self.shape} matrix has no swizzle '{name}'")
        check_swizzle(name, idx, self.n, AttributeError if reading else None)
        return idx

    def __getattr__(self, name):
        idx = self._swizzle(name, reading=True)
        if len(idx) == 1:
            return self.entries[idx[0]]
        return Matrix([self.entries[i] for i in idx])

    def __setattr__(self, name, value):
        if name in Matrix.__slots__:
            object.__setattr__(self, name, value)
            return
        idx = self._swizzle(name)
        vals = [value] if len(idx) == 1 else list(value)
        if len(vals) != len(idx):
            raise TaichiRuntimeError(f"value len does not match the swizzle pattern={name}: it takes {len(idx)} "
                                     f"values, got {len(vals)}", _loc())
        for i, v in zip(idx, vals):
            self.entries[i] = v

    # -- arithmetic --------------------------------------------------------------------------------
    def __add__(self, o):
        return operators.add(self, o)

    def __radd__(self, o):
        return operators.add(o, self)

    def __sub__(self, o):
        return operators.sub(self, o)

    def __rsub__(self, o):
        return operators.sub(o, self)

    def __mul__(self, o):
        return operators.mul(self, o)

    def __rmul__(self, o):
        return operators.mul(o, self)

    def __truediv__(self, o):
        return operators.truediv(self, o)

    def __rtruediv__(self, o):
        return operators.truediv(o, self)

    def __floordiv__(self, o):
        return operators.floordiv(self, o)

    def __rfloordiv__(self, o):
        return operators.floordiv(o, self)

    def __mod__(self, o):
        return operators.mod(self, o)

    def __rmod__(self, o):
        return operators.mod(o, self)

    def __pow__(self, o):
        return operators.pow(self, o)

    def __rpow__(self, o):
        return operators.pow(o, self)

    def __neg__(self):
        return operators.neg(self)

    def __pos__(self):
        return self

    def __abs__(self):
        return operators.abs(self)

    def __lt__(self, o):
        return operators.lt(self, o)

    def __le__(self, o):
        return operators.le(self, o)

    def __gt__(self, o):
        return operators.gt(self, o)

    def __ge__(self, o):
        return operators.ge(self, o)

    def __eq__(self, o):  # type: ignore[override]
        return operators.eq(self, o)

    def __ne__(self, o):  # type: ignore[override]
        return operators.ne(self, o)

    def __and__(self, o):
        return operators.bit_and(self, o)

    def __rand__(self, o):
        return operators.bit_and(o, self)

    def __or__(self, o):
        return operators.bit_or(self, o)

    def __ror__(self, o):
        return operators.bit_or(o, self)

    def __xor__(self, o):
        return operators.bit_xor(self, o)

    def __rxor__(self, o):
        return operators.bit_xor(o, self)

    def __lshift__(self, o):
        return operators.shl(self, o)

    def __rshift__(self, o):
        return operators.shr(self, o)

    def __invert__(self):
        return operators.bit_not(self)

    __hash__ = None  # type: ignore[assignment]

    def __matmul__(self, o):
        """matrix @ matrix, matrix @ vector (a vector), vector @ matrix (row vector times matrix, a vector,
        as Taichi), vector @ vector (the dot product)."""
        o = o if isinstance(o, Matrix) else Matrix(o)
        if self.m == 0 and o.m == 0:
            if self.n != o.n:
                raise ValueError(f"matmul of {self.shape} and {o.shape}")
            return self.dot(o)
        a = self if self.m else Matrix([list(self.entries)])
        b = o if o.m else Matrix([[e] for e in o.entries])
        if a.m != b.n:
            raise ValueError(f"matmul of {self.shape} and {o.shape}")
        rows = [[_sum([operators.mul(a.entries[i * a.m + k], b.entries[k * b.m + j]) for k in range(a.m)])
                 for j in range(b.m)] for i in range(a.n)]
        if o.m == 0:
            return Matrix([r[0] for r in rows])
        if self.m == 0:
            return Matrix(rows[0])
        return Matrix(rows)

    def __rmatmul__(self, o):
        return Matrix(o) @ self

    # -- methods (Taichi's names) -------------------------------------------------------------------
    def transpose(self) -> Matrix:
        if self.m == 0:  # Taichi 1.7 refuses it too (a vector has one axis)
            raise SimgradTypeError("`transpose()` cannot apply to a vector. If you want something like "
                                   "`a @ b.transpose()`, write `a.outer_product(b)` instead.", _loc())
        return Matrix([[self.entries[i * self.m + j] for i in range(self.n)] for j in range(self.m)])

    @property
    def T(self) -> Matrix:
        return self.transpose()

    def sum(self):
        return _sum(self.entries)

    def max(self):
        return operators.max(*self.entries) if len(self.entries) > 1 else self.entries[0]

    def min(self):
        return operators.min(*self.entries) if len(self.entries) > 1 else self.entries[0]

    def any(self):
        return _reduce(operators.bit_or, [operators.ne(e, 0) for e in self.entries])

    def all(self):
        return _reduce(operators.bit_and, [operators.ne(e, 0) for e in self.entries])

    def dot(self, o):
        o = o if isinstance(o, Matrix) else Matrix(o)
        if self.m != 0 or o.m != 0 or self.n != o.n:
            raise ValueError(f"dot needs two vectors of one size, got {self.shape} and {o.shape}")
        return _sum([operators.mul(a, b) for a, b in zip(self.entries, o.entries)])

    def norm(self, eps=0):
        """sqrt(sum of squares + eps); also the Frobenius norm of a matrix."""
        s = _sum([operators.mul(e, e) for e in self.entries])
        return operators.sqrt(operators.add(s, eps) if not _is_zero(eps) else s)

    def norm_inv(self, eps=0):
        return operators.rsqrt(operators.add(self.norm_sqr(), eps))

    def norm_sqr(self):
        return _sum([operators.mul(e, e) for e in self.entries])

    def normalized(self, eps=0):
        """v / (|v| + eps): Taichi's formula (eps is added to the norm, not under the sqrt)."""
        n = self.norm()
        return operators.mul(self, operators.truediv(1.0, n if _is_zero(eps) else operators.add(n, eps)))

    def cross(self, o):
        """2D: the scalar a.x*b.y - a.y*b.x; 3D: the cross-product vector."""
        o = o if isinstance(o, Matrix) else Matrix(o)
        if self.m != 0 or o.m != 0 or self.n != o.n or self.n not in (2, 3):
            raise ValueError(f"cross needs two 2D or two 3D vectors, got {self.shape} and {o.shape}")
        a, b = self.entries, o.entries
        if self.n == 2:
            return operators.sub(operators.mul(a[0], b[1]), operators.mul(a[1], b[0]))
        return Matrix([
            operators.sub(operators.mul(a[1], b[2]), operators.mul(a[2], b[1])),
            operators.sub(operators.mul(a[2], b[0]), operators.mul(a[0], b[2])),
            operators.sub(operators.mul(a[0], b[1]), operators.mul(a[1], b[0])),
        ])

    def outer_product(self, o):
        o = o if isinstance(o, Matrix) else Matrix(o)
        if self.m != 0 or o.m != 0:
            raise ValueError(f"outer_product needs two vectors, got {self.shape} and {o.shape}")
        return Matrix([[operators.mul(x, y) for y in o.entries] for x in self.entries])

    def trace(self):
        if self.n != self.m:
            raise SimgradTypeError(f"expected a square matrix, got shape {self.shape}", _loc())
        return _sum([self.entries[i * self.m + i] for i in range(self.n)])

    def _e(self, i, j):
        return self.entries[i * self.m + j]

    def determinant(self):
        n = self.n
        if n != self.m:
            raise ValueError("determinant of a non-square matrix")
        if n == 1:
            return self.entries[0]
        if n == 2:
            m = operators.mul
            return operators.sub(m(self._e(0, 0), self._e(1, 1)), m(self._e(0, 1), self._e(1, 0)))
        terms = []
        for j in range(n):
            minor = Matrix([[self._e(r, c) for c in range(n) if c != j] for r in range(1, n)])
            t = operators.mul(self._e(0, j), minor.determinant())
            terms.append(t if j % 2 == 0 else operators.neg(t))
        return _sum(terms)

    def inverse(self):
        """Adjugate over determinant (unrolled cofactors): exact formulas, no pivoting, for n <= 4."""
        n = self.n
        if n != self.m:
            raise ValueError("inverse of a non-square matrix")
        if n == 1:
            return Matrix([[operators.truediv(1.0, self.entries[0])]])
        inv_det = operators.truediv(1.0, self.determinant())
        if n == 2:
            a, b, c, d = self.entries
            return Matrix([[operators.mul(d, inv_det), operators.mul(operators.neg(b), inv_det)],
                           [operators.mul(operators.neg(c), inv_det), operators.mul(a, inv_det)]])
        cof = []
        for i in range(n):
            row = []
            for j in range(n):
                minor = Matrix([[self._e(r, c) for c in range(n) if c != i] for r in range(n) if r != j])
                d = minor.determinant()
                row.append(operators.mul(d if (i + j) % 2 == 0 else operators.neg(d), inv_det))
            cof.append(row)
        return Matrix(cof)

    def cast(self, dtype) -> Matrix:
        return self._like([operators.cast(e, dtype) for e in self.entries])

    def to_numpy(self, keep_dims=False):
        return np.array(self.entries).reshape(self.shape)

    def to_list(self):
        return self.to_numpy().tolist()

    def fill(self, v) -> None:
        self.entries = [v] * len(self.entries)

    def __repr__(self) -> str:  # Python-scope values print as taichi prints them: [0.5 2. ]
        return str(self.to_numpy()) if not any(isinstance(e, Expr) for e in self.entries) else \
            f"Matrix({self.shape})"

    def __array__(self, dtype=None, copy=None):
        a = self.to_numpy()
        return a.astype(dtype) if dtype is not None else a

    # -- constructors -------------------------------------------------------------------------------
    @staticmethod
    def identity(dt_, n):
        return Matrix([[operators.cast(1 if i == j else 0, dt_) for j in range(n)] for i in range(n)])

    @staticmethod
    def zero(dt_, n, m=None):
        return Matrix._filled(0, dt_, n, m)

    @staticmethod
    def one(dt_, n, m=None):
        return Matrix._filled(1, dt_, n, m)

    @staticmethod
    def _filled(v, dt_, n, m):
        if m is None:
            return Matrix([operators.cast(v, dt_) for _ in range(n)])
        return Matrix([[operators.cast(v, dt_) for _ in range(m)] for _ in range(n)])

    @staticmethod
    def diag(dim, val):
        """val on the diagonal, zeros of val's type elsewhere."""
        if isinstance(val, Expr):
            zero = operators.cast(0, val.dtype)
        else:
            zero = 0.0 if isinstance(val, float) else 0
        return Matrix([[val if i == j else zero for j in range(dim)] for i in range(dim)])

    @staticmethod
    def unit(n, i, dt=None):
        return Matrix([1 if k == i else 0 for k in range(n)], dt=dt)

    @staticmethod
    def rows(rows):
        return Matrix([list(r.entries) if isinstance(r, Matrix) else list(r) for r in rows])

    @staticmethod
    def cols(cols):
        return Matrix.rows(cols).transpose()

    @staticmethod
    def field(*args, **kwargs):
        """`ti.Matrix.field(n, m, dtype, shape=...)`: a field of n x m matrices (lang/factories.py)."""
        from simgrad.lang.factories import matrix_field

        return matrix_field(*args, **kwargs)

    @staticmethod
    def ndarray(n, m, dtype, shape, needs_grad=False):
        """`ti.Matrix.ndarray(n, m, dtype, shape)`: an ndarray of n x m matrices (lang/ndarray.py)."""
        from simgrad.lang.ndarray import MatrixNdarray

        return MatrixNdarray(n, m, dtype, shape, needs_grad)


class _VectorMeta(type):
    def __instancecheck__(cls, obj):
        return isinstance(obj, Matrix) and obj.m == 0


class Vector(Matrix, metaclass=_VectorMeta):
    """`ti.Vector([...])`: builds a Matrix (m == 0); isinstance(x, ti.Vector) holds for any vector.
    `ti.Vector.field` makes a vector field."""

    def __new__(cls, arr=None, dt=None, **kw):
        return Matrix(arr, dt=dt)

    @staticmethod
    def field(*args, **kwargs):
        """`ti.Vector.field(n, dtype, shape=...)`: a field of n-vectors (lang/factories.py)."""
        from simgrad.lang.factories import vector_field

        return vector_field(*args, **kwargs)

    @staticmethod
    def ndarray(n, dtype, shape, needs_grad=False):
        """`ti.Vector.ndarray(n, dtype, shape)`: an ndarray of n-vectors (lang/ndarray.py)."""
        from simgrad.lang.ndarray import VectorNdarray

        return VectorNdarray(n, dtype, shape, needs_grad)


_PLAIN_OPERANDS = frozenset((Matrix, int, float, bool, Expr))  # operands _map takes as they are


def _is_zero(v) -> bool:
    return isinstance(v, numbers.Number) and v == 0


def _reduce(fn, xs):
    out = xs[0]
    for x in xs[1:]:
        out = fn(out, x)
    return out


def _sum(xs):
    return _reduce(operators.add, xs)


def dtype_of(m: Matrix) -> dt.DataType:
    for e in m.entries:
        if isinstance(e, Expr):
            return e.dtype
    return dt.Defaults.fp if any(isinstance(e, float) for e in m.entries) else dt.Defaults.ip


def check_dynamic_index(key, dims) -> None:
    from simgrad.ir import context

    comp = context.current()
    if comp is None or not getattr(comp, "debug", False):
        return
    for k, d in zip(key, dims):
        if isinstance(k, Expr):
            ok = operators.logical_and(operators.ge(k, 0), operators.lt(k, d))
            comp.builder.emit(Op.ASSERT, None, (operators.ne(ok, 0).stmt,),
                              {"message": f"Out of bound access: index out of range for a local vector/matrix "
                                          f"dimension of size {d}"})


def _in_kernel() -> bool:
    from simgrad.ir import context

    return context.current() is not None


def _loc():
    from simgrad.ir import context

    return context.current_loc()
