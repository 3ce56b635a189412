"""Small-matrix decompositions (ti.polar_decompose, ti.svd, ti.sym_eig), unrolled into scalar IR.

Everything here is straight-line code: a fixed number of Jacobi sweeps, branches as `operators.select`, so the
same code runs on Python floats (Python scope) and on kernel values, and reverse-mode autodiff can
differentiate it entry by entry.

Method (written from the textbook description of cyclic Jacobi and Givens QR):

* `sym_eig`: cyclic Jacobi rotations on the (symmetrised) matrix, then a select-based sorting network.
* `svd`: one-sided (Hestenes) cyclic Jacobi rotates the columns of B = A V until they are orthogonal
  (the rotations of Jacobi on AᵀA, without forming AᵀA); a Givens QR of B (B = U R) then gives U, with
  R diagonal up to rounding: S = diag(R). Sorting V's columns by decreasing σ² first makes R's diagonal
  decreasing, and because U and V are products of rotations (column swaps negate one column), both are
  rotations: the sign of det(A) ends up on the last, smallest singular value, Taichi's convention for
  3x3 (we use it for 2x2 too, where Taichi lets U be a reflection).

Degenerate inputs (zero matrix, repeated singular values) stay finite in value *and* derivative: the
input is first scaled by a power of two to a largest entry in [1, 2), and every sqrt/rsqrt/division
whose argument can be zero is guarded by a `tiny` (1e-18 in f32, 1e-60 in f64) relative to that
scale: tiny enough to change no result above rounding level, large enough that tiny**2 is a normal
number (derivatives like -a/y**2 stay finite). Python scope computes in Python floats with the f64
constants.
"""

from __future__ import annotations

import math

from simgrad import dtypes as dt
from simgrad.errors import SimgradTypeError
from simgrad.ir import context
from simgrad.ir.ops import Op
from simgrad.lang import operators
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix

# sweeps of cyclic Jacobi for 3x3 (one rotation is exact for 2x2): convergence is quadratic; 4 sweeps
# already reach rounding level on clustered and ill-conditioned inputs, the last one is margin
_SWEEPS = {32: 4, 64: 5}
_TINY = {32: 1e-18, 64: 1e-60}
# 2x2 polar: ((below, scale up), (above, scale down), floor of r2); f32: every normal |x| lands in
# [2^-40, 2^50], so r2 in [2^-80, 2^101] and r2^-1.5 < 2^120 (finite); f64 has room to spare
_POLAR_RANGE = {
    32: ((2.0**-40, 2.0**90), (2.0**40, 2.0**-80), 2.0**-100),
    64: ((2.0**-300, 2.0**700), (2.0**300, 2.0**-600), 2.0**-660),
}
_PAIRS = {2: [(0, 1)], 3: [(0, 1), (0, 2), (1, 2)]}


class _Work:
    """The working precision: the kernel dtype (None in Python scope) and its guard constant."""

    def __init__(self, A, dt_, what: str = "this decomposition"):
        if not isinstance(A, (Matrix, list, tuple)):
            raise SimgradTypeError(f"{what} only supports 2D and 3D matrices: got a {type(A).__name__} (pass a "
                                   "matrix value, e.g. m[i] of a matrix field)", _loc())
        self.A = A if isinstance(A, Matrix) else Matrix(A)
        if self.A.m != self.A.n or self.A.n not in (2, 3):
            raise SimgradTypeError(f"{what} only supports 2D and 3D matrices: got shape {self.A.shape}", _loc())
        self.n = self.A.n
        exprs = [e for e in self.A.entries if isinstance(e, Expr)]
        if not exprs:
            self.dtype = None
            self.bits = 64
            self.entries = [float(e) for e in self.A.entries]
        else:
            if dt_ is not None:
                t = dt.from_any(dt_)
            else:
                floats = [e.dtype for e in exprs if e.dtype.is_float]
                t = floats[0] if floats else dt.Defaults.fp
                for f in floats[1:]:
                    t = dt.promote(t, f)
            t = dt.f32 if t is dt.f16 else t
            self.dtype = t
            self.bits = 64 if t.bits == 64 else 32
            self.entries = [operators.cast(e, t) for e in self.A.entries]
        self.tiny = _TINY[self.bits]
        self.sweeps = _SWEEPS[self.bits] if self.n == 3 else 1

    def rows(self, entries=None):
        e = self.entries if entries is None else entries
        return [[e[i * self.n + j] for j in range(self.n)] for i in range(self.n)]

    def scaled(self):
        """(A * 2**-e, 2**e) with 2**e ~ the largest |entry|: makes the guards scale-free and keeps AᵀA
        clear of overflow/underflow. A power of two scales exactly, and e is piecewise constant (floor),
        so no derivative flows through it: the result is exactly differentiable as f(A 2**-e) 2**e."""
        lo, hi = (-126, 126) if self.bits == 32 else (-1022, 1022)
        s = operators.max(*[operators.abs(e) for e in self.entries])
        if self.dtype is None:  # Python floats: frexp's exponent is floor(log2 s) + 1
            e = min(max(math.frexp(max(s, 2.0**lo))[1] - 1, lo), hi)
            return [x * 2.0**-e for x in self.entries], 2.0**e
        # in kernels the exponent field of s's bits (s >= 2**lo is normal and positive): floor(log2 s) exactly,
        # and the powers of two built from bits, where log and two pow calls cost a quarter of an MPM step
        ity, mant, bias = (dt.i32, 23, 127) if self.bits == 32 else (dt.i64, 52, 1023)
        s = operators.max(s, self.const(2.0**lo))
        e = operators.sub(operators.shr(operators.bit_cast(s, ity), mant), bias)
        e = operators.min(operators.max(e, lo), hi)
        inv = self.power_of_two(operators.sub(bias, e), mant)
        return [x * inv for x in self.entries], self.power_of_two(operators.add(bias, e), mant)

    def power_of_two(self, biased, mant: int):
        """The float whose exponent field is `biased`: piecewise constant in the input, so marked as having no
        derivative (a user's ti.bit_cast to a float has no rule and says so)."""
        bits = operators.shl(biased, mant)
        return Expr(context.builder().emit(Op.BITCAST, self.dtype, (bits.stmt,), {"zero_gradient": True}))

    def const(self, v: float):
        """A constant of the working type (two bare literals in a select would get default_fp)."""
        return v if self.dtype is None else operators.cast(v, self.dtype)

    def eye(self):
        """Python floats, also in kernels: the first rotations applied to them fold at trace time."""
        return [[1.0 if i == j else 0.0 for j in range(self.n)] for i in range(self.n)]


