"""A global store overwrites its element, so its adjoint consumes that element's gradient: it passes it on to
the stored value and then zeroes it. Without that, a gradient that reached an element flows a second time into
whatever wrote the element earlier (clear-then-accumulate gave 9 instead of 5). Each case is checked against
central finite differences of the whole Tape in float64; the `.grad` left on an overwritten output is 0, as
taichi 1.7.4 leaves it."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import f64, fd_grad

import simgrad as ti

N = 5


def _fields():
    x = ti.field(ti.f64, N, needs_grad=True)
    y = ti.field(ti.f64, N, needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)
    x.from_numpy(np.linspace(-0.8, 1.1, N))
    return x, y, loss


def _check(x, loss, run, validation=False):
    with ti.ad.Tape(loss=loss, validation=validation):
        run()
    got = x.grad.to_numpy()

    def value():
        loss[None] = 0
        run()
        return loss[None]

    want = fd_grad(value, x)
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9)
    return got


@pytest.mark.parametrize("validation", [False, True])
def test_clear_then_accumulate_across_kernels(validation):
    f64()
    x, y, loss = _fields()

    @ti.kernel
    def clear():
        for i in x:
            y[i] = 0

    @ti.kernel
    def acc():
        for i in x:
            y[i] += 5 * x[i]

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i]

    def run():
        clear()
        acc()
        total()

    got = _check(x, loss, run, validation)
    np.testing.assert_allclose(got, np.full(N, 5.0))
    np.testing.assert_array_equal(y.grad.to_numpy(), np.zeros(N))  # consumed by clear's store


def test_set_then_overwrite_then_accumulate():
    f64()
    x, y, loss = _fields()

    @ti.kernel
    def set_y():
        for i in x:
            y[i] = 2 * x[i] ** 2  # overwritten below: contributes nothing

    @ti.kernel
    def overwrite():
        for i in x:
            y[i] = ti.sin(x[i])

    @ti.kernel
    def acc():
        for i in x:
            y[i] += 5 * x[i]

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i] ** 2

    def run():
        set_y()
        overwrite()
        acc()
        total()

    _check(x, loss, run)


def test_kernel_grad_alone_zeroes_the_overwritten_output():
    f64()
    x, y, _ = _fields()

    @ti.kernel
    def f():
        for i in x:
            y[i] = 3 * x[i]

    f()
    y.grad.fill(1)
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), np.full(N, 3.0))
    np.testing.assert_array_equal(y.grad.to_numpy(), np.zeros(N))


def test_store_in_a_serial_inner_loop_counts_once():
    f64()
    x, y, loss = _fields()

    @ti.kernel
    def f():
        for i in x:
            for j in range(3):
                y[i] = x[i] * (j + 1)  # only the last store survives: y = 3 x

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i]

    def run():
        f()
        total()

    got = _check(x, loss, run)
    np.testing.assert_allclose(got, np.full(N, 3.0))


def test_store_then_atomic_add_in_one_kernel():
    f64()
    x, y, loss = _fields()

    @ti.kernel
    def before():
        for i in x:
            y[i] = 7 * x[i]  # overwritten by f

    @ti.kernel
    def f():
        for i in x:
            y[i] = 2 * x[i]
            y[i] += x[i] ** 2

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i]

    def run():
        before()
        f()
        total()

    xs = x.to_numpy()
    got = _check(x, loss, run)
    np.testing.assert_allclose(got, 2 + 2 * xs)


def test_store_inside_if_overwrites_only_where_taken():
    f64()
    x, y, loss = _fields()

    @ti.kernel
    def first():
        for i in x:
            y[i] = x[i]

    @ti.kernel
    def maybe():
        for i in x:
            if x[i] > 0:
                y[i] = 3 * x[i]

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i]

    def run():
        first()
        maybe()
        total()

    xs = x.to_numpy()
    got = _check(x, loss, run)
    np.testing.assert_allclose(got, np.where(xs > 0, 3.0, 1.0))


def test_vector_field_store_consumes_each_component():
    f64()
    x, _, loss = _fields()
    v = ti.Vector.field(2, ti.f64, N, needs_grad=True)

    @ti.kernel
    def first():
        for i in x:
            v[i] = ti.Vector([x[i], 2 * x[i]])

    @ti.kernel
    def second():
        for i in x:
            v[i] = ti.Vector([3 * x[i], x[i] ** 3])

    @ti.kernel
    def total():
        for i in v:
            loss[None] += v[i][0] + v[i][1]

    def run():
        first()
        second()
        total()

    xs = x.to_numpy()
    got = _check(x, loss, run)
    np.testing.assert_allclose(got, 3 + 3 * xs ** 2)
    np.testing.assert_array_equal(v.grad.to_numpy(), np.zeros((N, 2)))


def test_intermediate_field_written_and_read_in_one_kernel():
    """A finite-element pattern (taichi's fem99): one loop stores F[i], a later loop of the same kernel reads it
    into the energy. d U / d pos matches finite differences; F.grad is consumed by the store (0, as taichi)."""
    f64()
    pos, _, U = _fields()
    F = ti.field(ti.f64, N, needs_grad=True)

    @ti.kernel
    def energy():
        for i in range(N):
            F[i] = pos[i] * pos[(i + 1) % N] + 1.0
        for i in range(N):
            U[None] += ti.log(F[i] ** 2 + 1.0)

    _check(pos, U, energy)
    np.testing.assert_array_equal(F.grad.to_numpy(), np.zeros(N))


def test_intermediate_field_read_by_a_later_kernel_only():
    """F written outside the Tape and only read inside it: its gradient is filled and left for the user."""
    f64()
    x, _, loss = _fields()
    F = ti.field(ti.f64, N, needs_grad=True)

    @ti.kernel
    def make():
        for i in x:
            F[i] = x[i] * 2

    @ti.kernel
    def total():
        for i in F:
            loss[None] += F[i] ** 2

    make()
    with ti.ad.Tape(loss=loss):
        total()
    np.testing.assert_allclose(F.grad.to_numpy(), 2 * F.to_numpy())
