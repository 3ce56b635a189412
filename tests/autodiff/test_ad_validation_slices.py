"""Run-time access checks (Tape(validation=True) and debug mode) watch only the slices of the leading axis
that a launch read when kernel arguments pick them: a time-stepped program that reads v[t - 1] and later
writes v[t] obeys the rules (taichi differentiates it; the unmodified mass_spring_simple is such a program),
while overwriting the slice that was read is still refused with a located error."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import f64, fd_grad

import simgrad as ti
from simgrad.errors import GradientError

T, N = 6, 4


def _program():
    x = ti.field(ti.f64, shape=(T, N), needs_grad=True)
    v = ti.field(ti.f64, shape=(T, N), needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def advance(t: ti.i32):
        for i in range(N):
            v[t, i] = v[t - 1, i] * 0.9 + ti.sin(x[t - 1, i])

    @ti.kernel
    def move(t: ti.i32):
        for i in range(N):
            x[t, i] = x[t - 1, i] + 0.1 * v[t, i]

    @ti.kernel
    def total():
        for i in range(N):
            loss[None] += x[T - 1, i] ** 2

    x.from_numpy(np.random.default_rng(1).standard_normal((T, N)))
    return x, v, loss, advance, move, total


@pytest.mark.parametrize("mode", ["validation", "debug"])
def test_reading_t_minus_1_then_writing_t_is_allowed(mode):
    ti.init(arch=ti.cpu, default_fp=ti.f64, debug=(mode == "debug"))
    x, v, loss, advance, move, total = _program()

    def run():
        for t in range(1, T):
            advance(t)
            move(t)
        total()

    with ti.ad.Tape(loss=loss, validation=(mode == "validation")):
        run()
    got = x.grad.to_numpy()[0]

    def value():
        loss[None] = 0
        run()
        return loss[None]

    want = fd_grad(value, x)[0]
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)


def test_overwriting_the_slice_that_was_read_is_refused():
    f64()
    x, v, loss, advance, move, total = _program()

    @ti.kernel
    def clobber(t: ti.i32):
        for i in range(N):
            v[t, i] = 5.0

    with pytest.raises(GradientError, match="field 'v' was modified after kernel advance") as info:
        with ti.ad.Tape(loss=loss, validation=True):
            advance(2)  # reads v[1]
            clobber(1)  # overwrites v[1]
            total()
    assert "v[t - 1, i]" in str(info.value)
