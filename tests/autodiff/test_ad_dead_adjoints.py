"""Adjoints of values that reach no write of a gradient field are not computed (reverse.py `_reaching`),
and what remains of the NaN-through-a-zero-adjoint class (docs/autodiff_nan.md)."""

from __future__ import annotations

import numpy as np
from ad_util import f64

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


def _grad_ops(kernel) -> set:
    (inst,) = kernel._caches["grad"].values()
    return {s.op for s in walk(inst.ir.body)}


def test_dead_value_that_overflows_gives_no_nan():
    """Issue 21: `v` overflows to inf in a loop and is never used for the loss; its adjoint chain used to
    multiply a zero adjoint by an infinite derivative (0 * inf = NaN in x.grad; taichi 1.7.4 gives NaN)."""
    f64()
    n = 4
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    x.fill(3.0)

    @ti.kernel
    def f():
        for i in range(n):
            v = x[i]
            for _k in range(10):
                v = v * v * v
            dead = ti.exp(ti.sin(v))  # noqa: F841
            loss[None] += x[i]

    with ti.ad.Tape(loss=loss):
        f()
    np.testing.assert_array_equal(x.grad.to_numpy(), [1.0] * n)
    assert Op.COS not in _grad_ops(f)  # nothing of the dead value's derivative chain was emitted


def test_nan_through_an_untaken_select_remains_and_its_workarounds():
    """JAX's "NaN through where" class: `select(x > 0, sqrt(x), 0)` at x <= 0 is live, its adjoint is a
    run-time zero and sqrt's derivative there is inf or NaN, so x.grad is NaN (taichi 1.7.4 gives the same,
    checked by hand). An `if`, or a select that also keeps sqrt's argument in its domain, gives 0."""
    f64()
    x = ti.field(ti.f64, shape=3, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)
    x.from_numpy(np.array([-1.0, 0.0, 4.0]))

    @ti.kernel
    def plain():
        for i in x:
            loss[None] += ti.select(x[i] > 0, ti.sqrt(x[i]), 0.0)

    @ti.kernel
    def double_select():
        for i in x:
            loss[None] += ti.select(x[i] > 0, ti.sqrt(ti.select(x[i] > 0, x[i], 1.0)), 0.0)

    @ti.kernel
    def branch():
        for i in x:
            r = 0.0
            if x[i] > 0:
                r = ti.sqrt(x[i])
            loss[None] += r

    got = {}
    for k in (plain, double_select, branch):
        with ti.ad.Tape(loss=loss):
            k()
        got[k] = x.grad.to_numpy()
    assert np.isnan(got[plain][:2]).all() and got[plain][2] == 0.25
    np.testing.assert_array_equal(got[double_select], [0.0, 0.0, 0.25])
    np.testing.assert_array_equal(got[branch], [0.0, 0.0, 0.25])
