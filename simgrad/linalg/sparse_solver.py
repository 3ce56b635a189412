"""ti.linalg.SparseSolver on scipy's SuperLU.

Taichi factorises with Eigen: SimplicialLLT / SimplicialLDLT (which read only the lower triangle of the
matrix, taking it as symmetric) and SparseLU. simgrad does all three with scipy.sparse.linalg.splu:
- "LU": splu of the matrix (partial pivoting).
- "LLT" and "LDLT": splu of the symmetric matrix the lower triangle defines, with a symmetric ordering and a
  zero pivot threshold, so U's diagonal holds the LDLᵀ pivots: LDLT fails (info() False) on a singular matrix,
  LLT on any pivot that is not positive (the matrix is not positive definite), as Eigen's do. Unlike Eigen's,
  SuperLU still pivots around a zero leading diagonal entry of a nonsingular LDLT matrix and solves it, where
  taichi reports failure (tests/lang/test_linalg_sparse.py).
The ordering "AMD" is SuperLU's minimum degree on AᵀA+A ("MMD_AT_PLUS_A"), "COLAMD" its COLAMD. A failed
factorisation makes solve() return NaNs.

A matrix of at most DENSE_MAX rows is factorised dense (LAPACK through scipy.linalg), where SuperLU's set-up costs
~10x the arithmetic (72 x 72: 160 -> 12 us): LLT and LDLT by Cholesky of the same symmetric matrix, and an LDLT
whose matrix is not positive definite by the sparse path above, so that both paths agree; LU by LAPACK's
partial pivoting, as SuperLU's."""

from __future__ import annotations

import numpy as np

from simgrad import dtypes as dt
from simgrad.errors import SimgradRuntimeError, caller_loc
from simgrad.linalg import _scipy
from simgrad.linalg.sparse_matrix import SparseMatrix

_SOLVERS = ["LLT", "LDLT", "LU"]
_ORDERINGS = ["AMD", "COLAMD"]
#: the largest matrix factorised dense (its n^3 / 3 flops then still cost less than SuperLU's set-up)
DENSE_MAX = 160


def _symmetric_from_lower(sp, a):
    """The symmetric CSC matrix that ``a``'s lower triangle defines (what Eigen's LLT/LDLT read), its zeros
    dropped: the matrix ``tril(a) + tril(a, -1).T`` makes, from one COO pass (those scipy calls took ~3x as
    long; a frame of implicit_mass_spring factorises a 72 x 72 matrix)."""
    coo = a.tocoo()
    keep = (coo.row >= coo.col) & (coo.data != 0)
    r, c, v = coo.row[keep], coo.col[keep], coo.data[keep]
    off = r != c
    rows, cols = np.concatenate([r, c[off]]), np.concatenate([c, r[off]])
    return sp.csc_matrix((np.concatenate([v, v[off]]), (rows, cols)), shape=a.shape)


