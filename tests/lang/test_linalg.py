"""ti.svd / ti.sym_eig / ti.polar_decompose against numpy, in Python scope and in kernels (f32 and f64).

Expectations are numpy's (np.linalg.svd / eigh / det) plus the defining identities; the conventions
checked are Taichi's: rotations U, V with the sign of det(A) on the last (smallest) singular value,
singular values by decreasing magnitude, sym_eig eigenvalues decreasing for 2x2 and increasing for 3x3."""

import numpy as np
import pytest

import simgrad as ti

TOL = {ti.f32: 2e-5, ti.f64: 1e-11}


def _rot(rng, n):
    q, r = np.linalg.qr(rng.standard_normal((n, n)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _cases(n, count=24, seed=0):
    """Random, structured and degenerate n x n matrices (well scaled: entries O(1))."""
    rng = np.random.default_rng(seed + n)
    mats = [rng.standard_normal((n, n)) for _ in range(count)]
    mats += [
        np.zeros((n, n)),
        np.eye(n),
        -np.eye(n),
        np.diag(np.arange(1.0, n + 1)),
        np.diag(np.r_[-1.0, np.arange(2.0, n + 1)]),  # negative determinant, diagonal
        _rot(rng, n),  # all singular values 1
        _rot(rng, n) @ np.diag([2.0] * (n - 1) + [0.5]) @ _rot(rng, n).T,  # repeated largest
        _rot(rng, n) @ np.diag([1.0] + [0.0] * (n - 1)) @ _rot(rng, n).T,  # rank one
        _rot(rng, n) @ np.diag([1.0] * (n - 1) + [1e-7]) @ _rot(rng, n).T,  # near singular
        _rot(rng, n) @ np.diag([1.0] * (n - 1) + [-1e-3]) @ _rot(rng, n).T,  # det < 0, small
        np.outer(np.arange(1.0, n + 1), np.ones(n)),  # rank one, exact
        1e-6 * rng.standard_normal((n, n)),
        1e6 * rng.standard_normal((n, n)),
        1e-25 * rng.standard_normal((n, n)),  # AᵀA would underflow f32 without the internal scaling
        1e25 * rng.standard_normal((n, n)),  # ... and overflow
    ]
    return np.array(mats)


def _check_svd(A, U, S, V, tol):
    n = A.shape[-1]
    scale = np.maximum(np.abs(A).max(axis=(1, 2)), 1e-30)[:, None, None]
    eye = np.eye(n)
    assert np.isfinite(U).all() and np.isfinite(S).all() and np.isfinite(V).all()
    np.testing.assert_allclose((U @ S @ V.transpose(0, 2, 1) - A) / scale, 0, atol=tol)
    np.testing.assert_allclose(U.transpose(0, 2, 1) @ U, np.broadcast_to(eye, U.shape), atol=tol)
    np.testing.assert_allclose(V.transpose(0, 2, 1) @ V, np.broadcast_to(eye, V.shape), atol=tol)
    np.testing.assert_allclose(np.linalg.det(U), 1, atol=tol)
    np.testing.assert_allclose(np.linalg.det(V), 1, atol=tol)
    s = np.diagonal(S, axis1=1, axis2=2)
    np.testing.assert_array_equal(S - s[:, :, None] * eye, 0)  # exactly diagonal
    np.testing.assert_allclose(np.abs(s) / scale[:, 0], np.linalg.svd(A, compute_uv=False) / scale[:, 0],
                               atol=tol)
    assert (s[:, :-1] >= -tol * scale[:, 0]).all()  # only the last one may be negative
    assert (np.diff(np.abs(s), axis=1) <= tol * scale[:, 0]).all()  # decreasing magnitude
    det = np.linalg.det(A / scale)
    clear = np.abs(det) > 1e-3
    np.testing.assert_array_equal(np.sign(s[clear, -1]), np.sign(det[clear]))


def _check_eig(A, w, Q, tol):
    n = A.shape[-1]
    scale = np.maximum(np.abs(A).max(axis=(1, 2)), 1e-30)
    ref = np.linalg.eigvalsh(A)
    order = ref[:, ::-1] if n == 2 else ref  # Taichi: 2x2 decreasing, 3x3 increasing
    assert np.isfinite(w).all() and np.isfinite(Q).all()
    np.testing.assert_allclose(w / scale[:, None], order / scale[:, None], atol=tol)
    np.testing.assert_allclose((A @ Q - Q * w[:, None, :]) / scale[:, None, None], 0, atol=tol)
    np.testing.assert_allclose(Q.transpose(0, 2, 1) @ Q, np.broadcast_to(np.eye(n), Q.shape), atol=tol)


def _check_polar(A, R, P, tol):
    n = A.shape[-1]
    scale = np.maximum(np.abs(A).max(axis=(1, 2)), 1e-30)[:, None, None]
    assert np.isfinite(R).all() and np.isfinite(P).all()
    np.testing.assert_allclose((R @ P - A) / scale, 0, atol=tol)
    np.testing.assert_allclose(R.transpose(0, 2, 1) @ R, np.broadcast_to(np.eye(n), R.shape), atol=tol)
    np.testing.assert_allclose(np.linalg.det(R), 1, atol=tol)
    np.testing.assert_allclose((P - P.transpose(0, 2, 1)) / scale, 0, atol=tol)
    # where det(A) > 0 the polar factor is unique: P = sqrt(AᵀA), by an eigen-decomposition in numpy
    for a, p in zip(A, P):
        if np.linalg.det(a) > 1e-6 * np.abs(a).max() ** n:
            lam, q = np.linalg.eigh(a.T @ a)
            ref = q @ np.diag(np.sqrt(np.maximum(lam, 0))) @ q.T
            np.testing.assert_allclose(p, ref, atol=tol * max(np.abs(a).max(), 1) * 10)


def _np(m):
    return np.array(m.to_numpy(), dtype=np.float64)


# -- Python scope ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [2, 3])
def test_python_scope_svd_eig_polar(n):
    A = _cases(n, count=12)
    out = [ti.svd(ti.Matrix(a)) for a in A]
    U, S, V = (np.array([_np(o[k]) for o in out]) for k in range(3))
    _check_svd(A, U, S, V, 1e-12)
    sym = A + A.transpose(0, 2, 1)
    eig = [ti.sym_eig(ti.Matrix(a)) for a in sym]
    _check_eig(sym, np.array([_np(e[0]) for e in eig]), np.array([_np(e[1]) for e in eig]), 1e-12)
    pol = [ti.polar_decompose(ti.Matrix(a)) for a in A]
    _check_polar(A, np.array([_np(p[0]) for p in pol]), np.array([_np(p[1]) for p in pol]), 1e-12)


def test_taichi_sign_and_order_conventions():
    U, S, V = ti.svd(ti.Matrix(np.diag([1.0, 3.0, 2.0])))
    np.testing.assert_allclose(_np(S), np.diag([3.0, 2.0, 1.0]), atol=1e-14)
    _, S, _ = ti.svd(ti.Matrix(np.diag([-1.0, 3.0, 2.0])))
    np.testing.assert_allclose(_np(S), np.diag([3.0, 2.0, -1.0]), atol=1e-14)
    U, S, V = ti.svd(ti.Matrix(-np.eye(3)))
    np.testing.assert_allclose(_np(S), np.diag([1.0, 1.0, -1.0]), atol=1e-14)
    np.testing.assert_allclose(_np(U) @ _np(S) @ _np(V).T, -np.eye(3), atol=1e-14)
    U, S, V = ti.svd(ti.Matrix(np.zeros((3, 3))))  # zero matrix: identities and zeros, as Taichi
    np.testing.assert_array_equal(_np(U), np.eye(3))
    np.testing.assert_array_equal(_np(S), np.zeros((3, 3)))
    np.testing.assert_array_equal(_np(V), np.eye(3))
    _, S, _ = ti.svd(ti.Matrix([[-1.0, 0.0], [0.0, 2.0]]))  # 2x2: rotations too (sign on the last)
    np.testing.assert_allclose(_np(S), np.diag([2.0, -1.0]), atol=1e-14)
    w, _ = ti.sym_eig(ti.Matrix([[1.0, 0.0], [0.0, 2.0]]))
    np.testing.assert_allclose(_np(w), [2.0, 1.0])  # decreasing in 2x2
    w, _ = ti.sym_eig(ti.Matrix(np.diag([2.0, -1.0, 3.0])))
    np.testing.assert_allclose(_np(w), [-1.0, 2.0, 3.0])  # increasing in 3x3
    R, P = ti.polar_decompose(ti.Matrix(np.zeros((2, 2))))  # finite (Taichi gives NaN here)
    np.testing.assert_array_equal(_np(R), np.eye(2))
    np.testing.assert_array_equal(_np(P), np.zeros((2, 2)))


def test_ints_lists_and_bad_shapes():
    U, S, V = ti.svd(ti.Matrix([[2, 0], [0, 1]]))
    np.testing.assert_allclose(_np(S), np.diag([2.0, 1.0]))
    w, _ = ti.sym_eig([[2.0, 1.0], [1.0, 2.0]])
    np.testing.assert_allclose(_np(w), [3.0, 1.0], atol=1e-14)
    with pytest.raises(ti.TaichiCompilationError, match="SVD only supports 2D and 3D matrices"):
        ti.svd(ti.Matrix(np.eye(4)))
    with pytest.raises(ti.TaichiCompilationError, match="only supports 2D and 3D matrices"):
        ti.sym_eig(ti.Matrix([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]))
    m = ti.Matrix.field(1, 1, ti.f32, shape=())

    @ti.kernel
    def field_not_value():
        ti.polar_decompose(m, ti.f32)

    with pytest.raises(ti.TaichiCompilationError, match="Polar decomposition only supports 2D and 3D matrices"):
        field_not_value()


# -- kernels ----------------------------------------------------------------------------------------------
def _run_kernel(n, t):
    A = _cases(n, count=40, seed=7)
    sym = A + A.transpose(0, 2, 1)
    N = len(A)
    M, Ms = ti.Matrix.field(n, n, ti.f64, shape=N), ti.Matrix.field(n, n, ti.f64, shape=N)
    U, S, V, Q, R, P = (ti.Matrix.field(n, n, ti.f64, shape=N) for _ in range(6))
    w = ti.Vector.field(n, ti.f64, shape=N)
    M.from_numpy(A)
    Ms.from_numpy(sym)

    @ti.kernel
    def decompose(dt: ti.template()):
        for i in M:
            U[i], S[i], V[i] = ti.svd(M[i], dt)
            w[i], Q[i] = ti.sym_eig(Ms[i], dt)
            R[i], P[i] = ti.polar_decompose(M[i], dt)

    decompose(t)
    tol = TOL[t]
    _check_svd(A, U.to_numpy(), S.to_numpy(), V.to_numpy(), tol)
    _check_eig(sym, w.to_numpy(), Q.to_numpy(), tol)
    _check_polar(A, R.to_numpy(), P.to_numpy(), tol)


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_kernel_2x2(t):
    _run_kernel(2, t)


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_kernel_3x3(t):
    _run_kernel(3, t)


def test_kernel_default_dtype_and_local_matrix():
    """Without dt the entries' type is used (f32 by default); results land in locals and are reused."""
    out = ti.field(ti.f32, shape=6)

    @ti.kernel
    def k():
        A = ti.Matrix([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]])
        U, S, V = ti.svd(A)
        B = U @ S @ V.transpose()
        out[0] = (B - A).norm()
        out[1] = S[0, 0]
        w, Q = ti.sym_eig(A)
        out[2] = w[0]
        q0 = ti.Vector([Q[0, 0], Q[1, 0], Q[2, 0]])
        out[3] = (A @ q0 - w[0] * q0).norm()
        R, P = ti.polar_decompose(A)
        out[4] = (R @ P - A).norm()
        out[5] = R.determinant()

    k()
    A = np.array([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]])
    r = out.to_numpy()
    assert r[0] < 1e-5 and r[3] < 1e-5 and r[4] < 1e-5
    np.testing.assert_allclose(r[1], np.linalg.svd(A, compute_uv=False)[0], rtol=1e-6)
    np.testing.assert_allclose(r[2], np.linalg.eigvalsh(A)[0], rtol=1e-6)
    np.testing.assert_allclose(r[5], 1.0, rtol=1e-6)


