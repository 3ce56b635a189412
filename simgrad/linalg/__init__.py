"""ti.linalg: sparse matrices, their builder (a kernel argument), direct and CG solvers on scipy.sparse, and
matrix-free CG / BiCGSTAB over fields with simgrad kernels. scipy is imported when a sparse matrix or solver
is first made (pip install simgrad[linalg]); the matrix-free solvers do not need it."""

from simgrad.errors import TaichiRuntimeError, TaichiTypeError
from simgrad.linalg.matrixfree_cg import LinearOperator, MatrixFreeBICGSTAB, MatrixFreeCG
from simgrad.linalg.sparse_cg import SparseCG
from simgrad.linalg.sparse_matrix import SparseMatrix, SparseMatrixBuilder
from simgrad.linalg.sparse_solver import SparseSolver

__all__ = ["LinearOperator", "MatrixFreeBICGSTAB", "MatrixFreeCG", "SparseCG", "SparseMatrix",
           "SparseMatrixBuilder", "SparseSolver", "TaichiRuntimeError", "TaichiTypeError"]
