"""Gradients through ndarray arguments (ti.ndarray(..., needs_grad=True), ti.types.ndarray(needs_grad=...)),
checked against central differences in float64, and the errors around them."""

import numpy as np
import pytest
from ad_util import f64, fd_grad, rel_err

import simgrad as ti


def test_scalar_ndarray_kernel_grad_matches_finite_differences():
    f64()
    n = 6

    @ti.kernel
    def energy(x: ti.types.ndarray(), w: ti.types.ndarray(), out: ti.types.ndarray()):
        for i in range(n):
            out[None] += w[i] * ti.sin(x[i]) * x[(i + 1) % n] ** 2

    rng = np.random.default_rng(1)
    x = ti.ndarray(ti.f64, shape=n, needs_grad=True)
    w = rng.random(n)  # a plain numpy array: a constant of the kernel
    out = ti.ndarray(ti.f64, shape=(), needs_grad=True)
    x.from_numpy(rng.random(n))

    def loss():
        out.fill(0)
        energy(x, w, out)
        return out[None]

    loss()
    out.grad[None] = 1.0
    energy.grad(x, w, out)
    assert rel_err(x.grad.to_numpy(), fd_grad(loss, x)) < 1e-7


def test_vector_ndarray_tape_matches_finite_differences():
    f64()
    n = 5

    @ti.kernel
    def spring(p: ti.types.ndarray(dtype=ti.math.vec3), loss: ti.types.ndarray()):
        for i in range(n - 1):
            d = p[i + 1] - p[i]
            loss[0] += (d.norm() - 0.5) ** 2

    p = ti.Vector.ndarray(3, ti.f64, shape=n, needs_grad=True)
    loss = ti.ndarray(ti.f64, shape=(1,), needs_grad=True)
    p.from_numpy(np.random.default_rng(2).random((n, 3)))

    def value():
        loss.fill(0)
        spring(p, loss)
        return loss[0]

    with ti.ad.Tape(loss=loss):
        spring(p, loss)
    assert loss[0] == pytest.approx(value())
    assert rel_err(p.grad.to_numpy(), fd_grad(value, p)) < 1e-7


def test_field_and_ndarray_gradients_together():
    f64()
    n = 4
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    total = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def mix(a: ti.types.ndarray()):
        for i in range(n):
            total[None] += a[i] * y[i] * a[i]

    a = ti.ndarray(ti.f64, shape=n, needs_grad=True)
    a.from_numpy(np.arange(1.0, n + 1))
    y.from_numpy(np.linspace(0.5, 2.0, n))
    with ti.ad.Tape(loss=total):
        mix(a)
    np.testing.assert_allclose(a.grad.to_numpy(), 2 * a.to_numpy() * y.to_numpy(), rtol=1e-12)
    np.testing.assert_allclose(y.grad.to_numpy(), a.to_numpy() ** 2, rtol=1e-12)


def test_needs_grad_false_annotation_keeps_the_argument_constant():
    f64()

    @ti.kernel
    def k(x: ti.types.ndarray(needs_grad=False), out: ti.types.ndarray()):
        for i in range(3):
            out[0] += 2.0 * x[i]

    x = ti.ndarray(ti.f64, shape=3, needs_grad=True)
    out = ti.ndarray(ti.f64, shape=1, needs_grad=True)
    out.grad.fill(1.0)
    k.grad(x, out)
    np.testing.assert_array_equal(x.grad.to_numpy(), 0.0)


def test_needs_grad_true_annotation_without_a_gradient_is_refused():
    @ti.kernel
    def k(x: ti.types.ndarray(needs_grad=True)):
        for i in range(3):
            x[i] += 1.0

    with pytest.raises(ti.TaichiCompilationError, match="needs_grad=True"):
        k(ti.ndarray(ti.f32, shape=3))


def test_integer_ndarray_with_gradient_is_refused():
    with pytest.raises(ti.TaichiRuntimeError, match="i32 is not supported"):
        ti.ndarray(ti.i32, shape=3, needs_grad=True)


def test_grad_of_an_argument_readable_forward_refused_in_an_adjoint():
    @ti.kernel
    def k(x: ti.types.ndarray(), b: ti.types.ndarray()):
        for i in x:
            b[None] += x.grad[i]

    a = ti.ndarray(ti.f32, shape=4, needs_grad=True)
    b = ti.ndarray(ti.f32, shape=(), needs_grad=True)
    a.grad.fill(2.0)
    k(a, b)
    assert b[None] == 8.0
    with pytest.raises(RuntimeError, match="differentiate through a grad tensor"):
        k.grad(a, b)


def test_tape_loss_ndarray_must_hold_one_element_and_a_gradient():
    with pytest.raises(ti.SimgradError, match="one element"):
        ti.ad.Tape(loss=ti.ndarray(ti.f32, shape=2, needs_grad=True))
    with pytest.raises(ti.SimgradError, match="no gradient"):
        ti.ad.Tape(loss=ti.ndarray(ti.f32, shape=1))


@pytest.mark.parametrize("threads", [1, 4])
def test_adjoint_of_an_ndarray_gather_scatters_into_per_thread_copies(threads):
    """out[i] = sum_k c_k * d[idx(i, k)] over a small d: the adjoint adds d.grad[idx] += c_k * out.grad[i], a
    scatter into an ndarray gradient, run over per-thread copies at 4 threads (compiler/test_ndarray_privatize.py
    for the forward scatters). Kernel.grad and the Tape against central differences in float64."""
    ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=threads)
    n, cells = 3000, 7

    @ti.kernel
    def gather(d: ti.types.ndarray(dtype=ti.math.vec2), out: ti.types.ndarray()):
        for i in range(n):
            for k in ti.static(range(3)):
                v = d[(i * 3 + k * 5) % cells]
                out[None] += (k + 1.0) * ti.sin(v[0] + 0.1 * i) * v[1]

    rng = np.random.default_rng(3)
    d = ti.Vector.ndarray(2, ti.f64, shape=cells, needs_grad=True)
    d.from_numpy(rng.random((cells, 2)))
    out = ti.ndarray(ti.f64, shape=(), needs_grad=True)

    def loss():
        out.fill(0)
        gather(d, out)
        return out[None]

    want = fd_grad(loss, d)
    with ti.ad.Tape(loss=out):
        gather(d, out)
    assert rel_err(d.grad.to_numpy(), want) < 1e-7
    d.grad.fill(0)
    out.grad[None] = 1.0
    gather.grad(d, out)
    assert rel_err(d.grad.to_numpy(), want) < 1e-7
    text = gather._instance_for((d, out), "grad").llvm_text
    assert "_private" in text  # the variant exists at any thread count; the run-time rule picks it
    if threads > 1:
        assert gather._instance_for((d, out), "grad").launcher._holders[:, 0].any()
