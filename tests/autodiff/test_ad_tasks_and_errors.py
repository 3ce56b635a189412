"""Kernels with several tasks (top-level loops and serial code between them), global accesses inside
nested control flow, integer loop-carried state, and the errors of the reverse transform."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import f64, rel_err

import simgrad as ti
from simgrad.errors import GradientError
from simgrad.testing import check_grads


def test_two_parallel_loops_in_one_kernel_run_adjoints_in_reverse_task_order():
    """Loop 2 reads what loop 1 wrote: its adjoint must have finished before loop 1's adjoint."""
    f64()
    n = 50_000
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    z = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = ti.sin(x[i])
        for i in y:
            z[i] = y[i] * y[(i + 1) % n]

    xs = np.random.default_rng(0).uniform(-2, 2, n)
    x.from_numpy(xs)
    f()
    z.grad.fill(1)
    f.grad()
    s = np.sin(xs)
    gy = np.roll(s, -1) + np.roll(s, 1)
    # 1e-11: the kernel's vectorised sin/cos are codegen/vecmath.py's (within 1 ulp, not numpy's bits), and gy
    # cancels where neighbours' sines do (1.04e-12 seen)
    assert rel_err(x.grad.to_numpy(), gy * np.cos(xs), floor=1e-9) < 1e-11


def test_serial_code_between_loops_and_top_level_control_flow():
    f64()
    n = 20
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    a = ti.field(ti.f64, shape=(), needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    z = ti.field(ti.f64, shape=n, needs_grad=True)
    total = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        s = a[None] * 2.0
        if s > 1.0:
            s = ti.sqrt(s)
        k = 0
        while k < 3:
            s = s * a[None] + 0.1
            k += 1
        for i in x:
            y[i] = x[i] * s
        t = y[3] * y[5] + s  # top-level serial code after the loop: runs after it
        total[None] = t
        for i in x:
            z[i] = total[None] * x[i] ** 2

    x.from_numpy(np.linspace(-1, 1, n))
    for av in (0.8, 0.3):
        a[None] = av
        check_grads(f, [x, a], [y, z, total], rtol=1e-6, atol=1e-10)


def test_global_loads_and_stores_inside_nested_control_flow():
    f64()
    n, m = 8, 6
    x = ti.field(ti.f64, shape=(n, m), needs_grad=True)
    y = ti.field(ti.f64, shape=(n, m), needs_grad=True)
    flags = ti.field(ti.i32, shape=(n, m))

    @ti.kernel
    def f():
        for i in range(n):
            s = 0.0
            for j in range(m):
                v = x[i, (j * 3) % m]  # index computed in the loop: replayed from the tape
                if flags[i, j] == 1:
                    s = s + ti.exp(v)
                    y[i, j] = s * v
                elif flags[i, j] == 2:
                    k = 0
                    while k < j:
                        s = s * 0.9 + v * 0.01
                        k += 1
                    y[i, j] = s
                else:
                    y[i, j] = -v
                    s -= v * v

    rng = np.random.default_rng(1)
    x.from_numpy(rng.uniform(-1, 1, (n, m)))
    flags.from_numpy(rng.integers(0, 3, (n, m)).astype(np.int32))
    check_grads(f, [x], [y], rtol=1e-6, atol=1e-10, directions=3)


def test_integer_loop_carried_state_mixed_with_floats():
    f64()
    n = 16
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            s = x[i]
            c = 1
            for k in range(12):
                c = (c * 3 + k) % 7
                s = s * 0.8 + c * 0.1 * ti.sin(s) + ti.cast(c, ti.f64) * x[i] * 0.01
            y[i] = s

    x.from_numpy(np.linspace(-2, 2, n))
    check_grads(f, [x], [y], rtol=1e-6)


def test_mixed_precision_f32_fields_f64_locals():
    ti.init(arch=ti.cpu, default_fp=ti.f32)
    x = ti.field(ti.f32, shape=16, needs_grad=True)
    y = ti.field(ti.f64, shape=16, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            v = ti.cast(x[i], ti.f64)
            acc = ti.cast(0.0, ti.f64)
            for k in range(4):
                acc = acc * v + ti.cast(ti.sin(x[i] * k), ti.f64)
            y[i] = acc

    xs = np.linspace(-1, 1, 16).astype(np.float32)
    x.from_numpy(xs)
    f()
    y.grad.fill(1)
    f.grad()
    check_grads(f, [x], [y], eps=1e-3, rtol=5e-3, atol=1e-4)


def test_kernel_with_return_value_is_differentiable():
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)

    @ti.kernel
    def f() -> ti.f64:
        for i in x:
            y[i] = x[i] ** 3
        return y[1]

    x.from_numpy(np.arange(4.0))
    assert f() == 1.0
    y.grad.fill(1)
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), 3 * np.arange(4.0) ** 2)


