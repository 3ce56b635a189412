"""Reverse mode through control flow: parallel and serial loops (reversed, runtime bounds, loop-carried
locals), nested loops, if/elif/else, while, break/continue (structurized), ti.func, ti.static."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ad_util import f64, rel_err

import simgrad as ti
from simgrad.ir.ops import Op
from simgrad.testing import check_grads


def _grad_ir(kernel):
    (inst,) = kernel._caches["grad"].values()
    return inst.ir


def test_parallel_loop_large_range_adjoint_stays_parallel():
    f64()
    n = 100_000
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = ti.sin(x[i]) * x[i]
            loss[None] += x[i] * x[i]

    xs = np.random.default_rng(0).uniform(-2, 2, n)
    x.from_numpy(xs)
    f()
    w = np.random.default_rng(1).standard_normal(n)
    y.grad.from_numpy(w)
    loss.grad[None] = 0.5
    f.grad()
    expect = w * (np.cos(xs) * xs + np.sin(xs)) + xs
    assert rel_err(x.grad.to_numpy(), expect, floor=1e-9) < 1e-10
    loops = [s for s in _grad_ir(f).body.stmts if s.op is Op.RANGE_FOR]
    assert loops and all(s.attrs.get("parallel") for s in loops), "the adjoint of a parallel loop is parallel"


def test_top_level_statements_shared_by_parallel_iterations():
    """A top-level value used by 10^5 parallel iterations: its adjoint sums every iteration's share."""
    f64()
    n = 100_000
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    a = ti.field(ti.f64, shape=(), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    z = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        s = ti.exp(a[None])  # top-level, before the loop
        for i in range(n):
            y[i] = x[i] * s
        z[None] = s * s + x[3]  # top-level, after the loop

    xs = np.random.default_rng(2).standard_normal(n)
    x.from_numpy(xs)
    a[None] = 0.3
    f()
    w = np.random.default_rng(3).standard_normal(n)
    y.grad.from_numpy(w)
    z.grad[None] = 2.0
    f.grad()
    s = math.exp(0.3)
    expect_a = (np.sum(w * xs) * s + 2.0 * 2 * s * s)
    assert rel_err(a.grad[None], expect_a) < 1e-10
    gx = w * s
    gx[3] += 2.0
    assert rel_err(x.grad.to_numpy(), gx, floor=1e-9) < 1e-12


def test_serial_inner_loop_runtime_bounds_is_reversed():
    """Horner-like recurrences depend on the order: a wrongly ordered adjoint fails."""
    f64()
    n = 16
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    c = ti.field(ti.f64, shape=20, needs_grad=True)
    lo = ti.field(ti.i32, shape=n)
    hi = ti.field(ti.i32, shape=n)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f(shift: ti.i32):
        for i in x:
            acc = 0.0
            for k in range(lo[i], hi[i] + shift):
                acc = acc * x[i] + c[k] * ti.cos(acc)
            y[i] = acc

    rng = np.random.default_rng(4)
    x.from_numpy(rng.uniform(-1, 1, n))
    c.from_numpy(rng.uniform(-1, 1, 20))
    lo.from_numpy(rng.integers(0, 5, n).astype(np.int32))
    hi.from_numpy(rng.integers(5, 18, n).astype(np.int32))
    check_grads(lambda: f(1), [x, c], [y], rtol=1e-6, atol=1e-10, directions=3)
    # compare the forward value with a Python replay
    f(1)
    xs, cs, los, his = x.to_numpy(), c.to_numpy(), lo.to_numpy(), hi.to_numpy()
    for i in range(n):
        acc = 0.0
        for k in range(los[i], his[i] + 1):
            acc = acc * xs[i] + cs[k] * math.cos(acc)
        assert abs(y[i] - acc) < 1e-12


def test_loop_carried_local_polynomial_of_sines():
    """s = s * x + sin(k * x) over k: the gradient is checked against the closed-form derivative."""
    f64()
    n, m = 32, 12
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f(steps: ti.i32):
        for i in x:
            s = 1.0
            for k in range(steps):
                s = s * x[i] + ti.sin(k * x[i])
            y[i] = s

    xs = np.linspace(-1.2, 1.2, n)
    x.from_numpy(xs)
    f(m)
    y.grad.fill(1)
    f.grad(m)
    s, ds = np.ones(n), np.zeros(n)
    for k in range(m):
        s, ds = s * xs + np.sin(k * xs), ds * xs + s + k * np.cos(k * xs)
    np.testing.assert_allclose(y.to_numpy(), s, rtol=1e-13)
    assert rel_err(x.grad.to_numpy(), ds, floor=1e-9) < 1e-11
    check_grads(lambda: f(m), [x], [y], rtol=1e-6)


def test_nested_serial_loops_with_mutable_locals():
    f64()
    n = 8
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    w = ti.field(ti.f64, shape=(4, 5), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            t = x[i]
            for j in range(4):
                u = 0.0
                for k in range(j + 1, 5):
                    u += w[j, k] * ti.tanh(t + u)
                t = t * 0.5 + u * x[i]
            y[i] = t

    rng = np.random.default_rng(5)
    x.from_numpy(rng.uniform(-1, 1, n))
    w.from_numpy(rng.uniform(-1, 1, (4, 5)))
    check_grads(f, [x, w], [y], rtol=1e-6, atol=1e-10, directions=3)


def test_parallel_ndrange_and_struct_for_2d():
    f64()
    a = ti.field(ti.f64, shape=(6, 7), needs_grad=True)
    b = ti.field(ti.f64, shape=(6, 7), needs_grad=True)
    c = ti.field(ti.f64, shape=(6, 7), needs_grad=True)

    @ti.kernel
    def f():
        for i, j in a:
            b[i, j] = a[i, j] * a[(i + 1) % 6, j]
        for i, j in ti.ndrange((1, 5), 7):
            c[i, j] = ti.sin(a[i - 1, j]) + a[i + 1, (j + 2) % 7] ** 2

    a.from_numpy(np.random.default_rng(6).uniform(-1, 1, (6, 7)))
    check_grads(f, [a], [b, c], rtol=1e-6, atol=1e-10)


def test_if_elif_else_inside_serial_loop_condition_recorded_per_iteration():
    f64()
    n = 16
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            s = x[i]
            for k in range(10):
                if s > 1.0:
                    s = s * 0.3 + ti.sin(s)
                elif s < -0.5:
                    s = -s * s + 0.1 * k
                else:
                    s = s * 1.9 + 0.2
            y[i] = s

    def replay(v):
        s = v
        for k in range(10):
            if s > 1.0:
                s = s * 0.3 + math.sin(s)
            elif s < -0.5:
                s = -s * s + 0.1 * k
            else:
                s = s * 1.9 + 0.2
        return s

    xs = np.linspace(-1.3, 1.7, n) + 0.0123
    x.from_numpy(xs)
    f()
    np.testing.assert_allclose(y.to_numpy(), [replay(v) for v in xs], rtol=1e-13)
    y.grad.fill(1)
    f.grad()
    fd = np.array([(replay(v + 1e-7) - replay(v - 1e-7)) / 2e-7 for v in xs])
    assert rel_err(x.grad.to_numpy(), fd, floor=1e-6) < 1e-5
    check_grads(f, [x], [y], rtol=1e-6)


def test_if_at_top_of_parallel_body_and_branch_only_adjoint():
    """Gradients flow only through the branch that ran; the other side gets exactly zero."""
    f64()
    n = 32
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    p = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            v = 0.0
            if x[i] > 0:
                v = p[i] * x[i]
            else:
                v = ti.exp(x[i])
            y[i] = v

    xs = np.linspace(-1, 1, n) + 0.01
    ps = np.random.default_rng(0).uniform(1, 2, n)
    x.from_numpy(xs)
    p.from_numpy(ps)
    f()
    y.grad.fill(1)
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), np.where(xs > 0, ps, np.exp(xs)), rtol=1e-14)
    np.testing.assert_array_equal(p.grad.to_numpy(), np.where(xs > 0, xs, 0.0))


