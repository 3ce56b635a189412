"""Kernel parameters (scalars, vectors, templates, ndarrays), return values, and ti.func."""

import numpy as np
import pytest

import simgrad as ti


def test_scalar_annotations():
    @ti.kernel
    def k(a: ti.i32, b: ti.f64, c: int, d: float, e: ti.u8, f: ti.i64) -> ti.f64:
        return a * 1000 + b + c * 100 + d + e * 10000 + f

    assert k(1, 0.25, 2, 0.5, 3, 2**40) == 1000 + 0.25 + 200 + 0.5 + 30000 + 2**40
    assert k(-1, -0.25, -2, 0.125, 255, -(2**40)) == -1000 - 0.25 - 200 + 0.125 + 255 * 10000 - 2**40

    @ti.kernel
    def types(c: int, d: float) -> ti.f64:
        return d * 0 + 1 / 3 + c * 0  # `float` means default_fp (f32) so 1/3 is rounded to f32

    assert types(1, 1.0) == float(np.float32(1) / np.float32(3))


def test_scalar_args_accept_numpy_scalars_and_bool():
    @ti.kernel
    def k(a: ti.i32, b: ti.f32) -> ti.f32:
        return a + b

    assert k(np.int64(3), np.float64(0.5)) == 3.5
    assert k(True, np.float32(0.25)) == 1.25


def test_f64_arg_keeps_full_precision():
    @ti.kernel
    def k(x: ti.f64) -> ti.f64:
        return x + 1e-12

    assert k(1.0) == 1.0 + 1e-12

    @ti.kernel
    def k32(x: ti.f32) -> ti.f64:
        return x

    assert k32(0.1) == float(np.float32(0.1))


def test_vector_args():
    @ti.kernel
    def k(v: ti.math.vec3, w: ti.types.vector(2, ti.i32), m: ti.types.matrix(2, 2, ti.f64)) -> ti.f64:
        return v.dot(ti.math.vec3(1.0, 10.0, 100.0)) + w[0] * 1000 + w[1] * 10000 + (m @ m)[0, 1]

    m = np.array([[1.0, 2.0], [3.0, 4.0]])
    want = 1 + 20 + 300 + 4000 + 50000 + (m @ m)[0, 1]
    assert k(ti.math.vec3(1, 2, 3), [4, 5], m) == want
    assert k([1.0, 2.0, 3.0], np.array([4, 5]), ti.Matrix([[1.0, 2.0], [3.0, 4.0]])) == want
    assert k((1, 2, 3), (4, 5), m.tolist()) == want


def test_return_vector_and_matrix():
    @ti.kernel
    def k(x: ti.f32) -> ti.math.vec2:
        return ti.math.vec2(x, x * 2)

    r = k(1.5)
    assert r[0] == 1.5 and r[1] == 3.0 and len(r) == 2

    @ti.kernel
    def m(x: ti.i32) -> ti.types.matrix(2, 2, ti.i32):
        return ti.Matrix([[x, x + 1], [x + 2, x + 3]])

    r = m(10)
    assert r[1, 0] == 12 and r[0, 1] == 11
    np.testing.assert_array_equal(r.to_numpy(), [[10, 11], [12, 13]])


def test_return_scalar_is_cast_to_annotation():
    @ti.kernel
    def k(x: ti.f32) -> ti.i32:
        return x * 2

    assert k(1.75) == 3 and isinstance(k(1.75), int)

    @ti.kernel
    def u(x: ti.i32) -> ti.u8:
        return x

    assert u(258) == 2

    @ti.kernel
    def f() -> ti.f64:
        return 7 // 2

    assert f() == 3.0 and isinstance(f(), float)


