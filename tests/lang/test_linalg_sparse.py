"""ti.linalg: the sparse matrix builder as a kernel argument, SparseMatrix operations, SparseSolver, SparseCG and
the matrix-free solvers, each checked against numpy on the same data (dense references built independently)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import simgrad as ti
from simgrad.errors import SimgradRuntimeError, SimgradSyntaxError, SimgradTypeError

pytest.importorskip("scipy")


def _laplacian_dense(g: int) -> np.ndarray:
    """The 5-point Laplacian of a g x g grid (Dirichlet), cell (i, j) at row i * g + j, built entry by entry."""
    a = np.zeros((g * g, g * g))
    for i in range(g):
        for j in range(g):
            r = i * g + j
            a[r, r] = 4.0
            for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                if 0 <= i + di < g and 0 <= j + dj < g:
                    a[r, (i + di) * g + j + dj] = -1.0
    return a


def _fill_laplacian(g: int):
    @ti.kernel
    def fill(A: ti.types.sparse_matrix_builder()):
        for i, j in ti.ndrange(g, g):  # a parallel loop: the triplets arrive in any order
            r = i * g + j
            A[r, r] += 3.0
            A[r, r] += 1.0  # duplicates are summed by build()
            if i > 0:
                A[r, r - g] -= 1.0
            if i < g - 1:
                A[r, r + g] -= 1
            if j > 0:
                A[r, r - 1] += -1.0
            if j < g - 1:
                A[r, r + 1] -= 1.0

    return fill


@pytest.mark.parametrize("dtype, fmt", [(ti.f32, "col_major"), (ti.f64, "row_major")])
def test_builder_from_a_kernel_builds_the_laplacian(dtype, fmt):
    g = 24
    builder = ti.linalg.SparseMatrixBuilder(g * g, g * g, max_num_triplets=6 * g * g, dtype=dtype,
                                            storage_format=fmt)
    _fill_laplacian(g)(builder)
    A = builder.build()
    assert A.shape == (g * g, g * g) and A.dtype == dtype
    assert A.matrix.format == ("csc" if fmt == "col_major" else "csr")
    np.testing.assert_array_equal(A.matrix.toarray(), _laplacian_dense(g))
    assert A[g + 1, g + 1] == 4.0 and A[g + 1, 1] == -1.0 and A[0, g * g - 1] == 0.0
    # build() empties the builder (as Taichi's): the next build is the zero matrix
    assert builder.build().matrix.count_nonzero() == 0


@pytest.mark.parametrize("fmt", ["col_major", "row_major"])
def test_duplicate_triplets_sum_in_the_order_they_came(fmt):
    # as Eigen's setFromTriplets (taichi 1.7.4 builds 1.0 from 1e8, 1, -1e8, 1 in f32): one by one in order,
    # not pairwise (numpy's reduceat gives 0.0), long runs too
    long_run = 69
    cells = [(0, 1)] * 4 + [(1, 0)] * 9 + [(2, 2)] * long_run + [(0, 1)] * 4 + [(1, 2)]
    vals = np.array([1e8, 1, -1e8, 1] + [0.1] * 9 + [0.5] * long_run + [1e8, 1, -1e8, 1] + [3.0], np.float32)
    groups: dict = {}
    for k, c in enumerate(cells):
        groups.setdefault(c, []).append(k)
    order = [g[d] for d in range(len(cells)) for g in groups.values() if d < len(g)]  # round robin: interleaved,
    # each cell's triplets in their order
    want = {}
    for k in order:
        want[cells[k]] = np.float32(want.get(cells[k], np.float32(0)) + vals[k])
    builder = ti.linalg.SparseMatrixBuilder(3, 3, max_num_triplets=len(cells), dtype=ti.f32, storage_format=fmt)
    t = builder._triplets
    t.rows[:len(cells)] = [cells[k][0] for k in order]
    t.cols[:len(cells)] = [cells[k][1] for k in order]
    t.values[:len(cells)] = vals[order]
    t.count[0] = len(cells)
    A = builder.build()
    dense = np.zeros((3, 3), np.float32)
    for (i, j), v in want.items():
        dense[i, j] = v
    assert dense[0, 1] == 1.0  # 1e8, 1, -1e8, 1 twice, in f32: 1
    np.testing.assert_array_equal(A.matrix.toarray(), dense)
    assert A.matrix.nnz == len(want)


def test_builder_accumulates_over_launches_and_prints_triplets(capsys):
    builder = ti.linalg.SparseMatrixBuilder(3, 2, max_num_triplets=4, dtype=ti.f32)

    @ti.kernel
    def add(A: ti.types.sparse_matrix_builder(), i: ti.i32, j: ti.i32, v: ti.f32):
        A[i, j] += v

    add(builder, 2, 1, 0.25)
    add(builder, 0, 0, 1.5)
    add(builder, 2, 1, 1.0)
    builder.print_triplets()
    assert capsys.readouterr().out == ("n=3, m=2, num_triplets=3 (max=4)\n[2, 1] = 0.25\n[0, 0] = 1.5\n"
                                       "[2, 1] = 1\n")
    np.testing.assert_array_equal(builder.build().matrix.toarray(), [[1.5, 0], [0, 0], [0, 1.25]])


def test_builder_in_a_func_and_in_debug_mode():
    ti.init(arch=ti.cpu, debug=True)  # every element access is index-checked

    @ti.func
    def put(A: ti.template(), i, v):
        A[i, (i + 1) % 5] -= v

    @ti.kernel
    def fill(A: ti.types.sparse_matrix_builder(), w: ti.types.ndarray()):
        for i in range(5):
            put(A, i, w[i])

    w = np.arange(1, 6, dtype=np.float32)
    b32 = ti.linalg.SparseMatrixBuilder(5, 5, max_num_triplets=5)
    b64 = ti.linalg.SparseMatrixBuilder(5, 5, max_num_triplets=5, dtype=ti.f64)
    fill(b32, w)
    fill(b64, w)  # a builder of another dtype is another instantiation
    expect = np.zeros((5, 5))
    expect[np.arange(5), (np.arange(5) + 1) % 5] = -w
    np.testing.assert_array_equal(b32.build().matrix.toarray(), expect)
    A64 = b64.build()
    assert A64.dtype == ti.f64 and A64.matrix.dtype == np.float64
    np.testing.assert_array_equal(A64.matrix.toarray(), expect)


def test_overflow_of_max_num_triplets_raises():
    builder = ti.linalg.SparseMatrixBuilder(4, 4, max_num_triplets=10)

    @ti.kernel
    def fill(A: ti.types.sparse_matrix_builder()):
        for i, j in ti.ndrange(4, 4):
            A[i, j] += 1.0

    with pytest.raises(SimgradRuntimeError, match=r"given 16 triplets, more than its max_num_triplets=10") as e:
        fill(builder)
    assert e.value.loc is not None and e.value.loc.file == __file__
    with pytest.raises(SimgradRuntimeError, match="max_num_triplets=10"):
        builder.build()  # what was stored is incomplete: never built silently


def test_wrong_argument_for_a_builder_parameter_is_a_located_error():
    @ti.kernel
    def fill(A: ti.types.sparse_matrix_builder()):
        A[0, 0] += 1.0

    with pytest.raises(SimgradTypeError, match="expects a ti.linalg.SparseMatrixBuilder, got ndarray") as e:
        fill(np.zeros((2, 2), np.float32))
    assert e.value.loc is not None and e.value.loc.file == __file__


@ti.kernel
def _assign(A: ti.types.sparse_matrix_builder()):
    A[0, 0] = 1.0


@ti.kernel
def _scale(A: ti.types.sparse_matrix_builder()):
    A[0, 0] *= 2.0


@ti.kernel
def _read(A: ti.types.sparse_matrix_builder()):
    x = A[0, 0]


@ti.kernel
def _float_index(A: ti.types.sparse_matrix_builder()):
    A[0.5, 0] += 1.0


@ti.kernel
def _one_index(A: ti.types.sparse_matrix_builder()):
    A[0] += 1.0


@pytest.mark.parametrize("kernel, message", [
    (_assign, "cannot be assigned"),
    (_scale, r"only '\+=' and '-=' are supported"),
    (_read, "cannot be read"),
    (_float_index, "must be integer scalars"),
    (_one_index, "takes two indices"),
])
def test_builder_entries_only_take_add_and_sub(kernel, message):
    with pytest.raises((SimgradSyntaxError, SimgradTypeError, IndexError), match=message) as e:
        kernel(ti.linalg.SparseMatrixBuilder(2, 2, max_num_triplets=4))
    assert e.value.loc is not None and e.value.loc.file == __file__


def _from_dense(a: np.ndarray, dtype=ti.f64, fmt="col_major"):
    """A SparseMatrix with a's nonzeros, put in by a kernel reading them from an ndarray."""
    n, m = a.shape
    builder = ti.linalg.SparseMatrixBuilder(n, m, max_num_triplets=n * m, dtype=dtype, storage_format=fmt)

    @ti.kernel
    def fill(A: ti.types.sparse_matrix_builder(), src: ti.types.ndarray()):
        for i, j in ti.ndrange(n, m):
            if src[i, j] != 0:
                A[i, j] += src[i, j]

    fill(builder, np.ascontiguousarray(a))
    return builder.build()