def test_while_loop_newton_sqrt():
    """Newton iterations with a data-dependent trip count: d sqrt(a)/da = 1/(2 sqrt(a))."""
    f64()
    n = 16
    a = ti.field(ti.f64, shape=n, needs_grad=True)
    r = ti.field(ti.f64, shape=n, needs_grad=True)
    iters = ti.field(ti.i32, shape=n)

    @ti.kernel
    def f():
        for i in a:
            x = a[i] + 1.0
            k = 0
            while ti.abs(x * x - a[i]) > 1e-14 * a[i] and k < 100:
                x = 0.5 * (x + a[i] / x)
                k += 1
            r[i] = x
            iters[i] = k

    av = np.linspace(0.5, 50.0, n)
    a.from_numpy(av)
    f()
    np.testing.assert_allclose(r.to_numpy(), np.sqrt(av), rtol=1e-13)
    assert iters.to_numpy().max() > 3
    r.grad.fill(1)
    f.grad()
    assert rel_err(a.grad.to_numpy(), 0.5 / np.sqrt(av)) < 1e-9


def test_while_loop_with_runtime_trip_count_is_exact_power():
    f64()
    n = 10
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    e = ti.field(ti.i32, shape=n)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            s = 1.0
            k = 0
            while k < e[i]:
                s *= x[i]
                k += 1
            y[i] = s

    xs = np.linspace(-1.5, 1.5, n) + 0.05
    es = np.arange(n, dtype=np.int32)
    x.from_numpy(xs)
    e.from_numpy(es)
    f()
    y.grad.fill(1)
    f.grad()
    expect = np.where(es > 0, es * xs ** np.maximum(es - 1, 0), 0.0)
    assert rel_err(x.grad.to_numpy(), expect, floor=1e-9) < 1e-12


