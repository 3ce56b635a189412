"""Small-matrix decompositions (ti.polar_decompose, ti.svd, ti.sym_eig), unrolled into scalar IR."""

from __future__ import annotations

from simgrad.lang import ops
from simgrad.lang.matrix import Matrix


def polar_decompose(A, dt=None):
    """A = U P with U a rotation and P symmetric; returns (U, P)."""
    if A.n == 2:
        a, b, c, d = A.entries
        x = ops.add(a, d)
        y = ops.sub(c, b)
        scale = ops.rsqrt(ops.add(ops.mul(x, x), ops.mul(y, y)))
        cs, sn = ops.mul(x, scale), ops.mul(y, scale)
        U = Matrix([[cs, ops.neg(sn)], [sn, cs]])
        P = U.transpose() @ A
        return U, P
    U, S, V = svd(A, dt)
    return U @ V.transpose(), V @ S @ V.transpose()


def svd(A, dt=None):
    raise NotImplementedError("ti.svd is not implemented yet")


def sym_eig(A, dt=None):
    raise NotImplementedError("ti.sym_eig is not implemented yet")