def test_matrix_operations_match_numpy(tmp_path):
    rng = np.random.default_rng(5)
    a = np.where(rng.random((5, 4)) < 0.5, rng.integers(-4, 5, (5, 4)), 0).astype(np.float64)
    b = np.where(rng.random((5, 4)) < 0.5, rng.integers(-4, 5, (5, 4)), 0).astype(np.float64)
    c = rng.integers(-3, 4, (4, 3)).astype(np.float64)
    A, B, C = _from_dense(a), _from_dense(b, fmt="row_major"), _from_dense(c)
    for got, want in ((A + B, a + b), (A - B, a - b), (A * 2.5, a * 2.5), (3 * A, 3 * a), (A * B, a * b),
                      (A @ C, a @ c), (A.transpose(), a.T)):
        assert isinstance(got, ti.linalg.SparseMatrix)
        np.testing.assert_array_equal(got.matrix.toarray(), want)
    assert (A @ C).shape == (5, 3) and A.transpose().shape == (4, 5)
    A += B
    np.testing.assert_array_equal(A.matrix.toarray(), a + b)
    A -= B
    np.testing.assert_array_equal(A.matrix.toarray(), a)
    v = rng.random(4)
    np.testing.assert_allclose(A @ v, a @ v)
    f = ti.field(ti.f64, 4)
    f.from_numpy(v)
    np.testing.assert_allclose(A @ f, a @ v)
    nd = ti.ndarray(ti.f64, 4)
    nd.from_numpy(v)
    res = A @ nd
    assert isinstance(res, ti.ScalarNdarray) and res.shape == (5,)
    np.testing.assert_allclose(res.to_numpy(), a @ v)
    assert [[A[i, j] for j in range(4)] for i in range(5)] == a.tolist()
    A[4, 3] = 7.0
    assert A[4, 3] == 7.0
    with pytest.raises(IndexError):
        A[5, 0]
    with pytest.raises(AssertionError, match="Dimension mismatch"):
        A + C
    # the file scipy reads back is the matrix
    import scipy.io

    A.mmwrite(str(tmp_path / "a.mtx"))
    a[4, 3] = 7.0
    np.testing.assert_array_equal(scipy.io.mmread(str(tmp_path / "a.mtx")).toarray(), a)


