"""simgrad.testing.check_program_grads: a whole program's Tape gradients against finite differences, and
on disagreement the first launch whose adjoint is wrong, found by replaying the launches one by one.

How these tests were checked to be able to fail (each by editing simgrad/testing.py, then reverting):
`_check_launch` always agreeing failed the two tests that expect a unit to be named; the adjoint side taken as
`<K^T u, v>` (without `- u`) or the difference side as `<u, K v>` (without `- v`) failed those and the
Python-scope-write test (a kernel was blamed); the program's central difference with the wrong sign failed
the tests of correct programs."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import f64

import simgrad as ti
from simgrad.errors import GradientError
from simgrad.testing import check_program_grads

N, T = 4, 3


def test_kernel_grad_maps_gradients_by_the_transpose():
    """What the launch check relies on: with every gradient set to u, kernel.grad leaves K^T u over the whole
    state (a store consumes the gradient of what it overwrote; an accumulation passes it on)."""
    f64()
    x = ti.field(ti.f64, 3, needs_grad=True)
    y = ti.field(ti.f64, 3, needs_grad=True)

    @ti.kernel
    def store():
        for i in x:
            y[i] = x[i] ** 2

    @ti.kernel
    def accumulate():
        for i in x:
            y[i] += x[i]

    xs, ux, uy = np.array([1.0, 2.0, 3.0]), np.array([1.0, -1.0, 0.5]), np.array([0.5, 0.25, 2.0])
    for kernel, want_x, want_y in ((store, ux + 2 * xs * uy, 0 * uy), (accumulate, ux + uy, uy)):
        x.from_numpy(xs)
        y.from_numpy(np.array([10.0, 20.0, 30.0]))
        kernel()
        x.grad.from_numpy(ux)
        y.grad.from_numpy(uy)
        kernel.grad()
        np.testing.assert_array_equal(x.grad.to_numpy(), want_x)
        np.testing.assert_array_equal(y.grad.to_numpy(), want_y)


def _def_line(name: str) -> int:
    with open(__file__) as fh:
        return next(k + 1 for k, line in enumerate(fh) if line.lstrip().startswith(f"def {name}("))


def _spring_chain():
    """A 1-D chain of unit masses and springs, explicit Euler over time-indexed state x[t, i], v[t, i]."""
    f64()
    x = ti.field(ti.f64, (T + 1, N), needs_grad=True)
    v = ti.field(ti.f64, (T + 1, N), needs_grad=True)
    k = ti.field(ti.f64, (), needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)

    @ti.kernel
    def step(t: ti.i32):
        for i in range(N):
            f = 0.0
            if i > 0:
                f -= k[None] * (x[t - 1, i] - x[t - 1, i - 1] - 1.0)
            if i < N - 1:
                f += k[None] * (x[t - 1, i + 1] - x[t - 1, i] - 1.0)
            v[t, i] = v[t - 1, i] + 0.1 * f
            x[t, i] = x[t - 1, i] + 0.1 * v[t, i]

    @ti.kernel
    def energy():
        for i in range(N):
            loss[None] += (x[T, i] - 1.5 * i) ** 2 + 0.5 * v[T, i] ** 2

    rng = np.random.default_rng(1)
    x0 = np.zeros((T + 1, N))
    x0[0] = np.arange(N) * 1.2 + 0.1 * rng.standard_normal(N)
    x.from_numpy(x0)
    v.from_numpy(np.zeros((T + 1, N)))
    k[None] = 3.0

    def run():
        for t in range(1, T + 1):
            step(t)
        energy()

    return x, v, k, loss, step, run


def test_correct_multi_kernel_program_passes_and_memory_is_restored():
    x, v, k, loss, _, run = _spring_chain()
    with ti.ad.Tape(loss=loss):
        run()
    want = [f.to_numpy() for f in (x, v, k, loss, x.grad, v.grad, k.grad)]
    report = check_program_grads(run, loss, [x, v, k])
    assert len(report) == 3 and report.launches == T + 1
    assert report.names == ["step"] * T + ["energy"]
    for ad, fd in report:
        assert abs(ad) > 1e-3 and abs(ad - fd) <= 1e-5 * abs(fd)
    for f, w in zip((x, v, k, loss, x.grad, v.grad, k.grad), want):
        np.testing.assert_array_equal(f.to_numpy(), w)


def test_wrong_kernel_adjoint_names_the_kernel_and_launch():
    x, v, k, loss, step, run = _spring_chain()
    true_grad = step.grad

    def broken(t):  # the adjoint of the second launch is skipped
        if t != 2:
            true_grad(t)

    step.grad = broken
    with pytest.raises(GradientError) as e:
        check_program_grads(run, loss, [x, v, k])
    msg = str(e.value)
    assert f"launch #1 of {T + 1}, kernel step ({__file__}:{_def_line('step')}), arguments (2)" in msg, msg
    assert e.value.loc is not None and e.value.loc.line == _def_line("step")


def _squares(factor: float):
    f64()
    x = ti.field(ti.f64, 5, needs_grad=True)
    y = ti.field(ti.f64, 5, needs_grad=True)
    z = ti.field(ti.f64, 5, needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)
    x.from_numpy(np.linspace(-1.0, 1.3, 5))

    @ti.kernel
    def shift():
        for i in x:
            y[i] = x[i] + 0.5

    @ti.kernel
    def square():
        for i in y:
            z[i] = y[i] ** 2

    @ti.kernel
    def square_adjoint(c: ti.f64):
        for i in y:
            y.grad[i] += c * y[i] * z.grad[i]
            z.grad[i] = 0.0  # z was overwritten: its gradient is consumed

    @ti.ad.grad_replaced
    def squared():
        square()

    @ti.ad.grad_for(squared)
    def squared_grad():
        square_adjoint(factor)

    @ti.kernel
    def total():
        for i in z:
            loss[None] += ti.sin(z[i])

    def run():
        shift()
        squared()
        total()

    return x, loss, run


def test_correct_custom_gradient_passes():
    x, loss, run = _squares(2.0)
    check_program_grads(run, loss, [x])


def test_wrong_custom_gradient_is_blamed_on_its_unit():
    """The issue's "Show": the custom gradient drops the factor 2 of d(y^2)/dy."""
    x, loss, run = _squares(1.0)
    with pytest.raises(GradientError) as e:
        check_program_grads(run, loss, [x])
    msg = str(e.value)
    unit = (f"launch #1 of 3, @ti.ad.grad_replaced unit _squares.<locals>.squared ({__file__}:"
            f"{_def_line('squared')}) with gradient _squares.<locals>.squared_grad ({__file__}:"
            f"{_def_line('squared_grad')}), arguments ()")
    assert unit in msg, msg
    assert "y.grad (AD" in msg  # the gradient that reaches y is the wrong one


def test_python_scope_write_between_launches_is_a_whole_program_disagreement():
    f64()
    x = ti.field(ti.f64, 4, needs_grad=True)
    y = ti.field(ti.f64, 4, needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)
    x.from_numpy(np.array([0.3, -0.7, 1.1, 0.2]))

    @ti.kernel
    def sines():
        for i in x:
            y[i] = ti.sin(x[i])

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i] ** 2

    def run():
        sines()
        y.from_numpy(2.0 * y.to_numpy())  # invisible to the Tape
        total()

    with pytest.raises(GradientError, match="each of the 2 recorded launches with an adjoint") as e:
        check_program_grads(run, loss, [x])
    assert "Python-scope write" in str(e.value)
    run_ok = lambda: (sines(), total())  # noqa: E731  the same program without the write passes
    check_program_grads(run_ok, loss, [x])
