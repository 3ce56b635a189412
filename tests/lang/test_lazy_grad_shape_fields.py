"""ti.root.lazy_grad() gives gradients to fields made with ti.field(shape=...) too (Taichi places those under
ti.root), so `loss.grad[i] = 1` after it works, and kernel.grad fills x.grad (checked against numpy)."""

import numpy as np

import simgrad as ti


def test_lazy_grad_covers_shape_fields():
    ti.init(arch=ti.cpu)
    n = 5
    loss = ti.field(ti.f32, shape=n)
    x = ti.field(ti.f32, shape=n)
    y = ti.field(ti.f32, shape=n)
    ti.root.lazy_grad()
    for i in range(n):
        x[i], y[i] = i, -i
        loss.grad[i] = 1.0

    @ti.kernel
    def func():
        for i in range(n):
            loss[i] += ti.select(i % 2, x[i], y[i])

    func()
    func.grad()
    np.testing.assert_array_equal(x.grad.to_numpy(), np.arange(n) % 2)
    np.testing.assert_array_equal(y.grad.to_numpy(), 1 - np.arange(n) % 2)