class SparseSolver:
    """Solves A x = b for a SparseMatrix A: analyze_pattern(A), factorize(A) (or compute(A)), then solve(b)."""

    def __init__(self, dtype=dt.f32, solver_type="LLT", ordering="AMD"):
        if solver_type not in _SOLVERS or ordering not in _ORDERINGS:
            raise SimgradRuntimeError(f"The solver type {solver_type} with {ordering} is not supported for now. "
                                      f"Only {_SOLVERS} with {_ORDERINGS} are supported.", caller_loc())
        self.dtype = dt.from_any(dtype)
        self.solver_type, self.ordering = solver_type, ordering
        self.matrix: SparseMatrix | None = None
        self._lu = None
        self._dense: tuple | None = None  # (LAPACK's solve function, the factors) of a small matrix
        self._ok: bool | None = None

    @staticmethod
    def _check_type(sparse_matrix) -> None:
        if not isinstance(sparse_matrix, SparseMatrix):
            raise SimgradRuntimeError(f"The parameter type: {type(sparse_matrix)} is not supported in linear "
                                      "solvers for now.", caller_loc())

    def compute(self, sparse_matrix) -> None:
        """analyze_pattern and factorize in one call."""
        self.analyze_pattern(sparse_matrix)
        self.factorize(sparse_matrix)

    def analyze_pattern(self, sparse_matrix) -> None:
        """Check the matrix (SuperLU orders the columns as part of factorize)."""
        self._check_type(sparse_matrix)
        if sparse_matrix.dtype is not self.dtype:
            raise SimgradRuntimeError(f"The SparseSolver's dtype {self.dtype} is not consistent with the "
                                      f"SparseMatrix's dtype {sparse_matrix.dtype}.", caller_loc())
        if sparse_matrix.n != sparse_matrix.m:
            raise SimgradRuntimeError(f"SparseSolver needs a square matrix, got shape {sparse_matrix.shape}",
                                      caller_loc())
        self.matrix = sparse_matrix

    def factorize(self, sparse_matrix) -> None:
        self._check_type(sparse_matrix)
        self.matrix = sparse_matrix
        a = sparse_matrix.matrix.astype(self.dtype.np, copy=False)
        self._lu, self._dense, self._ok = None, None, False
        if a.shape[0] == 0:
            self._ok = True
            return
        if a.shape[0] <= DENSE_MAX and self._factorize_dense(a):
            return
        sp, spla = _scipy.sparse(), _scipy.sparse_linalg()
        if self.solver_type == "LU":
            permc, options = ("COLAMD" if self.ordering == "COLAMD" else "MMD_AT_PLUS_A"), {}
            pivot = 1.0
        else:
            a = _symmetric_from_lower(sp, a)
            permc, options, pivot = "MMD_AT_PLUS_A", {"SymmetricMode": True}, 0.0
        try:
            lu = spla.splu(a.tocsc(), permc_spec=permc, diag_pivot_thresh=pivot, options=options)
        except RuntimeError:  # exactly singular
            return
        pivots = lu.U.diagonal()
        if not np.all(np.isfinite(pivots)) or np.any(pivots == 0):
            return
        if self.solver_type == "LLT" and np.any(pivots < 0):
            return  # not positive definite: Eigen's LLT reports NumericalIssue
        self._lu, self._ok = lu, True

    def _factorize_dense(self, a) -> bool:
        """Factorise the small matrix ``a`` with LAPACK; False leaves it to SuperLU (an LDLT that is not positive
        definite). A failure leaves info() False, as the sparse path does."""
        import warnings

        sl = _scipy.dense_linalg()
        d = a.toarray()
        if self.solver_type == "LU":
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # LAPACK's singular-matrix warning: info() says it
                lu = sl.lu_factor(d, check_finite=False)
            pivots = np.diagonal(lu[0])
            if np.all(np.isfinite(pivots)) and not np.any(pivots == 0):
                self._dense, self._ok = (sl.lu_solve, lu), True
            return True
        sym = np.tril(d) + np.tril(d, -1).T
        try:
            c = sl.cho_factor(sym, lower=True, check_finite=False)
        except np.linalg.LinAlgError:  # not positive definite
            return self.solver_type == "LLT"  # (an LDLT may still exist: SuperLU finds it, or fails as Eigen's)
        if np.all(np.isfinite(np.diagonal(c[0]))):
            self._dense, self._ok = (sl.cho_solve, c), True
        return True

    def _solve(self, b: np.ndarray) -> np.ndarray:
        assert self.matrix is not None
        n = self.matrix.m
        b = np.asarray(b)
        if b.shape != (self.matrix.n,):
            raise SimgradRuntimeError(f"SparseSolver.solve: the right-hand side has shape {b.shape}, the matrix "
                                      f"{self.matrix.shape}", caller_loc())
        if not self._ok:
            return np.full(n, np.nan, dtype=self.dtype.np)
        if self._dense is not None:
            solve, factors = self._dense
            return np.asarray(solve(factors, b.astype(self.dtype.np), check_finite=False), dtype=self.dtype.np)
        if self._lu is None:
            return np.zeros(n, dtype=self.dtype.np)
        return np.asarray(self._lu.solve(b.astype(self.dtype.np)), dtype=self.dtype.np)

    def solve(self, b):
        """x with A x = b: a numpy array for a numpy array or a field, a ti.ndarray for a ti.ndarray."""
        from simgrad.lang.field import Field
        from simgrad.lang.ndarray import Ndarray, ScalarNdarray

        if self.matrix is None or self._ok is None:
            raise SimgradRuntimeError("Please call compute() (or analyze_pattern() and factorize()) before "
                                      "calling solve().", caller_loc())
        if isinstance(b, Field):
            return self._solve(b.to_numpy())
        if isinstance(b, np.ndarray):
            return self._solve(b)
        if isinstance(b, Ndarray):
            x = ScalarNdarray(b.dtype, (self.matrix.m,))
            x._ndarray[...] = self._solve(b._ndarray)
            return x
        raise SimgradRuntimeError(f"The parameter type: {type(b)} is not supported in linear solvers for now.",
                                  caller_loc())

    def info(self) -> bool:
        """Whether the last factorisation succeeded (False before any)."""
        return bool(self._ok)
