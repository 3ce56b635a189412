"""ti.Vector / ti.Matrix: construction, indexing, swizzles, arithmetic and methods, against numpy, in
Python scope and in kernels (results written to f64 fields)."""

import numpy as np
import pytest

import simgrad as ti


def _np(m):
    return np.array(m.to_numpy(), dtype=np.float64)


# -- Python scope ----------------------------------------------------------------------------------------
def test_construction_and_shapes():
    v = ti.Vector([1, 2, 3])
    assert v.n == 3 and v.ndim == 1 and v.get_shape() == (3,) and len(v) == 3
    assert v.to_list() == [1, 2, 3] and list(v) == [1, 2, 3]
    m = ti.Matrix([[1, 2, 3], [4, 5, 6]])
    assert (m.n, m.m, m.ndim, m.get_shape(), len(m)) == (2, 3, 2, (2, 3), 2)
    assert m.to_list() == [[1, 2, 3], [4, 5, 6]]
    assert ti.Matrix([1, 2, 3]).ndim == 1  # a flat list makes a vector, as in Taichi
    assert ti.Matrix([[1], [2]]).get_shape() == (2, 1)
    arr = np.arange(6.0).reshape(2, 3)
    np.testing.assert_array_equal(ti.Matrix(arr).to_numpy(), arr)
    f = ti.Vector([1, 2], dt=ti.f32)
    assert all(isinstance(e, float) for e in f.to_list())
    assert ti.Vector([1.7, -1.7], ti.i32).to_list() == [1, -1]
    assert isinstance(v, ti.Vector) and isinstance(v, ti.Matrix) and not isinstance(m, ti.Vector)
    with pytest.raises(ValueError):
        ti.Matrix([[1, 2], [3]])
    w = ti.Vector([1.0, 2.0])
    w.fill(7)
    assert w.to_list() == [7, 7]


def test_indexing_and_slices():
    m = ti.Matrix([[1, 2, 3], [4, 5, 6]])
    assert m[1, 0] == 4 and m[1][0] == 4 and m[-1, -1] == 6
    assert m[0].to_list() == [1, 2, 3]
    v = ti.Vector([10, 20, 30, 40])
    assert v[0] == 10 and v[-1] == 40
    assert v[1:3].to_list() == [20, 30] and v[::-1].to_list() == [40, 30, 20, 10]
    assert m[:, 1].to_list() == [2, 5] and m[1, :].to_list() == [4, 5, 6]
    assert m[:, 1:].to_list() == [[2, 3], [5, 6]]
    with pytest.raises(IndexError):
        v[4]
    with pytest.raises(IndexError):
        m[2, 0]
    with pytest.raises(IndexError):
        v[0, 0]
    m[0, 0] = 9
    m[1] = [7, 8, 9]
    assert m.to_list() == [[9, 2, 3], [7, 8, 9]]


def test_swizzles():
    v = ti.Vector([1, 2, 3, 4])
    assert (v.x, v.y, v.z, v.w) == (1, 2, 3, 4)
    assert (v.r, v.g, v.b, v.a) == (1, 2, 3, 4)
    assert (v.s, v.t, v.p, v.q) == (1, 2, 3, 4)
    assert v.xy.to_list() == [1, 2] and v.zyx.to_list() == [3, 2, 1] and v.wwxy.to_list() == [4, 4, 1, 2]
    assert v.bgr.to_list() == [3, 2, 1] and v.ts.to_list() == [2, 1]
    u = ti.Vector([1, 2, 3])
    u.x = 9
    u.zy = (7, 8)
    assert u.to_list() == [9, 8, 7]
    with pytest.raises(AttributeError):
        _ = u.w  # a 3-vector has no w
    with pytest.raises(AttributeError):
        _ = u.xr  # letters of two groups
    with pytest.raises(AttributeError):
        _ = ti.Matrix([[1, 2], [3, 4]]).x
    with pytest.raises(ti.TaichiRuntimeError, match="value len does not match the swizzle pattern=xy"):
        u.xy = (1, 2, 3)