def test_continue_and_break_in_serial_loop_inside_ifs():
    f64()
    n = 24
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            s = x[i]
            for k in range(30):
                if k % 3 == 0:
                    continue
                s = s * 0.9 + 0.3 * ti.sin(s) + 0.02 * k
                if s > 0.8:
                    if k > 6:
                        break
                    s -= 0.5
                elif s < -2.0:
                    continue
                s += 0.05 * x[i]
            y[i] = s

    def replay(v):
        s = v
        for k in range(30):
            if k % 3 == 0:
                continue
            s = s * 0.9 + 0.3 * math.sin(s) + 0.02 * k
            if s > 0.8:
                if k > 6:
                    break
                s -= 0.5
            elif s < -2.0:
                continue
            s += 0.05 * v
        return s

    xs = np.linspace(-2.5, 2.5, n) + 0.0137
    x.from_numpy(xs)
    f()
    np.testing.assert_allclose(y.to_numpy(), [replay(v) for v in xs], rtol=1e-12)
    y.grad.fill(1)
    f.grad()
    fd = np.array([(replay(v + 1e-7) - replay(v - 1e-7)) / 2e-7 for v in xs])
    assert rel_err(x.grad.to_numpy(), fd, floor=1e-5) < 1e-5


def test_break_inside_while_true_and_nested_loops():
    f64()
    n = 12
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            s = x[i]
            k = 0
            while True:
                k += 1
                for j in range(3):
                    if j == k % 3:
                        continue
                    s = s + 0.1 * ti.cos(s + j)
                if s > 2.0 or k >= 15:
                    break
            y[i] = s * k

    def replay(v):
        s, k = v, 0
        while True:
            k += 1
            for j in range(3):
                if j == k % 3:
                    continue
                s = s + 0.1 * math.cos(s + j)
            if s > 2.0 or k >= 15:
                break
        return s * k

    xs = np.linspace(-1.0, 1.9, n) + 0.003
    x.from_numpy(xs)
    f()
    np.testing.assert_allclose(y.to_numpy(), [replay(v) for v in xs], rtol=1e-12)
    y.grad.fill(1)
    f.grad()
    fd = np.array([(replay(v + 1e-7) - replay(v - 1e-7)) / 2e-7 for v in xs])
    assert rel_err(x.grad.to_numpy(), fd, floor=1e-5) < 1e-5


@ti.func
def _smooth(v, k):
    r = v
    if v > 0:
        r = ti.sqrt(v * v + k)
    return r * 2.0