def test_grouped_struct_for_on_vector_field():
    f64()
    u = ti.Vector.field(2, dtype=ti.f64, shape=(5, 4), needs_grad=True)
    out = ti.field(ti.f64, shape=(5, 4), needs_grad=True)

    @ti.kernel
    def f():
        for I in ti.grouped(u):
            out[I] = u[I].norm() * (I[0] + 1) + ti.atan2(u[I][1], u[I][0])

    u.from_numpy(np.random.default_rng(2).uniform(0.5, 1.5, (5, 4, 2)))
    check_grads(f, [u], [out], rtol=1e-6)


def test_random_in_differentiated_kernel_raises():
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = x[i] * ti.random()

    f()
    with pytest.raises(GradientError, match="random"):
        f.grad()


def test_using_atomic_return_value_raises():
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    acc = ti.field(ti.f64, shape=(), needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            old = ti.atomic_add(acc[None], x[i])
            y[i] = old * 2

    f()
    with pytest.raises(GradientError, match="atomic"):
        f.grad()


def test_parallel_loop_with_runtime_bounds_and_loop_carried_local_vector():
    """Bounds from a kernel argument and a field read at kernel level; a local vector carried through a
    serial loop (v = A v + 0.1 sin v)."""
    f64()
    n = 12
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    cnt = ti.field(ti.i32, shape=())
    A = ti.Matrix.field(2, 2, ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f(lo: ti.i32):
        m = cnt[None]
        for i in range(lo, m):
            v = ti.Vector([x[i], 1.0])
            for _k in range(5):
                v = A[None] @ v + ti.sin(v) * 0.1
            y[i] = v[0] * v[1]

    cnt[None] = 9
    A[None] = [[0.9, 0.2], [-0.3, 0.8]]
    x.from_numpy(np.linspace(-1, 1, n))
    f(2)
    y.grad.fill(1)
    f.grad(2)
    g = x.grad.to_numpy()
    assert np.all(g[:2] == 0) and np.all(g[9:] == 0) and np.all(g[2:9] != 0)
    check_grads(lambda: f(2), [x, A], [y], rtol=1e-6, atol=1e-10)


def test_matrix_field_component_stores():
    f64()
    n = 6
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    C = ti.Matrix.field(2, 2, ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            C[i][0, 1] = x[i] * 2
            C[i][1, 0] = ti.sin(x[i])
            C[i][0, 0] = 1.0
            C[i][1, 1] = x[i] ** 2

    xs = np.linspace(-1, 1, n)
    x.from_numpy(xs)
    f()
    C.grad.from_numpy(np.tile(np.array([[1.0, 2.0], [3.0, 4.0]]), (n, 1, 1)))
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), 4 + 3 * np.cos(xs) + 8 * xs, rtol=1e-14)


def test_runtime_index_into_local_vector_in_serial_loop():
    """v[k] with a run-time k, read and written in a serial loop (Taichi's dynamic indexing)."""
    f64()
    n = 12
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            v = ti.Vector([x[i], x[i] * 2, 3.0])
            s = 0.0
            for k in range(3):
                s += v[k] * (k + 1)
                v[k] = s * x[i]
            y[i] = s + v[i % 3]

    x.from_numpy(np.linspace(-1, 1, n) + 0.01)
    check_grads(f, [x], [y], rtol=1e-6)
