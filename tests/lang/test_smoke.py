import numpy as np

import simgrad as ti


def test_parallel_fill_and_struct_for_2d():
    x = ti.field(ti.f32, shape=8)
    y = ti.field(ti.f32, shape=(8, 4))

    @ti.kernel
    def fill(a: ti.f32):
        for i in x:
            x[i] = i * a
        for i, j in y:
            y[i, j] = i * 10 + j

    fill(2.0)
    np.testing.assert_array_equal(x.to_numpy(), np.arange(8) * 2.0)
    np.testing.assert_array_equal(y.to_numpy(), np.arange(8)[:, None] * 10 + np.arange(4)[None, :])


def test_kernel_scope_local_reduction_is_atomic():
    n = 200_000
    x = ti.field(ti.f32, shape=n)
    x.fill(1)

    @ti.kernel
    def total() -> ti.f32:
        s = 0.0
        for i in range(n):
            s += x[i]
        return s

    assert total() == n