def test_template_args_fields_and_python_values():
    a = ti.field(ti.f32, shape=4)
    b = ti.field(ti.i32, shape=(2, 3))
    compiled = []

    @ti.kernel
    def fill(x: ti.template(), v: ti.template()):
        compiled.append(1)  # runs at compile time only: counts instantiations
        for I in ti.grouped(x):
            x[I] = v * (I.sum() + 1)

    fill(a, 2)
    fill(b, 3)
    fill(a, 2)  # cached
    fill(a, 0.5)  # a new value is a new instantiation
    assert len(compiled) == 3
    np.testing.assert_array_equal(a.to_numpy(), 0.5 * (np.arange(4) + 1))
    np.testing.assert_array_equal(b.to_numpy(), 3 * (np.indices((2, 3)).sum(axis=0) + 1))


def test_template_with_python_function_and_tuple():
    x = ti.field(ti.f32, shape=3)

    @ti.func
    def sq(v):
        return v * v

    @ti.func
    def neg(v):
        return -v

    @ti.kernel
    def apply(fn: ti.template(), coeffs: ti.template()):
        for i in x:
            s = 0.0
            for c in ti.static(coeffs):
                s += c * fn(i + 1.0)
            x[i] = s

    apply(sq, (1, 2))
    np.testing.assert_array_equal(x.to_numpy(), 3 * np.arange(1, 4) ** 2)
    apply(neg, (0.5,))
    np.testing.assert_array_equal(x.to_numpy(), -0.5 * np.arange(1, 4))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int32, np.int64, np.uint8], ids=str)
def test_ndarray_args_of_several_dtypes(dtype):
    @ti.kernel
    def k(a: ti.types.ndarray(), out: ti.types.ndarray()):
        for i in range(a.shape[0]):
            out[i] = a[i] * 2 + 1

    a = np.arange(7).astype(dtype)
    out = np.zeros(7, dtype=dtype)
    k(a, out)
    np.testing.assert_array_equal(out, a * 2 + 1)


def test_ndarray_ndims_and_shape_in_kernel():
    @ti.kernel
    def k(a: ti.types.ndarray(dtype=ti.f32, ndim=2), b: ti.types.ndarray(ndim=3), s: ti.types.ndarray()):
        for i, j in a:
            a[i, j] = i * 10 + j
        for i, j, q in ti.ndrange(b.shape[0], b.shape[1], b.shape[2]):
            b[i, j, q] += i * 100 + j * 10 + q
        s[0] = a.shape[0]
        s[1] = a.shape[1]
        s[2] = b.shape[2]

    a = np.zeros((3, 5), np.float32)
    b = np.ones((2, 3, 4), np.int64)
    s = np.zeros(3, np.int32)
    k(a, b, s)
    np.testing.assert_array_equal(a, np.fromfunction(lambda i, j: i * 10 + j, (3, 5)))
    np.testing.assert_array_equal(b, 1 + np.fromfunction(lambda i, j, q: i * 100 + j * 10 + q, (2, 3, 4)))
    assert s.tolist() == [3, 5, 4]
    a2 = np.zeros((4, 2), np.float32)  # same dtype and ndim, another shape: same instantiation
    b2 = np.zeros((1, 1, 1), np.int64)
    k(a2, b2, s)
    np.testing.assert_array_equal(a2, np.fromfunction(lambda i, j: i * 10 + j, (4, 2)))
    assert s.tolist() == [4, 2, 1]


def test_ndarray_of_vec3():
    @ti.kernel
    def k(p: ti.types.ndarray(dtype=ti.math.vec3, ndim=1), out: ti.types.ndarray()):
        for i in p:
            out[i] = p[i].norm_sqr()
            p[i] = p[i] * 2 + ti.math.vec3(0, 0, 1)

    p = np.arange(12, dtype=np.float32).reshape(4, 3)
    p0 = p.copy()
    out = np.zeros(4, np.float32)
    k(p, out)
    np.testing.assert_allclose(out, (p0**2).sum(axis=1))
    np.testing.assert_array_equal(p, p0 * 2 + [0, 0, 1])


