"""kernel.grad(*args) called directly (template and scalar arguments), and ti.ad.Tape: loss seeding,
gradient clearing, reverse replay, no_grad, grad_replaced/grad_for, and its errors."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import f64, fd_grad, rel_err

import simgrad as ti
from simgrad.errors import SimgradError


def test_kernel_grad_with_template_and_scalar_args():
    f64()
    a = ti.field(ti.f64, shape=10, needs_grad=True)
    b = ti.field(ti.f64, shape=10, needs_grad=True)
    out = ti.field(ti.f64, shape=10, needs_grad=True)

    @ti.kernel
    def f(src: ti.template(), dst: ti.template(), scale: ti.f64, shift: ti.i32):
        for i in src:
            dst[i] = scale * ti.sin(src[(i + shift) % 10])

    rng = np.random.default_rng(0)
    av, bv = rng.standard_normal(10), rng.standard_normal(10)
    a.from_numpy(av)
    b.from_numpy(bv)
    w = rng.standard_normal(10)
    for src, vals in ((a, av), (b, bv)):
        f(src, out, 1.5, 3)
        ti.ad.clear_all_gradients()
        out.grad.from_numpy(w)
        f.grad(src, out, 1.5, 3)
        expect = np.zeros(10)
        np.add.at(expect, (np.arange(10) + 3) % 10, w * 1.5 * np.cos(vals[(np.arange(10) + 3) % 10]))
        assert rel_err(src.grad.to_numpy(), expect, floor=1e-9) < 1e-13
        other = b if src is a else a
        assert not np.any(other.grad.to_numpy())
    assert len(f._caches["grad"]) == 2  # one adjoint per template instantiation

    def loss():
        f(a, out, 1.5, 3)
        return float(np.sum(out.to_numpy() * w))

    ti.ad.clear_all_gradients()
    f(a, out, 1.5, 3)
    out.grad.from_numpy(w)
    f.grad(a, out, 1.5, 3)
    assert rel_err(a.grad.to_numpy(), fd_grad(loss, a), floor=1e-6) < 1e-7


def test_kernel_grad_keyword_arguments():
    f64()
    x = ti.field(ti.f64, shape=5, needs_grad=True)
    y = ti.field(ti.f64, shape=5, needs_grad=True)

    @ti.kernel
    def f(p: ti.f64, q: ti.f64):
        for i in x:
            y[i] = x[i] ** p * q

    x.from_numpy(np.linspace(0.5, 2, 5))
    f(2.0, 3.0)
    y.grad.fill(1)
    f.grad(q=3.0, p=2.0)
    np.testing.assert_allclose(x.grad.to_numpy(), 6.0 * np.linspace(0.5, 2, 5), rtol=1e-14)


def test_kernel_grad_matrix_argument():
    f64()
    x = ti.Vector.field(2, dtype=ti.f64, shape=3, needs_grad=True)
    y = ti.Vector.field(2, dtype=ti.f64, shape=3, needs_grad=True)

    @ti.kernel
    def f(A: ti.types.matrix(2, 2, ti.f64)):
        for i in x:
            y[i] = A @ x[i]

    A = ti.Matrix([[1.0, 2.0], [3.0, 4.0]])
    f(A)
    y.grad.from_numpy(np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]))
    f.grad(A)
    np.testing.assert_allclose(x.grad.to_numpy(), [[1.0, 2.0], [3.0, 4.0], [4.0, 6.0]], rtol=1e-14)


# -- Tape ----------------------------------------------------------------------------------------------

def _two_kernel_program():
    x = ti.field(ti.f64, shape=8, needs_grad=True)
    y = ti.field(ti.f64, shape=8, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def step1():
        for i in x:
            y[i] = ti.sin(x[i]) * 2

    @ti.kernel
    def step2():
        for i in y:
            loss[None] += y[i] ** 2

    x.from_numpy(np.linspace(-1, 1, 8))
    return x, y, loss, step1, step2


def test_tape_sets_loss_to_zero_seeds_and_runs_in_reverse():
    f64()
    x, y, loss, step1, step2 = _two_kernel_program()
    loss[None] = 123.0  # the tape resets it
    x.grad.fill(7.0)  # and clears stale gradients
    with ti.ad.Tape(loss=loss):
        step1()
        step2()
    xs = np.linspace(-1, 1, 8)
    assert loss[None] == pytest.approx(np.sum((2 * np.sin(xs)) ** 2), rel=1e-14)
    assert loss.grad[None] == 1.0
    np.testing.assert_allclose(x.grad.to_numpy(), 8 * np.sin(xs) * np.cos(xs), rtol=1e-13)
    # step1's store consumed y.grad after passing it on (taichi 1.7.4 leaves it zero too)
    np.testing.assert_array_equal(y.grad.to_numpy(), np.zeros(8))


def test_tape_clear_gradients_false_keeps_them():
    f64()
    x, y, loss, step1, step2 = _two_kernel_program()
    with ti.ad.Tape(loss=loss):
        step1()
        step2()
    g1 = x.grad.to_numpy()
    with ti.ad.Tape(loss=loss, clear_gradients=False):
        step1()
        step2()
    # x.grad keeps the first gradient and gets a second one; y.grad was consumed by step1's store in the
    # first Tape, so it does not seed the second pass twice (taichi 1.7.4 gives 2x as well)
    np.testing.assert_allclose(x.grad.to_numpy(), 2 * g1, rtol=1e-13)
    with ti.ad.Tape(loss=loss):
        step1()
        step2()
    np.testing.assert_allclose(x.grad.to_numpy(), g1, rtol=1e-13)


def test_old_spelling_ti_tape():
    f64()
    x, y, loss, step1, step2 = _two_kernel_program()
    assert hasattr(ti, "Tape"), "ti.Tape is missing at top level"
    with ti.Tape(loss):
        step1()
        step2()
    xs = np.linspace(-1, 1, 8)
    np.testing.assert_allclose(x.grad.to_numpy(), 8 * np.sin(xs) * np.cos(xs), rtol=1e-13)


def test_tape_records_same_kernel_with_different_args_and_matches_fd():
    """A time-stepped loop x[t+1] = f(x[t]) recorded on the tape: gradients through all steps."""
    f64()
    T, n = 30, 5
    x = ti.field(ti.f64, shape=(T + 1, n), needs_grad=True)
    k = ti.field(ti.f64, shape=(), needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def step(t: ti.i32):
        for i in range(n):
            x[t + 1, i] = x[t, i] + 0.05 * ti.sin(k[None] * x[t, (i + 1) % n])

    @ti.kernel
    def compute_loss():
        for i in range(n):
            loss[None] += x[T, i] ** 2

    x0 = np.random.default_rng(0).standard_normal(n)

    def run():
        xs = np.zeros((T + 1, n))
        xs[0] = x0
        x.from_numpy(xs)
        for t in range(T):
            step(t)
        compute_loss()

    k[None] = 1.3
    with ti.ad.Tape(loss=loss):
        run()
    g = k.grad[None]

    def loss_of_k():
        loss[None] = 0
        run()
        return loss[None]

    fd = fd_grad(loss_of_k, k)
    assert rel_err(g, fd) < 1e-7


def test_no_grad_kernel_runs_forward_and_is_skipped_backward():
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)
    z = ti.field(ti.f64, shape=4, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def square():
        for i in x:
            y[i] = x[i] * x[i]

    @ti.ad.no_grad
    @ti.kernel
    def detached():
        for i in x:
            z[i] = 1000.0 * x[i]  # its adjoint would add 1000 to x.grad if it ran

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i] + z[i]

    x.from_numpy(np.arange(4.0))
    with ti.ad.Tape(loss=loss):
        square()
        detached()
        total()
    assert loss[None] == pytest.approx(14.0 + 6000.0)  # it ran forward
    np.testing.assert_array_equal(z.grad.to_numpy(), np.ones(4))
    np.testing.assert_allclose(x.grad.to_numpy(), 2 * np.arange(4.0))  # and not backward


def test_no_grad_kernel_grad_attribute_is_not_called():
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.ad.no_grad
    @ti.kernel
    def log_it():
        for i in x:
            loss[None] += 0.0 * x[i]

    @ti.kernel
    def total():
        for i in x:
            loss[None] += 3 * x[i]

    called = []
    orig = log_it.grad
    log_it.grad = lambda *a: called.append(a) or orig(*a)
    with ti.ad.Tape(loss=loss):
        log_it()
        total()
    assert called == []
    np.testing.assert_array_equal(x.grad.to_numpy(), np.full(4, 3.0))


def test_grad_replaced_and_grad_for_custom_gradient():
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    log = []

    @ti.kernel
    def square(scale: ti.f64):
        for i in x:
            y[i] = scale * x[i] * x[i]

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i]

    @ti.ad.grad_replaced
    def forward(scale):
        log.append(("fwd", scale))
        square(scale)

    @ti.ad.grad_for(forward)
    def backward(scale):
        log.append(("bwd", scale))
        for i in range(4):
            x.grad[i] += 100.0 * y.grad[i]  # a deliberately different "gradient"

    x.from_numpy(np.arange(4.0))
    with ti.ad.Tape(loss=loss):
        forward(2.0)
        total()
    assert log == [("fwd", 2.0), ("bwd", 2.0)]
    np.testing.assert_array_equal(x.grad.to_numpy(), np.full(4, 100.0))
    assert loss[None] == pytest.approx(2 * (0 + 1 + 4 + 9))


def test_grad_for_requires_grad_replaced():
    def plain(s):
        pass

    with pytest.raises(SimgradError, match="grad_replaced"):
        ti.ad.grad_for(plain)(lambda s: None)


def test_tape_rejects_non_scalar_loss_and_loss_without_gradient():
    f64()
    vec = ti.field(ti.f64, shape=3, needs_grad=True)
    nograd = ti.field(ti.f64, shape=())
    vloss = ti.Vector.field(2, dtype=ti.f64, shape=(), needs_grad=True)
    with pytest.raises(SimgradError, match="0-d scalar field"):
        ti.ad.Tape(loss=vec)
    with pytest.raises(SimgradError, match="0-d scalar field"):
        ti.ad.Tape(loss=vloss)
    with pytest.raises(SimgradError, match="needs_grad=True"):
        ti.ad.Tape(loss=nograd)
    with pytest.raises(SimgradError, match="scalar field"):
        ti.ad.Tape(loss=1.0)


def test_tape_grad_twice_raises():
    f64()
    x, y, loss, step1, step2 = _two_kernel_program()
    tape = ti.ad.Tape(loss=loss)
    with tape:
        step1()
        step2()
    with pytest.raises(SimgradError, match="already"):
        tape.grad()


def test_tape_exception_inside_does_not_run_backward():
    f64()
    x, y, loss, step1, step2 = _two_kernel_program()
    with pytest.raises(RuntimeError, match="boom"):
        with ti.ad.Tape(loss=loss):
            step1()
            raise RuntimeError("boom")
    assert not np.any(x.grad.to_numpy())
    # and recording stopped: a later plain call is not recorded anywhere
    step1()
    with ti.ad.Tape(loss=loss):
        step2()
    assert not np.any(x.grad.to_numpy())
    assert np.any(y.grad.to_numpy())


def test_clear_all_gradients_zeroes_large_interleaved_gradients_and_keeps_primals():
    """Large gradients are zeroed by a compiled kernel (one pass over the cells), small ones by numpy;
    either way every gradient entry is 0 afterwards and the primals placed beside them are untouched."""
    import simgrad.lang.tape as tape

    x = ti.Vector.field(2, ti.f32)
    m = ti.Matrix.field(2, 2, ti.f32)
    s = ti.field(ti.f32, shape=7, needs_grad=True)
    ti.root.dense(ti.i, 300).dense(ti.j, 250).place(x, m)
    ti.root.lazy_grad()
    assert 300 * 250 >= tape._NATIVE_ZEROING
    rng = np.random.default_rng(0)
    prim = [rng.random((300, 250, 2)), rng.random((300, 250, 2, 2)), rng.random(7)]
    for f, p in zip((x, m, s), prim):
        f.from_numpy(p.astype(np.float32))
        f.grad.from_numpy(p.astype(np.float32) + 1)
    ti.ad.clear_all_gradients()
    for f, p in zip((x, m, s), prim):
        assert not f.grad.to_numpy().any()
        np.testing.assert_array_equal(f.to_numpy(), p.astype(np.float32))