def _rotation(app, aqq, apq, tiny):
    """(c, s) of the Jacobi rotation that diagonalises [[app, apq], [apq, aqq]]."""
    d = aqq - app
    # t = tan(theta), the smaller root of t^2 + 2 t cot(2 theta) - 1 = 0, in a form with no division by
    # apq: t = 2 apq / (d + sign(d) sqrt(d^2 + 4 apq^2)); tiny keeps sqrt off 0 when apq = d = 0 (t = 0)
    r = operators.sqrt(d * d + 4.0 * apq * apq + tiny)
    t = 2.0 * apq / (d + operators.select(d >= 0.0, r, -r))
    c = operators.rsqrt(1.0 + t * t)
    return c, t * c, t


def _rotate_cols(M, p, q, c, s):
    """M <- M J: columns p, q rotated."""
    for k in range(len(M)):
        mp, mq = M[k][p], M[k][q]
        M[k][p] = c * mp - s * mq
        M[k][q] = s * mp + c * mq


def _jacobi(S, V, p, q, tiny):
    """One two-sided Jacobi rotation in the (p, q) plane: zeroes S[p][q] (S symmetric, updated in place)
    and accumulates V <- V J, so that the original S = V diag V^T."""
    c, s, t = _rotation(S[p][p], S[q][q], S[p][q], tiny)
    to = t * S[p][q]
    S[p][p] = S[p][p] - to
    S[q][q] = S[q][q] + to
    S[p][q] = S[q][p] = 0.0
    for k in range(len(S)):
        if k != p and k != q:
            skp, skq = S[k][p], S[k][q]
            S[k][p] = S[p][k] = c * skp - s * skq
            S[k][q] = S[q][k] = s * skp + c * skq
    _rotate_cols(V, p, q, c, s)


def _col_dot(B, i, j):
    return _sum([B[k][i] * B[k][j] for k in range(len(B))])


def _one_sided(w: _Work, B):
    """One-sided (Hestenes) Jacobi: rotate B's columns (B <- B J, V <- V J) until they are orthogonal;
    returns V. The same rotations as two-sided Jacobi on BᵀB, but the
    off-diagonal inner product is recomputed from the current columns each time, which keeps small
    singular values accurate (BᵀB itself would square the condition number); the squared norms follow
    the rotations by the exact 2x2 update (they only steer the angles)."""
    V = w.eye()
    nrm = [_col_dot(B, i, i) for i in range(w.n)]
    for _ in range(w.sweeps):
        for p, q in _PAIRS[w.n]:
            g = _col_dot(B, p, q)
            c, s, t = _rotation(nrm[p], nrm[q], g, w.tiny)
            nrm[p], nrm[q] = nrm[p] - t * g, nrm[q] + t * g
            _rotate_cols(B, p, q, c, s)
            _rotate_cols(V, p, q, c, s)
    return V