def test_arithmetic_broadcasting():
    a = np.array([3.0, -2.0, 5.0])
    b = np.array([2.0, 4.0, -3.0])
    v, w = ti.Vector(a.tolist()), ti.Vector(b.tolist())
    cases = [
        (v + w, a + b), (v - w, a - b), (v * w, a * b), (v / w, a / b), (v + 1, a + 1), (1 - v, 1 - a),
        (2 * v, 2 * a), (v / 2, a / 2), (2 / v, 2 / a), (v ** 2, a ** 2), (2 ** v, 2 ** a), (-v, -a),
        (abs(v), np.abs(a)), (v // 2, a // 2), (v % 3, a % 3), (7 // v, 7 // a), (7 % v, 7 % a),
        (ti.max(v, w), np.maximum(a, b)), (ti.min(v, 0.0), np.minimum(a, 0.0)), (v < w, a < b),
        (v == w, a == b), (v >= 3, a >= 3),
    ]
    for got, want in cases:
        np.testing.assert_allclose(_np(got), want, rtol=1e-15)
    iv = ti.Vector([6, -7, 5])
    assert (iv // 4).to_list() == [1, -2, 1] and (iv % 4).to_list() == [2, 1, 1]  # floor semantics
    assert (iv & 3).to_list() == [2, 1, 1] and (iv | 1).to_list() == [7, -7, 5]
    assert (iv ^ 1).to_list() == [7, -8, 4] and (1 & iv).to_list() == [0, 1, 1]
    assert (iv << 1).to_list() == [12, -14, 10] and (~iv).to_list() == [-7, 6, -6]
    m = ti.Matrix([[1.0, 2.0], [3.0, 4.0]])
    np.testing.assert_allclose(_np(m * 2 + 1), np.array([[3, 5], [7, 9]]))
    with pytest.raises(ValueError):
        v + ti.Vector([1.0, 2.0])


def test_matmul_transpose():
    rng = np.random.default_rng(0)
    A, B = rng.standard_normal((2, 3)), rng.standard_normal((3, 4))
    x, y = rng.standard_normal(3), rng.standard_normal(2)
    mA, mB, vx, vy = ti.Matrix(A), ti.Matrix(B), ti.Vector(x), ti.Vector(y)
    np.testing.assert_allclose(_np(mA @ mB), A @ B, rtol=1e-13)
    np.testing.assert_allclose(_np(mA @ vx), A @ x, rtol=1e-13)
    assert (mA @ vx).ndim == 1
    np.testing.assert_allclose(_np(vy @ mA), y @ A, rtol=1e-13)  # row vector times matrix
    assert (vy @ mA).ndim == 1
    np.testing.assert_allclose(vx @ vx, x @ x, rtol=1e-13)
    np.testing.assert_allclose(_np(mA.transpose()), A.T)
    np.testing.assert_allclose(_np(mA.T), A.T)
    with pytest.raises(ValueError):
        mA @ mA
    with pytest.raises(ValueError):
        vx @ vy


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_determinant_inverse_trace(n):
    rng = np.random.default_rng(n)
    for _ in range(5):
        A = rng.standard_normal((n, n)) + n * np.eye(n)
        m = ti.Matrix(A)
        np.testing.assert_allclose(m.determinant(), np.linalg.det(A), rtol=1e-12)
        np.testing.assert_allclose(_np(m.inverse()), np.linalg.inv(A), rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(m.trace(), np.trace(A), rtol=1e-14)
    I = ti.Matrix(np.arange(n * n).reshape(n, n) % 5 + np.eye(n, dtype=int))
    assert I.determinant() == round(np.linalg.det(I.to_numpy()))  # integer matrices stay exact
    with pytest.raises(ValueError):
        ti.Matrix([[1.0, 2.0]]).determinant()


def test_vector_methods():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([4.0, -5.0, 6.0])
    v, w = ti.Vector(a.tolist()), ti.Vector(b.tolist())
    np.testing.assert_allclose(v.norm(), np.linalg.norm(a))
    np.testing.assert_allclose(v.norm(1e-2), np.sqrt(a @ a + 1e-2))
    np.testing.assert_allclose(v.norm_sqr(), a @ a)
    np.testing.assert_allclose(v.norm_inv(1e-2), 1 / np.sqrt(a @ a + 1e-2))
    np.testing.assert_allclose(_np(v.normalized()), a / np.linalg.norm(a))
    np.testing.assert_allclose(_np(v.normalized(1e-2)), a / (np.linalg.norm(a) + 1e-2))  # Taichi: |v| + eps
    np.testing.assert_allclose(_np(ti.Vector.normalized(v, 1e-2)), a / (np.linalg.norm(a) + 1e-2))
    np.testing.assert_allclose(v.dot(w), a @ b)
    np.testing.assert_allclose(ti.Vector.dot(v, w), a @ b)
    np.testing.assert_allclose(_np(v.cross(w)), np.cross(a, b))
    assert ti.Vector([1, 2]).cross(ti.Vector([3, 4])) == 1 * 4 - 2 * 3
    np.testing.assert_allclose(_np(v.outer_product(ti.Vector([1.0, 2.0]))), np.outer(a, [1.0, 2.0]))
    assert (v.sum(), w.max(), w.min()) == (6.0, 6.0, -5.0)
    assert ti.Vector([0, 1]).any() and not ti.Vector([0, 1]).all() and ti.Vector([2, -1]).all()
    assert not ti.Vector([0, 0]).any()
    assert ti.Vector([1.7, -1.7]).cast(ti.i32).to_list() == [1, -1]
    assert ti.Vector([0.1]).cast(ti.f32)[0] == float(np.float32(0.1))
    M = np.array([[1.0, -2.0], [3.0, 4.0]])
    np.testing.assert_allclose(ti.Matrix(M).norm(), np.linalg.norm(M))  # Frobenius
    assert ti.Matrix(M).sum() == M.sum() and ti.Matrix(M).max() == 4.0
    with pytest.raises(ValueError):
        v.dot(ti.Vector([1.0, 2.0]))
    with pytest.raises(ValueError):
        ti.Vector([1.0, 2.0, 3.0, 4.0]).cross(ti.Vector([1.0, 2.0, 3.0, 4.0]))


def test_constructors():
    np.testing.assert_array_equal(_np(ti.Matrix.identity(ti.f32, 3)), np.eye(3))
    np.testing.assert_array_equal(_np(ti.Matrix.zero(ti.f32, 2, 3)), np.zeros((2, 3)))
    np.testing.assert_array_equal(_np(ti.Matrix.one(ti.f64, 2, 2)), np.ones((2, 2)))
    assert ti.Vector.zero(ti.i32, 3).to_list() == [0, 0, 0] and ti.Vector.one(ti.i32, 2).to_list() == [1, 1]
    np.testing.assert_array_equal(_np(ti.Matrix.diag(3, 2.5)), 2.5 * np.eye(3))
    assert ti.Matrix.rows([ti.Vector([1, 2]), ti.Vector([3, 4])]).to_list() == [[1, 2], [3, 4]]
    assert ti.Matrix.cols([ti.Vector([1, 2]), ti.Vector([3, 4])]).to_list() == [[1, 3], [2, 4]]
    assert ti.Vector.unit(3, 1).to_list() == [0, 1, 0]
    assert ti.Vector.unit(2, 0, ti.f32).to_list() == [1.0, 0.0]


# -- kernels ----------------------------------------------------------------------------------------------
def test_kernel_methods_against_numpy():
    rng = np.random.default_rng(5)
    a, b = rng.standard_normal(3), rng.standard_normal(3)
    A, B = rng.standard_normal((3, 3)), rng.standard_normal((3, 2))
    va, vb = ti.Vector.field(3, ti.f64, shape=()), ti.Vector.field(3, ti.f64, shape=())
    mA, mB = ti.Matrix.field(3, 3, ti.f64, shape=()), ti.Matrix.field(3, 2, ti.f64, shape=())
    va[None], vb[None], mA[None], mB[None] = a.tolist(), b.tolist(), A.tolist(), B.tolist()
    out = ti.field(ti.f64, shape=64)

    @ti.kernel
    def k():
        v, w, M, N = va[None], vb[None], mA[None], mB[None]
        c = v.cross(w)
        o = v.outer_product(w)
        mm = M @ N
        mv = M @ v
        vm = v @ M
        Mt = M.transpose()
        nv = v.normalized(1e-2)
        nv2 = ti.Vector.normalized(w, 0.5)
        ele = (v * 2.0 - w / 3.0) ** 2
        vals = [v.dot(w), v.norm(), v.norm(0.3), v.norm_sqr(), v.norm_inv(), c[0], c[1], c[2], o[2, 1],
                mm[2, 1], mv[1], vm[2], Mt[0, 2], M.determinant(), M.inverse()[1, 2], M.trace(), M.norm(),
                nv[0], nv2[2], v.sum(), v.max(), v.min(), ele[1], (v @ w), v.x + 10.0 * v.zyx[0],
                M[1, 2], ti.max(v, w)[0], (v < w)[1], M.sum()]
        for j in ti.static(range(len(vals))):
            out[j] = vals[j]

    k()
    Ai = np.linalg.inv(A)
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    want = [a @ b, na, np.sqrt(a @ a + 0.3), a @ a, 1 / na, *np.cross(a, b), np.outer(a, b)[2, 1],
            (A @ B)[2, 1], (A @ a)[1], (a @ A)[2], A.T[0, 2], np.linalg.det(A), Ai[1, 2],
            np.trace(A), np.linalg.norm(A), a[0] / (na + 1e-2), b[2] / (nb + 0.5),
            a.sum(), a.max(), a.min(), ((a * 2 - b / 3) ** 2)[1], a @ b, a[0] + 10 * a[2], A[1, 2],
            max(a[0], b[0]), float(a[1] < b[1]), A.sum()]
    np.testing.assert_allclose(out.to_numpy()[: len(want)], want, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_kernel_determinant_inverse(n):
    rng = np.random.default_rng(10 + n)
    A = rng.standard_normal((16, n, n)) + n * np.eye(n)
    M, Inv = ti.Matrix.field(n, n, ti.f64, shape=16), ti.Matrix.field(n, n, ti.f64, shape=16)
    D = ti.field(ti.f64, shape=16)
    M.from_numpy(A)

    @ti.kernel
    def k():
        for i in M:
            D[i] = M[i].determinant()
            Inv[i] = M[i].inverse()

    k()
    np.testing.assert_allclose(D.to_numpy(), np.linalg.det(A), rtol=1e-12)
    np.testing.assert_allclose(Inv.to_numpy(), np.linalg.inv(A), rtol=1e-10, atol=1e-12)


def test_kernel_constructors_swizzles_and_local_updates():
    out = ti.field(ti.f64, shape=32)

    @ti.kernel
    def k():
        I = ti.Matrix.identity(ti.f32, 3)
        Z = ti.Matrix.zero(ti.f64, 2, 3)
        O = ti.Matrix.one(ti.f32, 2, 2)
        D = ti.Matrix.diag(3, 2.5)
        R = ti.Matrix.rows([ti.Vector([1, 2]), ti.Vector([3, 4])])
        C = ti.Matrix.cols([ti.Vector([1, 2]), ti.Vector([3, 4])])
        u = ti.Vector.unit(3, 1)
        v = ti.Vector([1.0, 2.0, 3.0, 4.0])
        v.x = 7.0
        v[1] = 8.0
        v.zw = ti.Vector([5.0, 6.0])
        m = ti.Matrix([[1.0, 2.0], [3.0, 4.0]])
        m[1, 0] = 9.0
        m[0, 1] = 5.0
        m += 1.0
        m *= 2.0
        vals = [I.sum(), I[1, 1], Z.sum(), O.sum(), D[2, 2] + D[0, 1], R[0, 1], C[0, 1], u[1] + 10 * u[0],
                v.x, v.y, v.z, v.w, v.wzyx[0], v.rg.sum(), m[0, 0], m[0, 1], m[1, 0], m[1, 1],
                ti.Vector([1, 2]).cross(ti.Vector([3, 4])), v.xyz.cross(ti.Vector([0.0, 0.0, 1.0]))[0]]
        for j in ti.static(range(len(vals))):
            out[j] = vals[j]

    k()
    want = [3, 1, 0, 4, 2.5, 2, 3, 1, 7, 8, 5, 6, 6, 15, 4, 12, 20, 10, -2, 8]
    np.testing.assert_allclose(out.to_numpy()[: len(want)], want)


def test_kernel_value_index_on_matrix_expression():
    """A run-time index into a matrix *value* (not a variable) selects among the entries."""
    out = ti.field(ti.f64, shape=7)

    @ti.kernel
    def k():
        for i in range(3):
            out[i] = (ti.Vector([10.0, 20.0, 30.0]) + 0.5)[i]
        for i, j in ti.ndrange(2, 2):
            out[3 + i * 2 + j] = (ti.Matrix([[1.0, 2.0], [3.0, 4.0]]) * 2.0)[i, j]

    k()
    np.testing.assert_allclose(out.to_numpy(), [10.5, 20.5, 30.5, 2, 4, 6, 8])


def test_kernel_runtime_index_into_local_matrix_variable():
    out = ti.field(ti.f64, shape=7)

    @ti.kernel
    def k():
        v = ti.Vector([10.0, 20.0, 30.0])
        m = ti.Matrix([[1.0, 2.0], [3.0, 4.0]])
        for i in range(3):
            out[i] = v[i]
        for i, j in ti.ndrange(2, 2):
            out[3 + i * 2 + j] = m[i, j]

    k()
    np.testing.assert_allclose(out.to_numpy(), [10, 20, 30, 1, 2, 3, 4])


def test_assigning_a_matrix_of_another_shape_is_refused_never_a_prefix():
    """A 2-vector stored into a 3-vector (field, ndarray or local) used to store two entries and leave
    the third: now a located error, as Taichi's 'cannot assign [Tensor (2) i32] to [Tensor (3) i32]'."""
    v = ti.Vector.field(3, ti.i32, shape=2)

    @ti.kernel
    def into_field():
        for i in v:
            v[i] = [1, 2]

    @ti.kernel
    def into_ndarray(a: ti.types.ndarray(dtype=ti.types.vector(3, ti.i32))):
        for i in a:
            a[i] = ti.Vector([1, 2])

    @ti.kernel
    def into_local() -> ti.i32:
        a = ti.Vector([1, 2, 3])
        a = [1, 2]
        return a[2]

    @ti.kernel
    def matrix_into_matrix():
        m = ti.Matrix([[1.0, 0.0], [0.0, 1.0]])
        m = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]

    for k, args in ((into_field, ()), (into_ndarray, (np.zeros((2, 3), np.int32),)), (into_local, ()),
                    (matrix_into_matrix, ())):
        with pytest.raises(ti.TaichiCompilationError, match=r"cannot assign '\[Tensor \(2\) i32\]'|"
                                                            r"cannot assign '\[Tensor \(2, 3\) f32\]'"):
            k(*args)
    assert not v.to_numpy().any()


def test_kernel_matrix_indexing_takes_one_index_per_axis():
    """As Taichi 1.7: in kernels a matrix is indexed m[i, j] and a vector v[i]; a row m[i] or v[i, j] is a
    located error (Python scope keeps numpy-like rows)."""

    @ti.kernel
    def row():
        m = ti.Matrix([[1, 2, 3], [4, 5, 6]])
        print(m[0])

    @ti.kernel
    def two_on_vector():
        v = ti.Vector([1, 2, 3])
        print(v[0, 0])

    with pytest.raises(ti.TaichiCompilationError, match=r"Expected 2 indices, got 1"):
        row()
    with pytest.raises(ti.TaichiCompilationError, match=r"Expected 1 indices, got 2"):
        two_on_vector()
    assert list(ti.Matrix([[1, 2], [3, 4]])[1]) == [3, 4]


def test_fill_of_a_local_or_element_matrix_assigns_it():
    """`m.fill(v)` on a kernel's local matrix, field element or struct member used to fill a loaded copy
    (the write was dropped)."""
    v = ti.Vector.field(3, ti.f32, shape=2)

    @ti.kernel
    def k() -> ti.f32:
        m = ti.Matrix([[0.0, 0.0], [0.0, 0.0]])
        m.fill(1.5)
        for i in v:
            v[i].fill(2.5)
        return m.sum()

    assert k() == 6.0
    np.testing.assert_array_equal(v.to_numpy(), 2.5)


def test_matrix_type_constructors_take_taichis_argument_forms():
    mat4x3 = ti.types.matrix(4, 3, float)
    mat2x6 = ti.types.matrix(2, 6, float)
    vec3 = ti.math.vec3
    b = np.arange(9.0).reshape(3, 3)
    want = np.arange(1.0, 13.0).reshape(4, 3)
    forms = [mat4x3([1, 2, 3], [4, 5, 6], [7, 8, 9], [10, 11, 12]), mat4x3(want.tolist()),
             mat4x3(vec3(1, 2, 3), vec3(4, 5, 6), vec3(7, 8, 9), vec3(10, 11, 12)), mat4x3(list(range(1, 13))),
             mat4x3(*range(1, 13)), mat4x3(mat4x3(want))]
    for m in forms:
        np.testing.assert_array_equal(m.to_numpy(), want)
    np.testing.assert_array_equal(ti.math.mat3(b).to_numpy(), b)
    np.testing.assert_array_equal(mat4x3(1).to_numpy(), np.ones((4, 3)))
    np.testing.assert_array_equal(mat2x6(forms[0]).to_numpy(), want.reshape(2, 6))
    with pytest.raises(ValueError, match="takes 12 entries, got 5"):
        mat4x3(1, 2, 3, 4, 5)
    with pytest.raises(ti.TaichiCompilationError, match="dimensionality of shape and offset"):
        ti.field(ti.f32, shape=3, offset=(3, 4))
