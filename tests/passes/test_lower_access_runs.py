"""The offsets passes/lower_access.py computes, checked against numpy on kernels that run: nested and
blocked dense layouts (division/remainder terms), offsets, AoS vector fields, ndarrays with element
dimensions, a loop-invariant element, and the debug-mode index check."""

import numpy as np
import pytest

import simgrad as ti


def test_blocked_and_nested_layouts_match_numpy():
    ti.init(arch=ti.cpu)
    a = ti.field(ti.f32)
    ti.root.dense(ti.ij, (3, 2)).dense(ti.ij, (4, 5)).place(a)
    b = ti.field(ti.f32, shape=(12, 10))
    c = ti.Vector.field(3, ti.f32, shape=(5, 7), offset=(-2, 3))

    @ti.kernel
    def fill():
        for i, j in a:
            a[i, j] = i * 100 + j
        for i, j in b:
            b[i, j] = a[i, j] * 2 + a[11 - i, 9 - j]
        for i, j in c:
            c[i, j] = ti.Vector([i, j, i * j])

    fill()
    ii, jj = np.meshgrid(np.arange(12), np.arange(10), indexing="ij")
    ref = (ii * 100 + jj).astype(np.float32)
    np.testing.assert_array_equal(a.to_numpy(), ref)
    np.testing.assert_array_equal(b.to_numpy(), ref * 2 + ref[::-1, ::-1])
    ci, cj = np.meshgrid(np.arange(-2, 3), np.arange(3, 10), indexing="ij")
    np.testing.assert_array_equal(c.to_numpy(), np.stack([ci, cj, ci * cj], -1).astype(np.float32))


def test_ndarray_elements_and_an_invariant_element():
    ti.init(arch=ti.cpu)
    total = ti.field(ti.f64, shape=(3,))

    @ti.kernel
    def k(x: ti.types.ndarray(dtype=ti.math.vec2, ndim=2), t: ti.i32):
        for i, j in x:
            x[i, j][1] = x[i, j][0] * 3 + i - j
            total[t] += x[i, j][0]

    x = np.random.default_rng(0).random((6, 9, 2)).astype(np.float32)
    want = x.copy()
    want[..., 1] = x[..., 0] * 3 + np.arange(6)[:, None] - np.arange(9)[None, :]
    k(x, 2)
    np.testing.assert_allclose(x, want, rtol=1e-6)
    np.testing.assert_allclose(total.to_numpy(), [0, 0, want[..., 0].astype(np.float64).sum()], rtol=1e-5)


def test_debug_mode_reports_the_users_index_through_the_lowered_check():
    ti.init(arch=ti.cpu, debug=True)
    f = ti.field(ti.f32, shape=(4, 5), offset=(1, 0))

    @ti.kernel
    def bad(i: ti.i32):
        f[i, 2] = 1.0

    bad(4)
    assert f[4, 2] == 1.0
    with pytest.raises(ti.SimgradIndexError, match=r"5"):
        bad(5)
