"""ti.linalg.SparseCG: conjugate gradients for a SparseMatrix (Taichi runs Eigen's ConjugateGradient on the
CPU: a Jacobi preconditioner and a residual measured relative to b; so does this numpy loop)."""

from __future__ import annotations

import numpy as np

from simgrad.errors import SimgradRuntimeError, caller_loc
from simgrad.linalg.sparse_matrix import SparseMatrix


def _vector(v, n: int, dtype, what: str) -> np.ndarray:
    from simgrad.lang.ndarray import Ndarray

    a = v._ndarray if isinstance(v, Ndarray) else np.asarray(v)
    if a.shape != (n,):
        raise SimgradRuntimeError(f"SparseCG: {what} has shape {a.shape}, expected ({n},)", caller_loc())
    return a.astype(dtype, copy=True)


class SparseCG:
    """Solves A x = b for a symmetric positive definite SparseMatrix A; solve() returns (x, converged)."""

    def __init__(self, A, b, x0=None, max_iter=50, atol=1e-6):
        if not isinstance(A, SparseMatrix):
            raise SimgradRuntimeError(f"SparseCG takes a SparseMatrix, got {type(A).__name__}", caller_loc())
        self.matrix, self.dtype = A, A.dtype
        self.max_iter, self.atol = int(max_iter), float(atol)
        t = A.dtype.np
        self.b = _vector(b, A.n, t, "b")
        self.x = _vector(x0, A.m, t, "x0") if x0 is not None else np.zeros(A.m, dtype=t)
        self._ok = False

    def solve(self):
        a = self.matrix.matrix
        b, x = self.b, self.x.copy()
        diag = a.diagonal()
        inv = np.where(diag != 0, 1 / np.where(diag != 0, diag, 1), 1).astype(b.dtype)
        r = b - a @ x
        bnorm2 = float(b @ b)
        tol2 = self.atol * self.atol * (bnorm2 if bnorm2 > 0 else 1.0)
        ok = float(r @ r) <= tol2
        if not ok:
            z = inv * r
            p = z.copy()
            rz = float(r @ z)
            for _ in range(self.max_iter):
                ap = a @ p
                pap = float(p @ ap)
                if pap == 0 or not np.isfinite(pap):
                    break  # a breakdown (A is not positive definite): not converged
                alpha = rz / pap
                x += alpha * p
                r -= alpha * ap
                if float(r @ r) <= tol2:
                    ok = True
                    break
                z = inv * r
                rz_new = float(r @ z)
                if rz == 0:
                    break
                p = z + (rz_new / rz) * p
                rz = rz_new
        self._ok = bool(ok and np.all(np.isfinite(x)))
        return x, self._ok
