"""ti.ndarray / ti.Vector.ndarray / ti.Matrix.ndarray objects: Python-scope indexing (live element views),
fill, to/from numpy, and use as kernel arguments with every form of ti.types.ndarray, against numpy."""

import numpy as np
import pytest

import simgrad as ti


def test_scalar_ndarray_python_scope_and_kernel():
    ti.init(arch=ti.cpu)
    a = ti.ndarray(ti.f32, shape=(3, 4))
    assert isinstance(a, ti.ScalarNdarray) and a.shape == (3, 4) and a.dtype is ti.f32
    a[1, 2] = 4.5
    assert a[1, 2] == 4.5 and isinstance(a[1, 2], float)

    @ti.kernel
    def scale(x: ti.types.ndarray(), k: ti.f32):
        for i, j in x:
            x[i, j] = x[i, j] * k + i * 10 + j

    scale(a, 2.0)
    want = np.fromfunction(lambda i, j: i * 10 + j, (3, 4)).astype(np.float32)
    want[1, 2] += 9.0
    np.testing.assert_array_equal(a.to_numpy(), want)
    a.fill(1.0)
    assert a.to_numpy().sum() == 12
    with pytest.raises(ti.SimgradIndexError):
        a[3, 0] = 1.0
    with pytest.raises(ti.SimgradIndexError):
        _ = a[-1, 0]


def test_vector_ndarray_elements_write_through_and_pass_to_kernels():
    ti.init(arch=ti.cpu)
    v = ti.ndarray(ti.math.vec3, shape=4)
    assert isinstance(v, ti.VectorNdarray) and v.shape == (4,) and v.element_shape == (3,)
    v[1] = ti.Vector([1.0, 2.0, 3.0])
    v[2][1] = 5.0  # element assignment writes through, as in Taichi
    v[3].z = 7.0
    np.testing.assert_array_equal(v.to_numpy(), [[0, 0, 0], [1, 2, 3], [0, 5, 0], [0, 0, 7]])

    @ti.kernel
    def norms(x: ti.types.ndarray(), out: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in x:  # a vec3 ndarray without dtype in the annotation: elements are its vectors
            out[i] = x[i].norm()

    out = ti.ndarray(ti.f32, shape=4)
    norms(v, out)
    np.testing.assert_allclose(out.to_numpy(), np.linalg.norm(v.to_numpy(), axis=1), rtol=1e-6)

    w = ti.Vector.ndarray(2, ti.i32, shape=(2, 2))

    @ti.kernel
    def fill_idx(x: ti.types.ndarray(dtype=ti.types.vector(2, ti.i32), ndim=2)):
        for i, j in x:
            x[i, j] = ti.Vector([i, j])

    fill_idx(w)
    np.testing.assert_array_equal(w.to_numpy(), np.stack(np.meshgrid([0, 1], [0, 1], indexing="ij"), -1))


def test_matrix_ndarray_from_numpy_and_element_dim_annotation():
    ti.init(arch=ti.cpu)
    m = ti.Matrix.ndarray(2, 2, ti.f64, shape=3)
    assert isinstance(m, ti.MatrixNdarray) and (m.n, m.m) == (2, 2)
    src = np.random.default_rng(0).random((3, 2, 2))
    m.from_numpy(src)
    m[0][1, 0] = -1.0
    src[0, 1, 0] = -1.0
    det = ti.ndarray(ti.f64, shape=3)

    @ti.kernel
    def dets(a: ti.types.ndarray(element_dim=2), out: ti.types.ndarray()):
        for i in a:
            out[i] = a[i].determinant()

    dets(m, det)
    np.testing.assert_allclose(det.to_numpy(), np.linalg.det(src), rtol=1e-12)
    with pytest.raises(ti.SimgradTypeError):
        m.from_numpy(np.zeros((3, 2)))


def test_boundary_clamp_clamps_every_index():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def read(x: ti.types.ndarray(boundary="clamp"), i: ti.i32, j: ti.i32) -> ti.f32:
        return x[i, j]

    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    for i, j in [(-1, 0), (-5, 2), (1, 9), (7, 7), (2, 1)]:
        assert read(a, i, j) == a[min(max(i, 0), 2), min(max(j, 0), 3)]
    with pytest.raises(ti.SimgradTypeError, match="boundary"):
        ti.types.ndarray(boundary="wrap")


def test_boundary_clamp_also_clamps_an_elements_own_run_time_index():
    """As Taichi: a vector element's index is clamped into [0, n); a matrix element's row-major flat index
    into [0, n*m) (so (2, 0) of a 2x2 element is its last entry)."""
    ti.init(arch=ti.cpu)

    @ti.kernel
    def vec_at(x: ti.types.ndarray(boundary="clamp"), k: ti.i32) -> ti.f32:
        return x[1, 2][k]

    @ti.kernel
    def mat_at(x: ti.types.ndarray(boundary="clamp"), i: ti.i32, j: ti.i32) -> ti.f32:
        return x[1, 2][i, j]

    v = ti.ndarray(ti.math.vec2, shape=(3, 3))
    m = ti.ndarray(ti.math.mat2, shape=(3, 3))
    v[1, 2] = [10.0, 20.0]
    m[1, 2] = [[1.0, 2.0], [3.0, 4.0]]
    assert [vec_at(v, k) for k in (-3, 0, 1, 7)] == [10.0, 10.0, 20.0, 20.0]
    flat = np.array([[1.0, 2.0], [3.0, 4.0]]).reshape(-1)
    for i, j in [(-1, 0), (1, -1), (2, 0), (1, 2), (0, 1)]:
        assert mat_at(m, i, j) == flat[min(max(i * 2 + j, 0), 3)]
