"""The global data access rules: a violation is refused with the field, kernel and line, never a wrong
gradient."""

import numpy as np
import pytest

import simgrad as ti


def _fields():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    return x, y, loss


def test_compile_time_read_then_overwrite_is_refused_with_location():
    x, _, _ = _fields()

    @ti.kernel
    def double_in_place():
        for i in x:
            x[i] = x[i] * 2

    double_in_place()  # the forward kernel itself is fine
    with pytest.raises(ti.GradientError, match=r"(?s)test_ad_validation.py.*x\[i\] = x\[i\] \* 2.*"
                                               r"kernel double_in_place overwrites .*field 'x'"):
        double_in_place.grad()


def test_time_stepped_update_is_accepted():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, shape=(3, 4), needs_grad=True)

    @ti.kernel
    def step(t: ti.i32):
        for i in range(4):
            x[t + 1, i] = x[t, i] * 2

    step(0)
    x.grad.fill(0)
    x.grad[1, 2] = 1.0
    step.grad(0)
    assert x.grad[0, 2] == 2.0


def test_runtime_validation_names_the_field_kernel_and_line():
    x, y, loss = _fields()

    @ti.kernel
    def square():
        for i in x:
            y[i] = x[i] ** 2

    @ti.kernel
    def overwrite():
        for i in x:
            x[i] = 3.0

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i]

    x.fill(1)
    with pytest.raises(ti.GradientError, match=r"(?s)y\[i\] = x\[i\] \*\* 2.*field 'x' was modified after "
                                               r"kernel square read it"):
        with ti.ad.Tape(loss=loss, validation=True):
            square()
            overwrite()
            total()


def test_runtime_validation_passes_a_correct_program():
    x, y, loss = _fields()

    @ti.kernel
    def square():
        for i in x:
            y[i] = x[i] ** 2

    @ti.kernel
    def total():
        for i in y:
            loss[None] += y[i]

    x.from_numpy(np.arange(4.0))
    with ti.ad.Tape(loss=loss, validation=True):
        square()
        total()
    np.testing.assert_allclose(x.grad.to_numpy(), 2 * np.arange(4.0))