def test_print_as_taichi():
    A = _from_dense(np.array([[1 / 3, 0], [0, 123456789.0], [1e-7, -2.5e10]]), dtype=ti.f32)
    assert str(A) == ("[   0.3333,         0]\n[        0, 1.235e+08]\n[    1e-07,  -2.5e+10]")
    assert repr(A) == str(A)


def test_build_from_ndarray():
    triplets = ti.Vector.ndarray(3, ti.f32, 4)
    triplets.from_numpy(np.array([[0, 1, 2.0], [2, 2, 3.0], [0, 1, 0.5], [1, 0, -1.0]], np.float32))
    A = ti.linalg.SparseMatrix(n=3, m=3, dtype=ti.f32)
    A.build_from_ndarray(triplets)
    np.testing.assert_array_equal(A.matrix.toarray(), [[0, 2.5, 0], [-1, 0, 0], [0, 0, 3]])
    with pytest.raises(ti.TaichiRuntimeError, match="divisible by 3"):
        A.build_from_ndarray(ti.ndarray(ti.f32, 4))
    bad = ti.ndarray(ti.f32, 3)
    bad.from_numpy(np.array([3, 0, 1], np.float32))
    with pytest.raises(IndexError, match="out of bounds"):
        A.build_from_ndarray(bad)