@ti.func
def _rotate(v, angle):
    c, s = ti.cos(angle), ti.sin(angle)
    return ti.Vector([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def test_ti_func_calls_with_returns():
    f64()
    n = 16
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    ang = ti.field(ti.f64, shape=(), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            v = _rotate(ti.Vector([x[i], 1.0]), ang[None] * i)
            acc = 0.0
            for k in range(3):
                acc += _smooth(v[0] + k * 0.1, 0.5)
            y[i] = acc + v[1]

    x.from_numpy(np.linspace(-1, 1, n) + 0.01)
    ang[None] = 0.2
    check_grads(f, [x, ang], [y], rtol=1e-6, atol=1e-10)


def test_static_loops_unrolled():
    f64()
    n = 8
    xs = [ti.field(ti.f64, shape=n, needs_grad=True) for _ in range(3)]
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(n):
            acc = 0.0
            for k in ti.static(range(3)):
                acc = acc * xs[k][i] + ti.sin(xs[k][i] * (k + 1))
            for fld in ti.static(xs):
                acc += fld[i] ** 2
            y[i] = acc

    rng = np.random.default_rng(9)
    for fld in xs:
        fld.from_numpy(rng.uniform(-1, 1, n))
    check_grads(f, xs, [y], rtol=1e-6)


def test_serialized_top_level_loop():
    """ti.loop_config(serialize=True): a prefix sum, whose adjoint is a reversed suffix sum."""
    f64()
    n = 20
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        acc = 0.0
        ti.loop_config(serialize=True)
        for i in range(n):
            acc = acc * 0.9 + x[i]
            y[i] = acc

    x.from_numpy(np.random.default_rng(1).standard_normal(n))
    check_grads(f, [x], [y], rtol=1e-6)
    w = np.random.default_rng(2).standard_normal(n)
    f()
    x.grad.fill(0)
    y.grad.from_numpy(w)
    f.grad()
    # d y_j / d x_i = 0.9^(j - i) for j >= i
    J = np.tril(0.9 ** np.subtract.outer(np.arange(n), np.arange(n)))
    assert rel_err(x.grad.to_numpy(), J.T @ w, floor=1e-9) < 1e-12


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_mixed_constructs_f32_and_f64(t):
    ti.init(arch=ti.cpu, default_fp=t)
    n = 64
    x = ti.field(t, shape=n, needs_grad=True)
    y = ti.field(t, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            s = x[i]
            k = 0
            while k < i % 5:
                if s > 0:
                    s = ti.sqrt(s + 1.0)
                else:
                    s = s * 0.5
                k += 1
            y[None] += s * s

    x.from_numpy((np.linspace(-1, 1, n) + 0.01).astype(t.np))

    def forward():
        y.fill(0)
        f()

    if t is ti.f64:
        check_grads(forward, [x], [y], rtol=1e-6)
    else:
        check_grads(forward, [x], [y], eps=1e-2, rtol=1e-2, atol=1e-3)


def test_break_skips_statements_before_it_in_later_iterations():
    """After `break`, no later iteration may replay the statements that precede the break (regression:
    the adjoint replayed `s = s * 2` in every remaining iteration). The loop is long (10^6) with an
    early exit: the adjoint replays only the iterations that ran, so the tape stays small."""
    f64()
    n = 6
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f(m: ti.i32):
        for i in x:
            s = x[i]
            for k in range(m):
                s = s * 2.0 + 0.01 * k
                if s > 3.0:
                    break
                s += x[i]
            y[i] = s

    def replay(v):
        s = v
        for k in range(10 ** 6):
            s = s * 2.0 + 0.01 * k
            if s > 3.0:
                break
            s += v
        return s

    xs = np.linspace(0.13, 2.5, n)
    x.from_numpy(xs)
    f(10 ** 6)
    np.testing.assert_allclose(y.to_numpy(), [replay(v) for v in xs], rtol=1e-14)
    y.grad.fill(1)
    f.grad(10 ** 6)
    fd = np.array([(replay(v + 1e-7) - replay(v - 1e-7)) / 2e-7 for v in xs])
    assert rel_err(x.grad.to_numpy(), fd, floor=1e-6) < 1e-6


def test_break_in_serialized_top_level_loop():
    f64()
    n = 40
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        acc = 0.0
        ti.loop_config(serialize=True)
        for i in range(n):
            acc = acc * 0.5 + x[i] * x[i]
            if acc > 2.0:
                break
        y[None] = acc

    xs = np.linspace(0.1, 1.5, n)
    x.from_numpy(xs)

    def replay(v):
        acc = 0.0
        for i in range(n):
            acc = acc * 0.5 + v[i] * v[i]
            if acc > 2.0:
                break
        return acc

    f()
    assert abs(y[None] - replay(xs)) < 1e-14
    check_grads(f, [x], [y], rtol=1e-6)


def test_continue_in_parallel_loop_flag_is_per_iteration():
    """`continue` in the parallel loop: the adjoint's jump flag lives inside the loop body (one per
    iteration), not at kernel level where all threads would share it."""
    f64()
    n = 200_000
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            if x[i] < 0:
                continue
            y[i] = ti.sin(x[i]) * x[i]

    xs = np.random.default_rng(0).uniform(-1, 1, n)
    x.from_numpy(xs)
    f()
    y.grad.fill(1)
    f.grad()
    expect = np.where(xs < 0, 0.0, np.cos(xs) * xs + np.sin(xs))
    np.testing.assert_array_equal(x.grad.to_numpy() == 0, xs < 0)
    assert rel_err(x.grad.to_numpy(), expect, floor=1e-9) < 1e-12
    top = _grad_ir(f).body.stmts
    assert not any(s.op is Op.ALLOCA for s in top), "a kernel-level local would be shared by all threads"


def test_while_nested_in_while_with_breaks():
    f64()
    n = 10
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            s = x[i]
            a = 0
            while a < 4:
                b = 0
                while True:
                    s = s * 0.95 + 0.05 * ti.cos(s * (a + 1))
                    b += 1
                    if b > a:
                        break
                if s > 1.2:
                    break
                a += 1
            y[i] = s

    def replay(v):
        s, a = v, 0
        while a < 4:
            b = 0
            while True:
                s = s * 0.95 + 0.05 * math.cos(s * (a + 1))
                b += 1
                if b > a:
                    break
            if s > 1.2:
                break
            a += 1
        return s

    xs = np.linspace(-1, 2, n) + 0.011
    x.from_numpy(xs)
    f()
    np.testing.assert_allclose(y.to_numpy(), [replay(v) for v in xs], rtol=1e-13)
    y.grad.fill(1)
    f.grad()
    fd = np.array([(replay(v + 1e-7) - replay(v - 1e-7)) / 2e-7 for v in xs])
    assert rel_err(x.grad.to_numpy(), fd, floor=1e-6) < 1e-6