@pytest.mark.parametrize("n", [2, 3])
def test_gradients_finite_at_degenerate_inputs_and_match_differences(n):
    """Reverse-mode through svd/polar/sym_eig: finite at I, 0, -I, repeated and rank-one inputs (the
    guards), and equal to central differences of the forward kernel at a generic matrix. (The 3x3 adjoint
    is a large kernel: one svd and one sym_eig keep its compile time in check.)"""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    N = 6
    M = ti.Matrix.field(n, n, ti.f64, shape=N, needs_grad=True)
    W = ti.Matrix.field(n, n, ti.f64, shape=3)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        for i in M:
            U, S, V = ti.svd(M[i])
            w, Q = ti.sym_eig(M[i] + M[i].transpose())
            rot = U @ V.transpose()  # what polar_decompose computes in 3x3
            sym = V @ S @ V.transpose()
            acc = 0.0
            for a, b in ti.static(ti.ndrange(n, n)):
                acc += W[0][a, b] * rot[a, b] + W[1][a, b] * sym[a, b]
            if ti.static(n == 2):  # the closed-form 2x2 polar decomposition (3x3 is covered by svd above)
                R, P = ti.polar_decompose(M[i])
                for a, b in ti.static(ti.ndrange(n, n)):
                    acc += W[2][a, b] * (R[a, b] + P[b, a])
            for a in ti.static(range(n)):
                acc += S[a, a] * (a + 1) + w[a] * (a + 2)
            loss[None] += acc

    rng = np.random.default_rng(11)
    W.from_numpy(rng.standard_normal((3, n, n)))
    A = rng.standard_normal((N, n, n))
    A[1], A[2], A[3] = np.eye(n), 0.0, -np.eye(n)
    A[4] = np.diag([2.0] * (n - 1) + [1.0])
    A[5] = np.outer(np.ones(n), np.arange(1.0, n + 1))
    M.from_numpy(A)
    with ti.ad.Tape(loss=loss):
        f()
    g = M.grad.to_numpy()
    assert np.isfinite(g).all()

    def value(Av):
        M.from_numpy(Av)
        loss[None] = 0.0
        f()
        return loss[None]

    eps = 1e-6
    fd = np.zeros((n, n))
    for a in range(n):
        for b in range(n):
            Ap, Am = A.copy(), A.copy()
            Ap[0, a, b] += eps
            Am[0, a, b] -= eps
            fd[a, b] = (value(Ap) - value(Am)) / (2 * eps)
    np.testing.assert_allclose(g[0], fd, atol=1e-6 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_polar_2x2_over_the_whole_exponent_range(t):
    """The per-particle 2x2 polar decomposition rescales by constant powers of two (kept in the working
    type even when default_fp is f32): exact from the smallest normal to the largest magnitudes."""
    exps = [-37, -30, -12, 0, 12, 30, 37] if t is ti.f32 else [-307, -300, -100, 0, 100, 300, 307]
    sc = 10.0 ** np.array(exps, dtype=np.float64)
    A = np.array([[1.0, -2.0], [2.5, 0.5]])[None] * sc[:, None, None] / 3
    M, R, P = (ti.Matrix.field(2, 2, t, shape=len(sc)) for _ in range(3))
    M.from_numpy(A.astype(t.np))

    @ti.kernel
    def k():
        for i in M:
            R[i], P[i] = ti.polar_decompose(M[i])

    k()
    rot = np.array([[1.0, -3.0], [3.0, 1.0]]) / np.sqrt(10.0)  # normalise (a + d, c - b) = (1.5, 4.5)
    np.testing.assert_allclose(R.to_numpy(), np.broadcast_to(rot, (len(sc), 2, 2)), atol=TOL[t])
    Pn = P.to_numpy().astype(np.float64) / sc[:, None, None]
    np.testing.assert_allclose(Pn, Pn.transpose(0, 2, 1), atol=TOL[t])


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_svd_scale_at_powers_of_two_and_extremes(t):
    """The input scale is taken from the bits of the largest |entry| (lang/linalg.py `scaled`): entries at a
    power of two, one ulp below it, tiny and huge magnitudes and zero all give U S V^T = A and numpy's
    singular values."""
    f = np.float32 if t == ti.f32 else np.float64
    below = float(np.nextafter(f(4.0), f(0)))
    mats = [np.array(m, np.float64) for m in (
        [[4.0, 1.0, 0.5], [0.25, -2.0, 1.0], [1.0, 0.0, 3.0]],
        [[below, 1.0, 0.5], [0.25, -2.0, 1.0], [1.0, 0.0, 3.0]],
        [[1e-30, 2e-31, 0.0], [0.0, 3e-30, 1e-31], [5e-31, 0.0, 2e-30]],
        [[1e30, 2e29, 0.0], [0.0, -3e30, 1e29], [5e29, 0.0, 2e30]],
        [[0.0] * 3] * 3)]
    a = ti.Matrix.field(3, 3, t, shape=len(mats))
    r = ti.Matrix.field(3, 3, t, shape=len(mats))
    s = ti.Vector.field(3, t, shape=len(mats))
    a.from_numpy(np.stack(mats).astype(f))

    @ti.kernel
    def k():
        for i in a:
            U, S, V = ti.svd(a[i], t)
            r[i] = U @ S @ V.transpose()
            s[i] = ti.Vector([S[0, 0], S[1, 1], S[2, 2]])

    k()
    eps = 1e-5 if t == ti.f32 else 1e-12
    for i, m in enumerate(mats):
        m = m.astype(f).astype(np.float64)
        scale = max(np.abs(m).max(), 1e-300)
        np.testing.assert_allclose(r.to_numpy()[i], m, rtol=0, atol=eps * scale)
        want = np.linalg.svd(m, compute_uv=False)
        np.testing.assert_allclose(np.abs(s.to_numpy()[i]), want, rtol=0, atol=eps * scale)
