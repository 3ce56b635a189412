"""ti.linalg.SparseMatrix and SparseMatrixBuilder, on scipy.sparse.

A SparseMatrix wraps one scipy CSC ("col_major", Taichi's default, as Eigen's column-major storage) or CSR
("row_major") matrix. A SparseMatrixBuilder owns a TripletStore: a triplet count and preallocated rows,
columns and values, which kernels fill through a `ti.types.sparse_matrix_builder()` parameter (the
frontend's BuilderArg appends with an atomic add on the count) and build() turns into a matrix, summing
duplicates, as Eigen's setFromTriplets does."""

from __future__ import annotations

import warnings
from functools import reduce

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import (
    SimgradAssertionError,
    SimgradIndexError,
    SimgradRuntimeError,
    SimgradTypeError,
    SimgradValueError,
    caller_loc,
)
from simgrad.linalg import _scipy

_FORMATS = {"col_major": "csc", "row_major": "csr"}


def _value_type(dtype, what: str) -> dt.DataType:
    try:
        t = dt.from_any(dtype)
    except TypeError:
        t = None
    if t not in (dt.f32, dt.f64):
        raise SimgradTypeError(f"{what}: dtype must be ti.f32 or ti.f64, got {dtype!r}", caller_loc())
    return t


def _storage(storage_format: str, what: str) -> str:
    if storage_format not in _FORMATS:
        raise SimgradValueError(f"{what}: storage_format must be 'col_major' or 'row_major', got "
                                f"{storage_format!r}", caller_loc())
    return _FORMATS[storage_format]