def _spd(n: int, seed: int) -> np.ndarray:
    m = np.random.default_rng(seed).random((n, n))
    return m @ m.T + np.eye(n)


@pytest.fixture(params=["dense", "sparse"])
def factorisation(request, monkeypatch):
    """Both ways a SparseSolver factorises: LAPACK for small matrices, SuperLU for the rest (DENSE_MAX 0)."""
    from simgrad.linalg import sparse_solver

    if request.param == "sparse":
        monkeypatch.setattr(sparse_solver, "DENSE_MAX", 0)
    return request.param


@pytest.mark.parametrize("solver_type", ["LLT", "LDLT", "LU"])
@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_sparse_solver_matches_numpy(solver_type, dtype, factorisation):
    n = 12
    a = _spd(n, 1)
    A = _from_dense(a, dtype=dtype)
    rhs = np.arange(1, n + 1, dtype=dtype.np)
    want = np.linalg.solve(a, rhs.astype(np.float64))
    rtol = 1e-3 if dtype == ti.f32 else 1e-10
    solver = ti.linalg.SparseSolver(dtype=dtype, solver_type=solver_type, ordering="COLAMD")
    solver.analyze_pattern(A)
    solver.factorize(A)
    assert solver.info()
    x = solver.solve(rhs)
    assert isinstance(x, np.ndarray) and x.dtype == dtype.np
    np.testing.assert_allclose(x, want, rtol=rtol)
    f = ti.field(dtype, n)
    f.from_numpy(rhs)
    np.testing.assert_allclose(solver.solve(f), want, rtol=rtol)
    nd = ti.ndarray(dtype, n)
    nd.from_numpy(rhs)
    xn = solver.solve(nd)
    assert isinstance(xn, ti.Ndarray)
    np.testing.assert_allclose(xn.to_numpy(), want, rtol=rtol)


def test_sparse_solver_reports_failure(factorisation):
    indefinite = _from_dense(np.diag([-1.0, 2.0]))
    llt = ti.linalg.SparseSolver(dtype=ti.f64)
    llt.compute(indefinite)
    assert not llt.info()  # not positive definite, as Eigen's LLT
    assert np.isnan(llt.solve(np.ones(2))).all()
    ldlt = ti.linalg.SparseSolver(dtype=ti.f64, solver_type="LDLT")
    ldlt.compute(indefinite)
    assert ldlt.info()  # Eigen's LDLT takes an indefinite matrix without a zero pivot
    np.testing.assert_allclose(ldlt.solve(np.ones(2)), [-1.0, 0.5])
    ldlt.compute(_from_dense(np.array([[0.0, 1.0], [1.0, 2.0]])))
    # a zero leading pivot: taichi 1.7.4's info() is False (Eigen's LDLT does not pivot); SuperLU pivots and
    # solves it, correctly
    assert ldlt.info()
    np.testing.assert_allclose(ldlt.solve(np.array([1.0, 4.0])), [2.0, 1.0])
    ldlt.compute(_from_dense(np.array([[1.0, 1.0], [1.0, 1.0]])))
    assert not ldlt.info()  # singular
    lu = ti.linalg.SparseSolver(dtype=ti.f64, solver_type="LU")
    lu.compute(indefinite)
    assert lu.info()
    np.testing.assert_allclose(lu.solve(np.ones(2)), [-1.0, 0.5])
    singular = ti.linalg.SparseSolver(dtype=ti.f64, solver_type="LU")
    singular.compute(_from_dense(np.array([[1.0, 2.0], [2.0, 4.0]])))
    assert not singular.info()
    with pytest.raises(ti.TaichiRuntimeError, match="not consistent"):
        ti.linalg.SparseSolver(dtype=ti.f32).analyze_pattern(indefinite)
    with pytest.raises(ti.TaichiRuntimeError, match="not supported"):
        ti.linalg.SparseSolver(solver_type="QR")
    with pytest.raises(ti.TaichiRuntimeError, match="before"):
        ti.linalg.SparseSolver().solve(np.ones(2))


