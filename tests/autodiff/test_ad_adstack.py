"""The per-thread adstack: bounded, an overflow is a clear error naming the fix, and
ti.init(ad_stack_size=N) raises the bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

import simgrad as ti
from simgrad.errors import SimgradError


def _program(n_threads=4):
    x = ti.field(ti.f64, shape=n_threads, needs_grad=True)
    y = ti.field(ti.f64, shape=n_threads, needs_grad=True)

    @ti.kernel
    def f(m: ti.i32):
        for i in x:
            s = x[i]
            for _k in range(m):
                s = ti.sin(s) * 0.5 + 0.25  # each iteration pushes s for the adjoint of sin
            y[i] = s

    x.from_numpy(np.linspace(0.1, 0.4, n_threads))
    return x, y, f


def _expected_grad(x0, m):
    s, d = x0, 1.0
    for _ in range(m):
        d *= 0.5 * math.cos(s)
        s = math.sin(s) * 0.5 + 0.25
    return d


def test_default_capacity_overflow_names_ad_stack_size():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x, y, f = _program()
    f(10 ** 6)  # forward needs no tape
    y.grad.fill(1)
    with pytest.raises(SimgradError, match="ad_stack_size") as info:
        f.grad(10 ** 6)
    msg = str(info.value)
    assert "kernel f" in msg and "tape" in msg
    assert "s = ti.sin(s)" in msg  # located at the statement in the loop that pushes
    # a short loop still works afterwards on the same program
    x.grad.fill(0)
    f(10)
    y.grad.fill(1)  # the failed launch may have consumed part of it (a store's adjoint zeroes y.grad)
    f.grad(10)
    assert x.grad[0] == pytest.approx(_expected_grad(0.1, 10), rel=1e-12)


def test_large_ad_stack_size_works():
    m = 10 ** 6
    # entries per iteration: s (for sin) and sin(s) (for the product), plus a few outside the loop
    ti.init(arch=ti.cpu, default_fp=ti.f64, ad_stack_size=2 * m + 64)
    x, y, f = _program(2)
    f(m)
    y.grad.fill(1)
    f.grad(m)
    # d/dx contracts quickly (|0.5 cos| < 1); compare after a few iterations where it is still > 0
    assert x.grad[0] == pytest.approx(_expected_grad(0.1, m), rel=1e-9, abs=1e-300)
    m2 = 40
    x.grad.fill(0)
    f(m2)
    f.grad(m2)
    assert x.grad[1] == pytest.approx(_expected_grad(0.4, m2), rel=1e-12)


def test_tape_size_is_inferred_from_static_bounds_beyond_the_default():
    """A static 200000-iteration loop needs more than the default capacity; inference sizes it exactly."""
    ti.init(arch=ti.cpu, default_fp=ti.f64, ad_stack_size=16)
    x = ti.field(ti.f64, shape=2, needs_grad=True)
    y = ti.field(ti.f64, shape=2, needs_grad=True)

    @ti.kernel
    def run():
        for i in x:
            s = x[i]
            for _k in range(200_000):
                s = s + 1e-4 * ti.sin(s)
            y[i] = s

    x.from_numpy(np.array([0.3, 0.7]))
    run()
    y.grad.fill(1.0)
    run.grad()
    # d/dx of the fixed-point iteration by finite differences
    h = 1e-6
    for i, x0 in enumerate([0.3, 0.7]):
        def f(v):
            for _ in range(200_000):
                v = v + 1e-4 * math.sin(v)
            return v
        fd = (f(x0 + h) - f(x0 - h)) / (2 * h)
        assert abs(fd - 1.0) > 0.1  # the derivative is far from trivial
        assert abs(x.grad[i] - fd) <= 1e-6 + 1e-5 * abs(fd)


def test_pairwise_energy_with_a_carried_accumulator_where_taichi_crashes():
    """The potential_forces pattern: per i, `e += pair(i, j)` over every j inside an `if`. taichi 1.7.4
    (CPU, default ad_stack_size) segfaults in this kernel's Tape for n >= 64 (checked 2026-11-23 with the
    same kernel; n = 4 works there). We size the tape from the static bound; forces against finite
    differences of the energy."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    n = 64
    x = ti.Vector.field(2, ti.f64, shape=n, needs_grad=True)
    U = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def energy():
        for i in range(n):
            e = 0.0
            for j in range(n):
                if i != j:
                    r = x[i] - x[j]
                    e += 0.5 / ti.sqrt(r.dot(r) + 0.01)
            U[None] += e

    p = np.random.default_rng(5).random((n, 2))
    x.from_numpy(p)
    with ti.ad.Tape(loss=U):
        energy()
    got = x.grad.to_numpy()

    def u_of(q):
        r = q[:, None, :] - q[None, :, :]
        inv = 0.5 / np.sqrt((r ** 2).sum(-1) + 0.01)
        np.fill_diagonal(inv, 0)
        return inv.sum()

    assert abs(U[None] - u_of(p)) <= 1e-10 * u_of(p)
    h = 1e-6
    for k in (0, 17, 63):
        for c in (0, 1):
            a, b = p.copy(), p.copy()
            a[k, c] += h
            b[k, c] -= h
            fd = (u_of(a) - u_of(b)) / (2 * h)
            assert abs(got[k, c] - fd) <= 1e-6 * max(1.0, abs(fd))


def test_each_threads_tape_starts_on_a_cache_line_of_its_own():
    """Threads push and pop their tapes every iteration: two small tapes on one cache line ping-pong between the
    cores (diffmpm3d's p2g.grad, 2.9 -> 6.1 ms a launch, depending on where numpy placed the tape). The regions
    start on 64-byte lines, a whole number of lines each, and the gradient is the same as at one thread."""
    from simgrad.runtime.abi import CTX_TAPE, CTX_TAPE_CAP, CTX_TAPE_SERIAL

    grads = []
    for threads in (3, 1):
        ti.init(arch=ti.cpu, default_fp=ti.f64, cpu_max_num_threads=threads)
        x, y, f = _program(64)
        f(3)
        y.grad.fill(1)
        f.grad(3)
        buf = f._instance_for((3,), "grad").launcher.buf
        assert buf[CTX_TAPE] % 64 == 0 and buf[CTX_TAPE_CAP] % 8 == 0 and buf[CTX_TAPE_SERIAL] % 64 == 0
        grads.append(x.grad.to_numpy())
    np.testing.assert_array_equal(grads[0], grads[1])
    assert grads[0][0] == pytest.approx(_expected_grad(0.1, 3), rel=1e-12)
