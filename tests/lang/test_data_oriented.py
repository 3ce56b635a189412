"""@ti.data_oriented classes as Taichi has them: fields as attributes, kernels and funcs as methods (`self` is
a compile-time value), inheritance, instances made in a loop, gradients through method kernels."""

import numpy as np
import pytest

import simgrad as ti


@ti.data_oriented
class Springs:
    def __init__(self, n: int, k: float):
        self.n, self.k = n, k
        self.x = ti.field(ti.f64, shape=n, needs_grad=True)
        self.energy = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.func
    def spring(self, a, b):
        return 0.5 * self.k * (a - b) ** 2

    @ti.kernel
    def compute(self, scale: ti.f64):
        for i in range(self.n - 1):
            self.energy[None] += scale * self.spring(self.x[i], self.x[i + 1])


class Chain(Springs):  # inherits the decorated class's kernels
    @ti.kernel
    def place(self, step: ti.f64):
        for i in self.x:
            self.x[i] = step * i * i


def _energy(x, k, scale):
    return scale * 0.5 * k * np.sum(np.diff(x) ** 2)


def test_methods_inheritance_and_instances_made_in_a_loop():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    for n, k in ((4, 2.0), (7, 0.5), (4, 3.0)):
        c = Chain(n, k)
        c.place(0.5)
        c.compute(2.0)
        x = 0.5 * np.arange(n) ** 2
        np.testing.assert_allclose(c.x.to_numpy(), x)
        assert c.energy[None] == pytest.approx(_energy(x, k, 2.0), rel=1e-12)


def test_gradient_through_a_method_kernel_matches_finite_differences():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    s = Springs(5, 1.5)
    x0 = np.random.default_rng(1).random(5)
    s.x.from_numpy(x0)
    with ti.ad.Tape(loss=s.energy):
        s.compute(3.0)
    g = s.x.grad.to_numpy()
    eps = 1e-6
    for i in range(5):
        xp, xm = x0.copy(), x0.copy()
        xp[i] += eps
        xm[i] -= eps
        fd = (_energy(xp, 1.5, 3.0) - _energy(xm, 1.5, 3.0)) / (2 * eps)
        assert g[i] == pytest.approx(fd, rel=1e-6, abs=1e-9)
    s.energy[None] = 0
    s.energy.grad[None] = 1
    s.x.grad.fill(0)
    s.compute.grad(3.0)  # the bound adjoint
    np.testing.assert_allclose(s.x.grad.to_numpy(), g, rtol=1e-12)


def test_data_oriented_object_as_a_template_argument():
    ti.init(arch=ti.cpu)
    s = Springs(3, 1.0)
    out = ti.field(ti.f32, shape=())

    @ti.kernel
    def count(obj: ti.template()):
        for i in obj.x:
            out[None] += obj.n + obj.x[i] * 0

    count(s)
    assert out[None] == 9
