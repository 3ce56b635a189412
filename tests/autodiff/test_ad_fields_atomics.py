"""Gradient fields (needs_grad, lazy_grad, SNode placement, 0-d, vector/matrix), their Python access and
clearing, and the adjoints of atomics (+=, atomic_add/sub, atomic_min/max subgradient)."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import f64, rel_err

import simgrad as ti
from simgrad.errors import GradientError
from simgrad.testing import check_grads


def test_zero_d_fields():
    f64()
    a = ti.field(ti.f64, shape=(), needs_grad=True)
    b = ti.field(ti.f64, shape=(), needs_grad=True)
    out = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        out[None] = ti.sin(a[None]) * b[None] ** 3

    a[None], b[None] = 0.7, 1.3
    f()
    out.grad[None] = 1.0
    f.grad()
    assert rel_err(a.grad[None], np.cos(0.7) * 1.3 ** 3) < 1e-14
    assert rel_err(b.grad[None], np.sin(0.7) * 3 * 1.3 ** 2) < 1e-14
    check_grads(f, [a, b], [out], rtol=1e-7)


def test_vector_and_matrix_fields_grad_python_access():
    f64()
    v = ti.Vector.field(3, dtype=ti.f64, shape=4, needs_grad=True)
    M = ti.Matrix.field(2, 3, dtype=ti.f64, shape=4, needs_grad=True)
    out = ti.Vector.field(2, dtype=ti.f64, shape=4, needs_grad=True)

    @ti.kernel
    def f():
        for i in v:
            out[i] = M[i] @ (v[i] * v[i])

    rng = np.random.default_rng(0)
    vs, Ms = rng.standard_normal((4, 3)), rng.standard_normal((4, 2, 3))
    v.from_numpy(vs)
    M.from_numpy(Ms)
    f()
    assert v.grad.to_numpy().shape == (4, 3) and M.grad.to_numpy().shape == (4, 2, 3)
    out.grad.fill(1.0)  # fill of a vector gradient field
    np.testing.assert_array_equal(out.grad.to_numpy(), np.ones((4, 2)))
    f.grad()
    expect_M = np.broadcast_to((vs * vs)[:, None, :], (4, 2, 3))
    np.testing.assert_allclose(M.grad.to_numpy(), expect_M, rtol=1e-14)
    np.testing.assert_allclose(v.grad.to_numpy(), 2 * vs * Ms.sum(axis=1), rtol=1e-13)
    # element access of gradient fields from Python
    g = v.grad[2]
    np.testing.assert_allclose([g[0], g[1], g[2]], 2 * vs[2] * Ms[2].sum(axis=0), rtol=1e-13)
    assert M.grad[1][0, 2] == pytest.approx(vs[1, 2] ** 2, rel=1e-14)
    v.grad[2] = [0.0, 0.0, 5.0]
    assert v.grad.to_numpy()[2].tolist() == [0.0, 0.0, 5.0]
    check_grads(f, [v, M], [out], rtol=1e-6)


def test_root_dense_place_with_lazy_grad():
    f64()
    x = ti.field(ti.f64)
    y = ti.field(ti.f64)
    z = ti.field(ti.f64)
    ti.root.dense(ti.i, 16).place(x, y)
    ti.root.dense(ti.ij, (4, 4)).place(z)
    ti.root.lazy_grad()

    @ti.kernel
    def f():
        for i in x:
            y[i] = x[i] ** 2
            z[i // 4, i % 4] = ti.exp(x[i]) * y[i]

    xs = np.linspace(-1, 1, 16)
    x.from_numpy(xs)
    f()
    assert x.grad is not None and z.grad.shape == (4, 4)
    y.grad.fill(0)
    z.grad.fill(1)
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), np.exp(xs) * (xs ** 2 + 2 * xs), rtol=1e-13)
    check_grads(f, [x], [y, z], rtol=1e-6)


def test_needs_grad_false_field_gets_no_gradient_but_passes_values():
    f64()
    c = ti.field(ti.f64, shape=8)  # no gradient
    x = ti.field(ti.f64, shape=8, needs_grad=True)
    y = ti.field(ti.f64, shape=8, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = c[i] * x[i] + c[i] ** 2

    c.from_numpy(np.arange(8.0))
    x.from_numpy(np.ones(8))
    f()
    y.grad.fill(1)
    f.grad()
    np.testing.assert_array_equal(x.grad.to_numpy(), np.arange(8.0))
    assert c.grad is None or getattr(c.grad, "snode", None) is None


def test_grad_accumulates_across_calls_and_clear_all_gradients():
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    v = ti.Vector.field(2, dtype=ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = 3 * x[i] + v[i].sum()

    f()
    y.grad.fill(1)
    f.grad()
    # the store's adjoint consumes y.grad (as taichi does): a second launch adds nothing more
    np.testing.assert_array_equal(y.grad.to_numpy(), np.zeros(4))
    y.grad.fill(1)
    f.grad()
    np.testing.assert_array_equal(x.grad.to_numpy(), np.full(4, 6.0))  # adjoints accumulate
    ti.ad.clear_all_gradients()
    for g in (x.grad, v.grad, y.grad):
        assert not np.any(g.to_numpy())
    y.grad.fill(2)
    f.grad()
    np.testing.assert_array_equal(v.grad.to_numpy(), np.full((4, 2), 2.0))
    ti.clear_all_gradients()  # the old top-level spelling
    assert not np.any(v.grad.to_numpy()) and not np.any(y.grad.to_numpy())
    assert ti.clear_all_gradients is ti.ad.clear_all_gradients


def test_clear_all_gradients_on_lazy_grad_tree():
    f64()
    x = ti.field(ti.f64)
    ti.root.dense(ti.i, 5).place(x)
    ti.root.lazy_grad()
    x.grad.fill(3.0)
    ti.ad.clear_all_gradients()
    np.testing.assert_array_equal(x.grad.to_numpy(), np.zeros(5))


# -- atomics -------------------------------------------------------------------------------------

def test_augmented_add_sub_and_atomic_functions():
    f64()
    n = 1000
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    acc = ti.field(ti.f64, shape=4, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            acc[0] += x[i] * x[i]
            acc[1] -= ti.sin(x[i])
            ti.atomic_add(acc[2], 2 * x[i])
            ti.atomic_sub(acc[3], x[i] ** 3)

    xs = np.random.default_rng(1).uniform(-1, 1, n)
    x.from_numpy(xs)

    def forward():
        acc.fill(0)
        f()

    forward()
    np.testing.assert_allclose(acc.to_numpy(), [np.sum(xs ** 2), -np.sum(np.sin(xs)), 2 * np.sum(xs),
                                                -np.sum(xs ** 3)], rtol=1e-12)
    w = np.array([0.5, 2.0, -1.0, 3.0])
    acc.grad.from_numpy(w)
    f.grad()
    expect = w[0] * 2 * xs - w[1] * np.cos(xs) + w[2] * 2 - w[3] * 3 * xs ** 2
    assert rel_err(x.grad.to_numpy(), expect, floor=1e-9) < 1e-12
    check_grads(forward, [x], [acc], rtol=1e-6)


def test_local_accumulation_augmented_assign():
    f64()
    x = ti.field(ti.f64, shape=(8, 5), needs_grad=True)
    y = ti.field(ti.f64, shape=8, needs_grad=True)

    @ti.kernel
    def f():
        for i in range(8):
            s = 0.0
            for j in range(5):
                s += x[i, j] * s + x[i, j]
                s -= 0.1 * x[i, j] ** 2
            y[i] = s

    x.from_numpy(np.random.default_rng(2).uniform(-1, 1, (8, 5)))
    check_grads(f, [x], [y], rtol=1e-6)


def test_scatter_add_to_computed_indices():
    """Atomic adds into computed indices (a histogram-like scatter): each source gets the gradient of
    the cell it landed in."""
    f64()
    n, m = 500, 7
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    idx = ti.field(ti.i32, shape=n)
    grid = ti.field(ti.f64, shape=m, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            grid[idx[i]] += ti.exp(x[i])

    rng = np.random.default_rng(3)
    xs = rng.uniform(-1, 1, n)
    ids = rng.integers(0, m, n).astype(np.int32)
    x.from_numpy(xs)
    idx.from_numpy(ids)
    f()
    w = rng.standard_normal(m)
    grid.grad.from_numpy(w)
    f.grad()
    assert rel_err(x.grad.to_numpy(), w[ids] * np.exp(xs)) < 1e-13


@pytest.mark.parametrize("kind", ["max", "min"])
def test_atomic_min_max_subgradient_flows_to_the_winner(kind):
    """ti.atomic_max/min: the gradient of the final value flows to the operand equal to it."""
    f64()
    n = 2000
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    m = ti.field(ti.f64, shape=(), needs_grad=True)

    if kind == "max":
        @ti.kernel
        def f():
            for i in x:
                ti.atomic_max(m[None], x[i] * x[i])
    else:
        @ti.kernel
        def f():
            for i in x:
                ti.atomic_min(m[None], ti.exp(x[i]))

    xs = np.random.default_rng(4).uniform(-3, 3, n)
    x.from_numpy(xs)
    m[None] = -1e30 if kind == "max" else 1e30
    f()
    k = int(np.argmax(xs ** 2)) if kind == "max" else int(np.argmin(xs))
    expect_val = xs[k] ** 2 if kind == "max" else np.exp(xs[k])
    assert m[None] == pytest.approx(expect_val, rel=1e-15)
    m.grad[None] = 2.0
    f.grad()
    g = x.grad.to_numpy()
    expect = np.zeros(n)
    expect[k] = 2.0 * (2 * xs[k] if kind == "max" else np.exp(xs[k]))
    np.testing.assert_allclose(g, expect, rtol=1e-14, atol=0)


def test_atomic_max_on_vector_field_components():
    f64()
    x = ti.Vector.field(2, dtype=ti.f64, shape=50, needs_grad=True)
    hi = ti.Vector.field(2, dtype=ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            ti.atomic_max(hi[None][0], x[i][0])
            ti.atomic_max(hi[None][1], x[i][0] + x[i][1])

    xs = np.random.default_rng(5).standard_normal((50, 2))
    x.from_numpy(xs)
    hi[None] = [-1e30, -1e30]
    f()
    hi.grad[None] = [1.0, 10.0]
    f.grad()
    expect = np.zeros((50, 2))
    expect[np.argmax(xs[:, 0]), 0] += 1.0
    k = np.argmax(xs.sum(axis=1))
    expect[k] += 10.0
    np.testing.assert_array_equal(x.grad.to_numpy(), expect)


def test_atomic_add_on_local_and_atomic_max_on_local_raises():
    f64()
    n = 8
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            acc = 0.0
            for k in range(4):
                ti.atomic_add(acc, x[i] * k)
                acc *= 0.5
            y[i] = acc

    @ti.kernel
    def g():
        for i in x:
            acc = 0.0
            for k in range(4):
                ti.atomic_max(acc, x[i] * k)
            y[i] = acc

    x.from_numpy(np.linspace(0.3, 1.1, n))
    f()
    y.grad.fill(1)
    f.grad()
    # acc = sum_k x k 0.5^(4-k) = x (0.5^3 + 2 * 0.5^2 + 3 * 0.5)
    np.testing.assert_allclose(x.grad.to_numpy(), np.full(n, 0.125 + 0.5 + 1.5), rtol=1e-14)
    g()
    with pytest.raises(GradientError, match="atomic_max on a local variable"):
        g.grad()


def test_atomic_max_gradient_does_not_leak_to_the_overwritten_initial_value():
    f64()
    x0 = ti.field(ti.f64, shape=(), needs_grad=True)
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    m = ti.field(ti.f64, shape=(), needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.kernel
    def init():
        m[None] = x0[None]

    @ti.kernel
    def maximum():
        for i in x:
            ti.atomic_max(m[None], x[i])

    @ti.kernel
    def compute_loss():
        loss[None] = m[None]

    x0[None] = -5.0
    x.from_numpy(np.array([1.0, 3.0, 2.0, 0.0]))
    with ti.ad.Tape(loss=loss):
        init()
        maximum()
        compute_loss()
    np.testing.assert_array_equal(x.grad.to_numpy(), [0.0, 1.0, 0.0, 0.0])
    assert x0.grad[None] == 0.0  # x0 was overwritten by the maximum: d loss / d x0 = 0