def test_llt_reads_the_lower_triangle(factorisation):
    """Eigen's LLT/LDLT take the matrix as symmetric from its lower triangle; LU uses all of it."""
    a = np.array([[4.0, 5.0], [1.0, 3.0]])
    A = _from_dense(a)
    rhs = np.array([1.0, 2.0])
    sym = np.tril(a) + np.tril(a, -1).T
    for kind, ref in (("LLT", sym), ("LDLT", sym), ("LU", a)):
        s = ti.linalg.SparseSolver(dtype=ti.f64, solver_type=kind)
        s.compute(A)
        np.testing.assert_allclose(s.solve(rhs), np.linalg.solve(ref, rhs))


def test_the_symmetric_matrix_of_a_lower_triangle_is_scipys_tril_sum():
    # LLT/LDLT factorise the matrix tril(a) + tril(a, -1).T (Eigen reads the lower triangle only); it is built
    # from one COO pass: the same structure and values, explicit zeros and a non-symmetric upper part included
    import scipy.sparse as sp

    from simgrad.linalg.sparse_solver import _symmetric_from_lower

    rng = np.random.default_rng(6)
    for trial in range(60):
        n = int(rng.integers(1, 30))
        a = sp.random(n, n, density=rng.random(), random_state=trial, format="csr", dtype=np.float32)
        if trial % 3 == 0:
            a.data[::3] = 0.0
        want = (sp.tril(a, format="csc") + sp.tril(a, k=-1, format="csc").T).tocsc()
        got = _symmetric_from_lower(sp, a)
        want.sort_indices()
        got.sort_indices()
        assert got.dtype == want.dtype and got.shape == want.shape
        np.testing.assert_array_equal(got.indptr, want.indptr)
        np.testing.assert_array_equal(got.indices, want.indices)
        np.testing.assert_array_equal(got.data, want.data)


def test_sparse_cg_matches_numpy():
    a = _laplacian_dense(6)
    A = _from_dense(a)
    rhs = np.linspace(0, 1, 36)
    x, ok = ti.linalg.SparseCG(A, rhs, max_iter=200, atol=1e-10).solve()
    assert ok
    np.testing.assert_allclose(x, np.linalg.solve(a, rhs), rtol=1e-7, atol=1e-9)


def _tridiagonal(n: int, lower: float, diag: float, upper: float) -> np.ndarray:
    return np.diag(np.full(n, diag)) + np.diag(np.full(n - 1, lower), -1) + np.diag(np.full(n - 1, upper), 1)


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_matrix_free_cg_and_bicgstab_match_numpy(dtype):
    n = 40
    b = ti.field(dtype, n)
    x = ti.field(dtype, n)
    rhs = np.sin(np.linspace(0, 3, n))
    b.from_numpy(rhs)

    def operator(lower, upper):
        @ti.kernel
        def matvec(v: ti.template(), Av: ti.template()):
            for i in v:
                left = v[i - 1] if i > 0 else 0.0
                right = v[i + 1] if i < n - 1 else 0.0
                Av[i] = 4.0 * v[i] + lower * left + upper * right

        return ti.linalg.LinearOperator(matvec)

    tol = 1e-5 if dtype == ti.f32 else 1e-10
    assert ti.linalg.MatrixFreeCG(operator(-1.0, -1.0), b, x, tol=tol, maxiter=200)
    np.testing.assert_allclose(x.to_numpy(), np.linalg.solve(_tridiagonal(n, -1, 4, -1), rhs), atol=10 * tol)
    x.fill(0)
    assert ti.linalg.MatrixFreeBICGSTAB(operator(-2.0, 0.5), b, x, tol=tol, maxiter=200)
    np.testing.assert_allclose(x.to_numpy(), np.linalg.solve(_tridiagonal(n, -2, 4, 0.5), rhs), atol=10 * tol)
    with pytest.raises(TypeError, match="Dtype mismatch"):
        ti.linalg.MatrixFreeCG(operator(-1.0, -1.0), b, ti.field(ti.f16 if dtype == ti.f32 else ti.f32, n))


def test_linalg_names_and_missing_scipy(monkeypatch):
    import simgrad.linalg

    assert ti.linalg is simgrad.linalg
    assert ti.types.sparse_matrix_builder is ti.sparse_matrix_builder
    monkeypatch.setitem(sys.modules, "scipy", None)
    monkeypatch.setitem(sys.modules, "scipy.sparse", None)
    with pytest.raises(ImportError, match=r"pip install simgrad\[linalg\]"):
        ti.linalg.SparseMatrix(2, 2)