def _eig_sym(w: _Work, S):
    """Jacobi eigen-decomposition of a symmetric S (lists of rows): (eigenvalues, V with columns as
    eigenvectors), unsorted."""
    V = w.eye()
    for _ in range(w.sweeps):
        for p, q in _PAIRS[w.n]:
            _jacobi(S, V, p, q, w.tiny)
    return [S[i][i] for i in range(w.n)], V


def _sort(vals, mats, descending: bool, keep_det: bool):
    """Sort `vals`, permuting the columns of each matrix in `mats` alike, by a fixed compare-swap network;
    with keep_det a swap also negates one column so determinants are unchanged."""
    n = len(vals)
    for i, j in _PAIRS[n]:
        a, b = vals[i], vals[j]
        swap = operators.lt(a, b) if descending else operators.gt(a, b)
        vals[i], vals[j] = operators.select(swap, b, a), operators.select(swap, a, b)
        for M in mats:
            for k in range(n):
                x, y = M[k][i], M[k][j]
                M[k][i] = operators.select(swap, y, x)
                M[k][j] = operators.select(swap, -x if keep_det else x, y)


def _givens_qr(w: _Work, B):
    """B = U R by Givens rotations (U a rotation, R upper triangular, in place in B); returns U. A pair
    that is already ~zero is left alone (identity rotation) instead of normalising a zero vector."""
    U = w.eye()
    steps = [(0, 1, 0)] if w.n == 2 else [(0, 1, 0), (0, 2, 0), (1, 2, 1)]
    for p, q, col in steps:
        a, b = B[p][col], B[q][col]
        r2 = a * a + b * b
        ok = r2 > w.tiny
        inv = operators.rsqrt(operators.max(r2, w.tiny))
        c = operators.select(ok, a * inv, 1.0)
        s = operators.select(ok, b * inv, 0.0)
        for j in range(w.n):
            bp, bq = B[p][j], B[q][j]
            B[p][j] = c * bp + s * bq
            B[q][j] = c * bq - s * bp
        for k in range(w.n):
            up, uq = U[k][p], U[k][q]
            U[k][p] = c * up + s * uq
            U[k][q] = c * uq - s * up
    return U


def svd(A, dt=None):
    """A = U @ S @ V.transpose() for 2x2/3x3 A: returns (U, S, V), U and V rotations, S diagonal with
    |S| decreasing; the last entry of S carries the sign of det(A) (Taichi's convention)."""
    w = _Work(A, dt, "SVD")
    a, scale = w.scaled()
    B = w.rows(a)
    V = _one_sided(w, B)
    norms = [_col_dot(B, i, i) for i in range(w.n)]
    _sort(norms, [B, V], descending=True, keep_det=True)
    U = _givens_qr(w, B)
    S = [[B[i][i] * scale if i == j else 0.0 for j in range(w.n)] for i in range(w.n)]
    return Matrix(U), Matrix(S), Matrix(V)


def sym_eig(A, dt=None):
    """Eigen-decomposition of a symmetric 2x2/3x3 A: (eigenvalues vector, matrix with the unit
    eigenvectors as columns). Order follows Taichi: decreasing for 2x2, increasing for 3x3. Only the
    symmetric part of A is used."""
    w = _Work(A, dt, "Symmetric eigen decomposition")
    a, scale = w.scaled()
    R = w.rows(a)
    S = [[R[i][i] if i == j else 0.5 * (R[i][j] + R[j][i]) for j in range(w.n)] for i in range(w.n)]
    lam, V = _eig_sym(w, S)
    _sort(lam, [V], descending=w.n == 2, keep_det=False)
    return Matrix([x * scale for x in lam]), Matrix(V)


def polar_decompose(A, dt=None):
    """A = U @ P with U a rotation and P symmetric; returns (U, P). 2x2 in closed form (the rotation
    closest to A), 3x3 through the SVD: U = U_svd V^T, P = V S V^T."""
    w = _Work(A, dt, "Polar decomposition")
    if w.n == 2:
        a, b, c, d = w.entries
        x, y = a + d, c - b
        # The rotation is (x, y) normalised. This runs per particle in MPM codes, so instead of svd's
        # log/pow scaling, (x, y) is brought into a safe range by a select between constant powers of two
        # (exact, and piecewise constant: no derivative through it). Then x^2 + y^2 neither overflows
        # nor underflows, and rsqrt(r2)**3 in the derivative stays finite; r2 <= floor means x = y = 0
        # (A = [[p, q], [q, -p]]: every rotation is equally close, take I) or a subnormal A.
        m = operators.max(operators.abs(x), operators.abs(y))
        (lo, up), (hi, down), floor = _POLAR_RANGE[w.bits]
        one = w.const(1.0)
        k = operators.select(m < lo, w.const(up), one) * operators.select(m > hi, w.const(down), one)
        x, y = x * k, y * k
        r2 = x * x + y * y
        ok = r2 > floor
        inv = operators.rsqrt(operators.select(ok, r2, 1.0))
        cs, sn = operators.select(ok, x * inv, 1.0), operators.select(ok, y * inv, 0.0)
        U = Matrix([[cs, -sn], [sn, cs]])
        return U, U.transpose() @ Matrix(w.rows())
    U, S, V = svd(Matrix(w.rows()), w.dtype)
    return U @ V.transpose(), V @ S @ V.transpose()