def test_ndarray_wrong_dtype_or_ndim_is_an_error():
    @ti.kernel
    def k(a: ti.types.ndarray(dtype=ti.f32, ndim=1)):
        for i in a:
            a[i] = 1

    @ti.kernel
    def vec(a: ti.types.ndarray(dtype=ti.types.vector(2, ti.f32))):
        for i in a:
            a[i] = [1, 2]

    with pytest.raises(TypeError, match=r"kernel k: Invalid value for argument a - required array has dtype=f32, array "
                                        r"with dtype=f64 is provided"):  # Taichi's words for a numpy array
        k(np.zeros(3, np.float64))
    with pytest.raises(ValueError, match=r"argument a - required array has ndim=1, array with 2 dimensions is "):
        k(np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match=r"required element type: VectorType\[2, f32\], but \[Tensor \(2, 3\) "):
        vec(ti.Matrix.ndarray(2, 3, ti.f32, shape=4))  # a matrix element is never read as a vector
    with pytest.raises(ValueError, match=r"required element_shape=\(2,\), array with element shape of \(3,\)"):
        vec(np.zeros((4, 3), np.float32))
    with pytest.raises(TypeError, match="C-contiguous"):
        k(np.zeros(6, np.float32)[::2])


def test_func_with_return_value_nested_and_template_args():
    x = ti.field(ti.f32, shape=5)
    calls = []

    @ti.func
    def square(v):
        return v * v

    @ti.func
    def poly(v: ti.f32) -> ti.f32:
        return square(v) + 2 * v + 1

    @ti.func
    def add_to(f: ti.template(), i, v):
        f[i] += v  # templates pass fields by reference

    @ti.func
    def swap(a, b):
        calls.append(1)
        return b, a

    @ti.kernel
    def k():
        for i in x:
            x[i] = poly(i)
            add_to(x, i, 0.5)
            p, q = swap(i, 10)
            x[i] += p * 100 + q * 1000

    k()
    i = np.arange(5)
    np.testing.assert_array_equal(x.to_numpy(), (i + 1) ** 2 + 0.5 + 1000 + i * 1000)


def test_func_args_are_passed_by_value():
    out = ti.field(ti.i32, shape=2)

    @ti.func
    def bump(v):
        v += 1
        return v

    @ti.kernel
    def k():
        a = 5
        b = bump(a)
        out[0] = a
        out[1] = b

    k()
    assert out.to_numpy().tolist() == [5, 6]


def test_func_with_vector_args_and_early_static_branches():
    @ti.func
    def clamp_len(v, r: ti.template()):
        n = v.norm()
        res = v
        if n > r:
            res = v * (r / n)
        return res

    @ti.kernel
    def k(v: ti.math.vec2) -> ti.math.vec2:
        return clamp_len(v, 1.0)

    np.testing.assert_allclose(list(k([3.0, 4.0])), [0.6, 0.8], rtol=1e-6)
    np.testing.assert_allclose(list(k([0.3, 0.4])), [0.3, 0.4], rtol=1e-6)


def test_keyword_arguments():
    @ti.kernel
    def k(a: ti.i32, b: ti.i32) -> ti.i32:
        return a * 10 + b

    assert k(b=2, a=3) == 32
    assert k(3, b=2) == 32


def test_kernel_sees_python_globals_at_compile_time():
    out = ti.field(ti.f32, shape=())
    scale = 2.5

    @ti.kernel
    def k(x: ti.f32):
        out[None] = x * scale

    k(2.0)
    assert out[None] == 5.0


def test_float_argument_to_integer_parameter():
    """Passing 2.7 to an ti.i32 parameter silently truncates; Taichi raises a type error instead."""

    @ti.kernel
    def k(a: ti.i32) -> ti.i32:
        return a

    with pytest.raises(TypeError, match=r"kernel k: argument 'a'"):
        k(2.7)


def test_out_of_range_integer_argument_names_the_parameter():
    @ti.kernel
    def k(a: ti.u8) -> ti.i32:
        return a

    with pytest.raises((TypeError, OverflowError), match=r"kernel k.*'a'"):
        k(-1)
