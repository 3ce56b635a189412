"""`ti.types.ndarray(element_dim=...)` and `element_shape=...`: the trailing axes of the array form each
element, a vector or matrix (element_dim was accepted and ignored, so the unmodified diffmpm3d stopped on
`x_[i]`). Checked against numpy on the same arrays."""

from __future__ import annotations

import numpy as np
import pytest

import simgrad as ti
from simgrad.errors import SimgradTypeError


def test_element_dim_1_gives_vectors():
    ti.init(arch=ti.cpu)
    x = ti.Vector.field(3, ti.f32, 4)

    @ti.kernel
    def load(x_: ti.types.ndarray(element_dim=1)):
        for i in range(4):
            x[i] = x_[i] * 2

    a = np.arange(12, dtype=np.float32).reshape(4, 3)
    load(a)
    np.testing.assert_array_equal(x.to_numpy(), a * 2)
    b = np.arange(8, dtype=np.float32).reshape(4, 2)  # another element size compiles another instance
    with pytest.raises(SimgradTypeError, match=r"cannot assign .*a \(2,\) matrix to a \(3,\) one"):
        load(b)  # a 2-vector into a 3-vector field


def test_element_shape_gives_matrices():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def det_sum(y: ti.types.ndarray(element_shape=(2, 2))) -> ti.f32:
        s = 0.0
        for i in range(y.shape[0]):
            s += y[i].determinant() + y[i][0, 1]
        return s

    a = np.random.default_rng(0).standard_normal((5, 2, 2)).astype(np.float32)
    want = float(np.sum(np.linalg.det(a) + a[:, 0, 1]))
    assert det_sum(a) == pytest.approx(want, rel=1e-5)


def test_element_dim_2_and_a_wrong_trailing_shape():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def trace(y: ti.types.ndarray(element_dim=2), out: ti.types.ndarray()):
        for i in range(out.shape[0]):
            out[i] = y[i].trace()

    a = np.arange(18, dtype=np.float64).reshape(2, 3, 3)
    out = np.zeros(2)
    trace(a, out)
    np.testing.assert_array_equal(out, np.trace(a, axis1=1, axis2=2))

    @ti.kernel
    def first(y: ti.types.ndarray(element_shape=(3,))) -> ti.f32:
        return y[0][0]

    with pytest.raises(ValueError, match=r"Invalid value for argument y - required element type: \[Tensor \(3\) "
                                         r"f32\], but an array of shape \(4, 2\) is provided"):
        first(np.zeros((4, 2), np.float32))


def test_element_shape_is_a_method_in_kernels():
    # Taichi's kernel-scope ndarray (AnyArray) has element_shape() returning a list (real_func/graph/
    # stable_fluid_graph.py: `if ti.static(vf.element_shape() == [2])`); in Python scope it is a tuple property
    @ti.func
    def width(a: ti.template()):
        w = 0
        if ti.static(a.element_shape() == [2]):
            w = 2
        elif ti.static(a.element_shape() == []):
            w = 1
        return w

    @ti.kernel
    def widths(v: ti.types.ndarray(ndim=1), s: ti.types.ndarray(ndim=1)) -> ti.i32:
        return width(v) * 10 + width(s)

    v = ti.Vector.ndarray(2, ti.f32, shape=3)
    assert v.element_shape == (2,)
    assert widths(v, ti.ndarray(ti.f32, shape=3)) == 21