def _size(v, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
        raise SimgradTypeError(f"{what} must be a non-negative integer, got {v!r}", caller_loc())
    return int(v)


def _eigen_number(v: float) -> str:
    """A coefficient as Eigen prints it with precision 4 (C++ ostream defaults: %g)."""
    return f"{v:.4g}"


def _shortest(v, t: dt.DataType) -> str:
    """A value as Taichi's print_triplets writes it (fmt's `{}`): the shortest digits that read back at the
    value's type, positional for decimal exponents -4 to 15, else scientific with a two-digit exponent."""
    x = t.np.type(v)
    if not np.isfinite(x):
        return str(float(x))
    sci = np.format_float_scientific(x, unique=True, trim="-", exp_digits=2)
    if -4 <= int(sci.split("e")[1]) < 16:
        return np.format_float_positional(x, unique=True, trim="-")
    return sci


class SparseMatrix:
    """A sparse matrix (Taichi's ti.linalg.SparseMatrix) held as a scipy.sparse CSC/CSR matrix, `.matrix`.

    `SparseMatrix(n, m, dtype=ti.f32, storage_format="col_major")` is an n x m zero matrix (fill it with
    build_from_ndarray); SparseMatrixBuilder.build() and the operators make the others. `sm=` wraps a
    scipy.sparse matrix."""

    def __init__(self, n=None, m=None, sm=None, dtype=dt.f32, storage_format="col_major"):
        sp = _scipy.sparse()
        if sm is None:
            self.dtype = _value_type(dtype, "SparseMatrix")
            self._format = _storage(storage_format, "SparseMatrix")
            self.n = _size(n, "SparseMatrix: n")
            self.m = _size(m if m else n, "SparseMatrix: m")
            self.matrix = sp.csc_matrix((self.n, self.m), dtype=self.dtype.np) if self._format == "csc" else \
                sp.csr_matrix((self.n, self.m), dtype=self.dtype.np)
            return
        if not sp.issparse(sm):
            raise SimgradTypeError(f"SparseMatrix(sm=...) takes a scipy.sparse matrix, got {type(sm).__name__}",
                                   caller_loc())
        self._format = sm.format if sm.format in ("csc", "csr") else "csc"
        self.dtype = dt.f64 if sm.dtype == np.float64 else dt.f32
        self.matrix = sm.asformat(self._format).astype(self.dtype.np, copy=False)
        self.n, self.m = (int(x) for x in sm.shape)

    @classmethod
    def _wrap(cls, sm, fmt: str) -> SparseMatrix:
        out = cls.__new__(cls)
        out._format = fmt
        out.dtype = dt.f64 if sm.dtype == np.float64 else dt.f32
        out.matrix = sm.asformat(fmt)
        out.n, out.m = (int(x) for x in sm.shape)
        return out

    # -- arithmetic ---------------------------------------------------------------------------------
    def _same_shape(self, other, op: str) -> None:
        if not isinstance(other, SparseMatrix):
            raise SimgradTypeError(f"sparse matrix {op}: the other operand must be a SparseMatrix, got "
                                   f"{type(other).__name__}", caller_loc())
        if (self.n, self.m) != (other.n, other.m):
            raise SimgradAssertionError(f"Dimension mismatch between sparse matrices ({self.n}, {self.m}) and "
                                        f"({other.n}, {other.m})", caller_loc())

    def __add__(self, other):
        self._same_shape(other, "addition")
        return SparseMatrix._wrap(self.matrix + other.matrix, self._format)

    def __sub__(self, other):
        self._same_shape(other, "subtraction")
        return SparseMatrix._wrap(self.matrix - other.matrix, self._format)

    def __iadd__(self, other):
        self._same_shape(other, "addition")
        self.matrix = (self.matrix + other.matrix).asformat(self._format)
        self.dtype = dt.f64 if self.matrix.dtype == np.float64 else dt.f32
        return self

    def __isub__(self, other):
        self._same_shape(other, "subtraction")
        self.matrix = (self.matrix - other.matrix).asformat(self._format)
        self.dtype = dt.f64 if self.matrix.dtype == np.float64 else dt.f32
        return self

    def _scale(self, k):
        return SparseMatrix._wrap((self.matrix * self.dtype.np.type(k)).astype(self.dtype.np, copy=False), self._format)

    def __mul__(self, other):
        """A number times the matrix, or the elementwise (Hadamard) product with another SparseMatrix."""
        if isinstance(other, (int, float, np.integer, np.floating)) and not isinstance(other, bool):
            return self._scale(other)
        if isinstance(other, SparseMatrix):
            self._same_shape(other, "elementwise multiplication")
            return SparseMatrix._wrap(self.matrix.multiply(other.matrix), self._format)
        return NotImplemented

    def __rmul__(self, other):
        if isinstance(other, (int, float, np.integer, np.floating)) and not isinstance(other, bool):
            return self._scale(other)
        return NotImplemented

    def transpose(self) -> SparseMatrix:
        return SparseMatrix._wrap(self.matrix.transpose(), self._format)

    def __matmul__(self, other):
        """With a SparseMatrix: the sparse product. With a vector: a numpy array for a numpy array or a field
        (of the matrix's dtype), a ti.ndarray of the vector's dtype for a ti.ndarray."""
        from simgrad.lang.field import Field
        from simgrad.lang.ndarray import Ndarray, ScalarNdarray

        if isinstance(other, SparseMatrix):
            if self.m != other.n:
                raise SimgradAssertionError(f"Dimension mismatch between sparse matrices ({self.n}, {self.m}) and "
                                            f"({other.n}, {other.m})", caller_loc())
            return SparseMatrix._wrap(self.matrix @ other.matrix, self._format)
        if isinstance(other, (Field, np.ndarray)):
            v = other.to_numpy() if isinstance(other, Field) else other
            if v.ndim != 1 or v.shape[0] != self.m:
                raise SimgradAssertionError(f"Dimension mismatch between sparse matrix ({self.n}, {self.m}) and "
                                            f"vector ({tuple(v.shape)})", caller_loc())
            return np.asarray(self.matrix @ v.astype(self.dtype.np, copy=False))
        if isinstance(other, Ndarray):
            if other.element_shape or len(other.shape) != 1 or other.shape[0] != self.m:
                raise SimgradRuntimeError(f"Dimension mismatch between sparse matrix ({self.n}, {self.m}) and "
                                          f"vector ({other.shape})", caller_loc())
            res = ScalarNdarray(other.dtype, (self.n,))
            res._ndarray[...] = self.matrix @ other._ndarray.astype(self.dtype.np, copy=False)
            return res
        raise SimgradRuntimeError(f"Sparse matrix-matrix/vector multiplication does not support "
                                  f"{type(other).__name__}: supported are SparseMatrix, fields, ti.ndarray and "
                                  "numpy arrays", caller_loc())

    # -- elements ---------------------------------------------------------------------------------
    def _index(self, indices) -> tuple[int, int]:
        if not isinstance(indices, tuple) or len(indices) != 2:
            raise SimgradIndexError(f"a sparse matrix takes two indices, A[i, j]; got {indices!r}", caller_loc())
        i, j = indices
        for k, (x, n) in enumerate(zip((i, j), (self.n, self.m))):
            if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or not 0 <= x < n:
                raise SimgradIndexError(f"index {x!r} of axis {k} is out of bounds for the sparse matrix of shape "
                                        f"{self.shape}", caller_loc())
        return int(i), int(j)

    def __getitem__(self, indices) -> float:
        i, j = self._index(indices)
        return float(self.matrix[i, j])

    def __setitem__(self, indices, value) -> None:
        i, j = self._index(indices)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy's SparseEfficiencyWarning for a new nonzero
            self.matrix[i, j] = value

    @property
    def shape(self) -> tuple[int, int]:
        return (self.n, self.m)

    def __str__(self) -> str:
        """The dense matrix as Taichi prints it (Eigen's format, precision 4): one bracketed row per line, every
        entry right-aligned to the widest."""
        dense = self.matrix.toarray()
        cells = [[_eigen_number(float(v)) for v in row] for row in dense]
        width = max((len(c) for row in cells for c in row), default=0)
        return "\n".join("[" + ", ".join(c.rjust(width) for c in row) + "]" for row in cells)

    __repr__ = __str__

    def build_from_ndarray(self, ndarray) -> None:
        """Replace the matrix by the triplets (row, column, value) an ndarray holds, three scalars each in
        order (a ti.ndarray, ti.Vector.ndarray or ti.Matrix.ndarray); duplicates are summed."""
        from simgrad.lang.ndarray import Ndarray

        if not isinstance(ndarray, Ndarray):
            raise SimgradRuntimeError("Sparse matrix only supports building from [ti.ndarray, ti.Vector.ndarray, "
                                      f"ti.Matrix.ndarray], got {type(ndarray).__name__}", caller_loc())
        num = reduce(lambda a, b: a * b, tuple(ndarray.shape) + tuple(ndarray.element_shape), 1)
        if num % 3 != 0:
            raise SimgradRuntimeError("The number of ndarray elements must have a length that is divisible by 3.",
                                      caller_loc())
        t = ndarray._ndarray.reshape(-1, 3)
        rows, cols = _triplet_index(t[:, 0], "row"), _triplet_index(t[:, 1], "column")
        self.matrix = _assemble(rows, cols, t[:, 2], self.n, self.m, self.dtype, self._format)

    def mmwrite(self, filename) -> None:
        """Write the matrix in Matrix Market coordinate format (entries in storage order, 1-based, as Eigen's
        saveMarket writes them)."""
        coo = self.matrix.tocoo()
        key = np.lexsort((coo.row, coo.col)) if self._format == "csc" else np.lexsort((coo.col, coo.row))
        lines = ["%%MatrixMarket matrix coordinate real general", "%", f"{self.n} {self.m} {coo.nnz}"]
        lines += [f"{coo.row[k] + 1} {coo.col[k] + 1} {float(coo.data[k]):g}" for k in key]
        with open(filename, "w") as f:
            f.write("\n".join(lines) + "\n")


def _triplet_index(values: np.ndarray, what: str) -> np.ndarray:
    if values.dtype.kind == "f":
        if not np.all(np.isfinite(values)):
            raise SimgradValueError(f"a triplet's {what} index is not a finite number", caller_loc())
        values = np.trunc(values)
    return values.astype(np.int64)


def _assemble(rows, cols, vals, n: int, m: int, t: dt.DataType, fmt: str):
    """The n x m matrix of triplets (duplicates summed), every index checked."""
    for idx, extent, what in ((rows, n, "row"), (cols, m, "column")):
        bad = np.flatnonzero((idx < 0) | (idx >= extent))
        if bad.size:
            k = int(bad[0])
            raise SimgradIndexError(f"triplet {k} ({int(rows[k])}, {int(cols[k])}) has a {what} index out of "
                                    f"bounds for the sparse matrix of shape ({n}, {m})", caller_loc())
    sp = _scipy.sparse()
    coo = sp.coo_matrix((np.asarray(vals, dtype=t.np), (rows, cols)), shape=(n, m), dtype=t.np)
    return coo.tocsc() if fmt == "csc" else coo.tocsr()


class TripletStore:
    """A builder's triplets as kernels see them (runtime/args.py `builder_info`): `count` (one i64, the
    number of triplets added; past `capacity` the excess were dropped), `rows`, `cols` (i32) and `values`."""

    def __init__(self, capacity: int, dtype: dt.DataType):
        from simgrad.lang.program import get_program

        zeros = get_program().zeros  # memory kernels can write: the device's on arch=cuda (a launch that adds
        self.capacity, self.dtype = capacity, dtype  # triplets waits for its kernel: runtime/args.py)
        self.count = zeros(1, np.int64)
        self.rows = zeros(max(capacity, 1), np.int32)[:capacity]
        self.cols = zeros(max(capacity, 1), np.int32)[:capacity]
        self.values = zeros(max(capacity, 1), dtype.np)[:capacity]

    def size(self, what: str) -> int:
        n = int(self.count[0])
        if n > self.capacity:
            raise SimgradRuntimeError(f"{what}: the sparse matrix builder was given {n} triplets, more than its "
                                      f"max_num_triplets={self.capacity}", caller_loc())
        return n


class SparseMatrixBuilder:
    """Collects triplets (i, j, value) for a sparse matrix: pass it to a kernel parameter annotated
    `ti.types.sparse_matrix_builder()` and write `A[i, j] += v` (or `-= v`) there; then build().

    At most max_num_triplets triplets fit (over all launches until build()); a launch that adds more raises
    an error, and so does build()."""

    def __init__(self, num_rows=None, num_cols=None, max_num_triplets=0, dtype=dt.f32, storage_format="col_major"):
        self.num_rows = _size(num_rows, "SparseMatrixBuilder: num_rows")
        self.num_cols = _size(num_cols if num_cols else num_rows, "SparseMatrixBuilder: num_cols")
        self.dtype = _value_type(dtype, "SparseMatrixBuilder")
        self._format = _storage(storage_format, "SparseMatrixBuilder")
        self.max_num_triplets = _size(max_num_triplets, "SparseMatrixBuilder: max_num_triplets")
        if self.max_num_triplets >= 2**31:
            raise SimgradValueError("SparseMatrixBuilder: max_num_triplets must be below 2**31", caller_loc())
        self._triplets = TripletStore(self.max_num_triplets, self.dtype)

    def print_triplets(self) -> None:
        """Print the triplets added so far, one `[i, j] = v` line each, in the order they were stored."""
        t = self._triplets
        n = int(t.count[0])
        print(f"n={self.num_rows}, m={self.num_cols}, num_triplets={n} (max={t.capacity})")
        for k in range(min(n, t.capacity)):
            print(f"[{t.rows[k]}, {t.cols[k]}] = {_shortest(t.values[k], self.dtype)}")

    def build(self, dtype=None, _format="CSR") -> SparseMatrix:
        """The sparse matrix of the triplets added so far (duplicates summed); the builder is then empty, as
        Taichi's is. (Taichi ignores both arguments on the CPU; so does simgrad.)"""
        t = self._triplets
        n = t.size("SparseMatrixBuilder.build")
        sm = _assemble(t.rows[:n].astype(np.int64), t.cols[:n].astype(np.int64), t.values[:n], self.num_rows,
                       self.num_cols, self.dtype, self._format)
        t.count[0] = 0
        return SparseMatrix._wrap(sm, self._format)

    def __repr__(self) -> str:
        return (f"<SparseMatrixBuilder {self.num_rows}x{self.num_cols} {self.dtype} "
                f"{int(self._triplets.count[0])}/{self.max_num_triplets} triplets>")




__all__ = ["SparseMatrix", "SparseMatrixBuilder"]