def _sum(xs):
    out = xs[0]
    for x in xs[1:]:
        out = out + x
    return out


def eig(A, dt=None):
    """Eigenvalues and right eigenvectors of a real 2x2 A, in Taichi's complex layout: (2x2 matrix whose
    rows are the eigenvalues as (real, imaginary), 4x2 matrix whose columns are the unit eigenvectors as
    (re, im, re, im)). As in Taichi, an eigenvector of one eigenvalue is a column of A minus the other
    eigenvalue (Cayley-Hamilton: the first, else the second when the first is zero), and A = c*I gives the
    unit axes. Unlike Taichi (NaN), a repeated eigenvalue gets a unit eigenvector. 2x2 only, as Taichi."""
    w = _Work(A, dt, "ti.eig")
    if w.n != 2:
        raise ValueError("ti.eig supports 2x2 matrices only (as Taichi)")
    a, b, c, d = w.entries
    tr, det = a + d, a * d - b * c
    gap = tr * tr - 4.0 * det
    real = gap >= 0
    zero, one = w.const(0.0), w.const(1.0)
    s = operators.sqrt(operators.select(real, gap, zero))
    si = operators.sqrt(operators.select(real, zero, -gap))
    l1, l2 = [(tr + s) * 0.5, si * 0.5], [(tr - s) * 0.5, operators.select(real, zero, -si * 0.5)]  # +0.0, as Taichi

    def vector(other):  # a nonzero column of A - other * I (complex), normalised
        im = operators.select(real, zero, -other[1])
        col0 = [a - other[0], im, c, zero]
        col1 = [b, zero, d - other[0], im]
        n0, n1 = _sum([x * x for x in col0]), _sum([x * x for x in col1])
        first = n0 > 0
        v = [operators.select(first, x, y) for x, y in zip(col0, col1)]
        norm2 = operators.select(first, n0, n1)
        inv = 1.0 / operators.sqrt(operators.select(norm2 > 0, norm2, one))
        return [x * inv for x in v], norm2 > 0

    (v1, ok1), (v2, ok2) = vector(l2), vector(l1)
    v1 = [operators.select(ok1, x, e) for e, x in zip((zero, zero, one, zero), v1)]
    v2 = [operators.select(ok2, x, e) for e, x in zip((one, zero, zero, zero), v2)]
    return Matrix([l1, l2]), Matrix([[v1[k], v2[k]] for k in range(4)])


def solve(A, b, dt=None):
    """x with A x = b for 2x2/3x3 A: Gaussian elimination with partial pivoting (row swaps as selects), as
    Taichi's ti.solve. A singular A gives inf/nan, as there."""
    w = _Work(A, dt, "ti.solve")
    bv = b if isinstance(b, Matrix) else Matrix(b)
    if bv.n != w.n:
        raise ValueError(f"ti.solve: a {w.n}x{w.n} matrix needs a vector of {w.n} entries, got {bv.n}")
    n = w.n
    rhs = [operators.cast(e, w.dtype) if w.dtype is not None else float(e) for e in bv.entries]
    M = [row + [rhs[i]] for i, row in enumerate(w.rows())]
    for i in range(n):
        # the row with the largest |pivot| (the first of equals) swaps with row i
        best, chosen = operators.abs(M[i][i]), i
        for j in range(i + 1, n):
            take = operators.abs(M[j][i]) > best
            best, chosen = operators.select(take, operators.abs(M[j][i]), best), operators.select(take, j, chosen)
        old = [list(r) for r in M]
        for j in range(i + 1, n):
            here = chosen == j
            M[i] = [operators.select(here, y, x) for x, y in zip(M[i], old[j])]
            M[j] = [operators.select(here, x, y) for x, y in zip(old[i], old[j])]
        for j in range(i + 1, n):
            scale = M[j][i] / M[i][i]
            M[j] = [M[j][k] - M[i][k] * scale if k > i else w.const(0.0) for k in range(n + 1)]
    x: list = [None] * n
    for i in reversed(range(n)):
        acc = M[i][n]
        for k in range(i + 1, n):
            acc = acc - M[i][k] * x[k]
        x[i] = acc / M[i][i]
    return Matrix(x)


def _loc():
    from simgrad.ir import context

    return context.current_loc()
