"""Every derivative rule of autodiff/rules.py, element-wise against analytic derivatives and, through
simgrad.testing.check_grads, against central finite differences (f64 tight, a few in f32)."""

from __future__ import annotations

import numpy as np
import pytest
from ad_util import f64, rel_err

import simgrad as ti
from simgrad.errors import GradientError
from simgrad.testing import check_grads

N = 64

# name: (kernel function, numpy derivative, domain)
UNARY = {
    "neg": (lambda v: -v, lambda x: -np.ones_like(x), (-3.0, 3.0)),
    "sqrt": (lambda v: ti.sqrt(v), lambda x: 0.5 / np.sqrt(x), (0.1, 5.0)),
    "rsqrt": (lambda v: ti.rsqrt(v), lambda x: -0.5 * x ** -1.5, (0.1, 5.0)),
    "sin": (lambda v: ti.sin(v), np.cos, (-4.0, 4.0)),
    "cos": (lambda v: ti.cos(v), lambda x: -np.sin(x), (-4.0, 4.0)),
    "tan": (lambda v: ti.tan(v), lambda x: 1 / np.cos(x) ** 2, (-1.3, 1.3)),
    "asin": (lambda v: ti.asin(v), lambda x: 1 / np.sqrt(1 - x * x), (-0.95, 0.95)),
    "acos": (lambda v: ti.acos(v), lambda x: -1 / np.sqrt(1 - x * x), (-0.95, 0.95)),
    "exp": (lambda v: ti.exp(v), np.exp, (-3.0, 3.0)),
    "log": (lambda v: ti.log(v), lambda x: 1 / x, (0.05, 5.0)),
    "tanh": (lambda v: ti.tanh(v), lambda x: 1 - np.tanh(x) ** 2, (-3.0, 3.0)),
    "abs": (lambda v: ti.abs(v), np.sign, (-3.0, 3.0)),
    "square": (lambda v: v ** 2, lambda x: 2 * x, (-3.0, 3.0)),
    "cube": (lambda v: v ** 3, lambda x: 3 * x * x, (-3.0, 3.0)),
    "pow_neg_1_5": (lambda v: v ** -1.5, lambda x: -1.5 * x ** -2.5, (0.2, 4.0)),
    "pow_half": (lambda v: ti.pow(v, 0.5), lambda x: 0.5 / np.sqrt(x), (0.2, 4.0)),
    "reciprocal": (lambda v: 1 / v, lambda x: -1 / x ** 2, (0.2, 4.0)),
    "sin_of_square": (lambda v: ti.sin(v * v), lambda x: 2 * x * np.cos(x * x), (-2.0, 2.0)),
    "add_self": (lambda v: v + v, lambda x: 2 * np.ones_like(x), (-2.0, 2.0)),
    "mul_self": (lambda v: v * v, lambda x: 2 * x, (-2.0, 2.0)),
    "sub_const": (lambda v: 2.5 - v, lambda x: -np.ones_like(x), (-2.0, 2.0)),
    "div_const": (lambda v: v / 4.0, lambda x: 0.25 * np.ones_like(x), (-2.0, 2.0)),
    "python_abs": (lambda v: abs(v), np.sign, (-3.0, 3.0)),
}


def _unary_setup(fn, t, lo, hi, seed=1):
    x = ti.field(t, shape=N, needs_grad=True)
    y = ti.field(t, shape=N, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = fn(x[i])

    rng = np.random.default_rng(seed)
    xs = rng.uniform(lo, hi, N)
    x.from_numpy(xs.astype(t.np))
    return x, y, f, xs


@pytest.mark.parametrize("name", list(UNARY))
def test_unary_rule_f64_analytic_and_fd(name):
    f64()
    fn, d, (lo, hi) = UNARY[name]
    x, y, f, xs = _unary_setup(fn, ti.f64, lo, hi)
    f()
    w = np.random.default_rng(2).standard_normal(N)
    y.grad.from_numpy(w)
    f.grad()
    assert rel_err(x.grad.to_numpy(), w * d(xs), floor=1e-9) < 1e-12
    check_grads(f, [x], [y], rtol=1e-6, atol=1e-10)


@pytest.mark.parametrize("name", ["sqrt", "sin", "exp", "log", "tanh", "pow_neg_1_5", "atan"])
def test_unary_rule_f32(name):
    if name == "atan":
        fn, d, (lo, hi) = (lambda v: ti.atan2(v, 1.0), lambda x: 1 / (1 + x * x), (-3.0, 3.0))
    else:
        fn, d, (lo, hi) = UNARY[name]
    x, y, f, xs = _unary_setup(fn, ti.f32, lo, hi)
    f()
    y.grad.fill(1)
    f.grad()
    assert x.grad.dtype is ti.f32
    assert rel_err(x.grad.to_numpy(), d(xs.astype(np.float32).astype(np.float64)), floor=1e-6) < 2e-5
    check_grads(f, [x], [y], eps=1e-2, rtol=2e-2, atol=1e-4)


BINARY = {
    "add": (lambda a, b: a + b, lambda a, b: (np.ones_like(a), np.ones_like(b))),
    "sub": (lambda a, b: a - b, lambda a, b: (np.ones_like(a), -np.ones_like(b))),
    "mul": (lambda a, b: a * b, lambda a, b: (b, a)),
    "div": (lambda a, b: a / b, lambda a, b: (1 / b, -a / b ** 2)),
    "atan2": (lambda a, b: ti.atan2(a, b), lambda a, b: (b / (a * a + b * b), -a / (a * a + b * b))),
    "pow": (lambda a, b: a ** b, lambda a, b: (b * a ** (b - 1), a ** b * np.log(a))),
    "ti_pow": (lambda a, b: ti.pow(a, b), lambda a, b: (b * a ** (b - 1), a ** b * np.log(a))),
    "min": (lambda a, b: ti.min(a, b), lambda a, b: ((a < b) * 1.0, (a > b) * 1.0)),
    "max": (lambda a, b: ti.max(a, b), lambda a, b: ((a > b) * 1.0, (a < b) * 1.0)),
    "select": (lambda a, b: ti.select(a > b, a * a, 3 * b),
               lambda a, b: ((a > b) * 2 * a, (a <= b) * 3.0)),
    "mixed": (lambda a, b: ti.exp(a) * ti.sin(b) + ti.sqrt(a * a + b * b),
              lambda a, b: (np.exp(a) * np.sin(b) + a / np.hypot(a, b),
                            np.exp(a) * np.cos(b) + b / np.hypot(a, b))),
}


def _binary_setup(fn, t, seed=3):
    a = ti.field(t, shape=N, needs_grad=True)
    b = ti.field(t, shape=N, needs_grad=True)
    y = ti.field(t, shape=N, needs_grad=True)

    @ti.kernel
    def f():
        for i in a:
            y[i] = fn(a[i], b[i])

    rng = np.random.default_rng(seed)
    av = rng.uniform(0.3, 3.0, N)  # positive: pow is differentiable in its exponent
    bv = rng.uniform(0.5, 2.0, N) * rng.choice([-1.0, 1.0], N)  # away from 0: a / b stays well-conditioned
    a.from_numpy(av.astype(t.np))
    b.from_numpy(bv.astype(t.np))
    return a, b, y, f, av, bv


@pytest.mark.parametrize("name", list(BINARY))
def test_binary_rule_f64(name):
    f64()
    fn, d = BINARY[name]
    a, b, y, f, av, bv = _binary_setup(fn, ti.f64)
    f()
    w = np.random.default_rng(4).standard_normal(N)
    y.grad.from_numpy(w)
    f.grad()
    da, db = d(av, bv)
    assert rel_err(a.grad.to_numpy(), w * da, floor=1e-9) < 1e-11
    assert rel_err(b.grad.to_numpy(), w * db, floor=1e-9) < 1e-11
    check_grads(f, [a, b], [y], rtol=1e-6, atol=1e-10)


@pytest.mark.parametrize("name", ["mul", "div", "pow", "atan2", "mixed"])
def test_binary_rule_f32(name):
    fn, d = BINARY[name]
    a, b, y, f, av, bv = _binary_setup(fn, ti.f32)
    f()
    y.grad.fill(1)
    f.grad()
    da, db = d(av.astype(np.float32).astype(np.float64), bv.astype(np.float32).astype(np.float64))
    assert rel_err(a.grad.to_numpy(), da, floor=1e-4) < 1e-4
    assert rel_err(b.grad.to_numpy(), db, floor=1e-4) < 1e-4
    check_grads(f, [a, b], [y], eps=1e-2, rtol=2e-2, atol=1e-3)


def test_pow_with_runtime_exponent_argument():
    """x ** y with y a scalar kernel argument (not a constant): d/dx = y x^(y-1)."""
    f64()
    x = ti.field(ti.f64, shape=N, needs_grad=True)
    out = ti.field(ti.f64, shape=N, needs_grad=True)

    @ti.kernel
    def f(p: ti.f64):
        for i in x:
            out[i] = x[i] ** p

    xs = np.linspace(0.2, 3.0, N)
    x.from_numpy(xs)
    for p in (2.0, -1.5, 0.3):
        f(p)
        out.grad.fill(1)
        x.grad.fill(0)
        f.grad(p)
        assert rel_err(x.grad.to_numpy(), p * xs ** (p - 1)) < 1e-12
    check_grads(lambda: f(-1.5), [x], [out], rtol=1e-6)


def test_pow_exponent_gradient_is_zero_for_nonpositive_base():
    """d/dy x**y = x**y log x is taken as 0 where x <= 0 (log undefined): finite, no NaN."""
    f64()
    x = ti.field(ti.f64, shape=3, needs_grad=True)
    p = ti.field(ti.f64, shape=3, needs_grad=True)
    y = ti.field(ti.f64, shape=3, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = x[i] ** p[i]

    x.from_numpy(np.array([0.0, -2.0, 2.0]))
    p.from_numpy(np.array([2.0, 2.0, 2.0]))
    f()
    y.grad.fill(1)
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), [0.0, -4.0, 4.0], rtol=1e-14)
    np.testing.assert_allclose(p.grad.to_numpy(), [0.0, 0.0, 4 * np.log(2.0)], rtol=1e-14)


def test_min_max_ties_split_the_gradient_to_one_operand():
    """At a tie the whole gradient goes to one operand (the first), never to both or none."""
    f64()
    a = ti.field(ti.f64, shape=2, needs_grad=True)
    b = ti.field(ti.f64, shape=2, needs_grad=True)
    y = ti.field(ti.f64, shape=2, needs_grad=True)

    @ti.kernel
    def f():
        y[0] = ti.min(a[0], b[0])
        y[1] = ti.max(a[1], b[1])

    a.from_numpy(np.array([1.5, -0.5]))
    b.from_numpy(np.array([1.5, -0.5]))
    f()
    y.grad.from_numpy(np.array([2.0, 3.0]))
    f.grad()
    np.testing.assert_array_equal(a.grad.to_numpy() + b.grad.to_numpy(), [2.0, 3.0])
    np.testing.assert_array_equal(a.grad.to_numpy(), [2.0, 3.0])


def test_abs_gradient_at_zero_is_zero():
    f64()
    x = ti.field(ti.f64, shape=3, needs_grad=True)
    y = ti.field(ti.f64, shape=3, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = ti.abs(x[i])

    x.from_numpy(np.array([0.0, -1.0, 2.0]))
    f()
    y.grad.fill(1)
    f.grad()
    np.testing.assert_array_equal(x.grad.to_numpy(), [0.0, -1.0, 1.0])


def test_ternary_and_python_int_not_in_kernel_source():
    """`a if c else b`, `int(x)` and `not` written in the kernel (not through a helper)."""
    f64()
    a = ti.field(ti.f64, shape=N, needs_grad=True)
    b = ti.field(ti.f64, shape=N, needs_grad=True)
    y = ti.field(ti.f64, shape=N, needs_grad=True)
    z = ti.field(ti.f64, shape=N, needs_grad=True)

    @ti.kernel
    def f():
        for i in a:
            y[i] = a[i] * b[i] if a[i] < b[i] else a[i] - b[i]
            z[i] = int(a[i]) + (not (b[i] > 0.0))

    rng = np.random.default_rng(7)
    av, bv = rng.uniform(-2, 2, N), rng.uniform(-2, 2, N)
    a.from_numpy(av)
    b.from_numpy(bv)
    f()
    w = rng.standard_normal(N)
    y.grad.from_numpy(w)
    z.grad.fill(1)
    f.grad()
    np.testing.assert_allclose(a.grad.to_numpy(), w * np.where(av < bv, bv, 1.0), rtol=1e-14)
    np.testing.assert_allclose(b.grad.to_numpy(), w * np.where(av < bv, av, -1.0), rtol=1e-14)
    y.grad.fill(0)
    a.grad.fill(0)
    b.grad.fill(0)
    f.grad()  # z alone: int() and `not` carry no gradient
    np.testing.assert_array_equal(a.grad.to_numpy(), np.zeros(N))
    np.testing.assert_array_equal(b.grad.to_numpy(), np.zeros(N))
    check_grads(f, [a, b], [y, z], rtol=1e-6)


@pytest.mark.parametrize("src,dst", [(ti.f32, ti.f64), (ti.f64, ti.f32)], ids=["f32->f64", "f64->f32"])
def test_float_casts_carry_gradient(src, dst):
    x = ti.field(src, shape=N, needs_grad=True)
    y = ti.field(dst, shape=N, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            v = ti.cast(x[i], dst)
            y[i] = v * v + ti.cast(ti.sin(x[i]), dst)

    xs = np.linspace(-1, 1, N).astype(src.np)
    x.from_numpy(xs)
    f()
    y.grad.fill(1)
    f.grad()
    assert x.grad.dtype is src and y.grad.dtype is dst
    xd = xs.astype(np.float64)
    assert rel_err(x.grad.to_numpy(), 2 * xd + np.cos(xd), floor=1e-3) < 1e-5
    check_grads(f, [x], [y], eps=1e-2, rtol=1e-2, atol=1e-3)


ZERO = {
    "floor": lambda v: ti.floor(v),
    "ceil": lambda v: ti.ceil(v),
    "round": lambda v: ti.round(v),
    "int_cast": lambda v: ti.cast(ti.cast(v, ti.i32), ti.f64),
    "compare_gt": lambda v: ti.cast(v > 0.25, ti.f64),
    "compare_le": lambda v: ti.cast(v <= 0.25, ti.f64),
    "compare_eq": lambda v: ti.cast(v == v, ti.f64),
    "floor_to_int": lambda v: ti.cast(ti.floor(v, ti.i32), ti.f64),
}


@pytest.mark.parametrize("name", list(ZERO))
def test_piecewise_constant_ops_have_exactly_zero_gradient(name):
    f64()
    fn = ZERO[name]
    x = ti.field(ti.f64, shape=N, needs_grad=True)
    y = ti.field(ti.f64, shape=N, needs_grad=True)
    z = ti.field(ti.f64, shape=N, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = fn(x[i])
            z[i] = fn(x[i]) * x[i]  # d/dx = fn(x): the piecewise-constant factor passes through

    xs = np.linspace(-2.3, 2.3, N)
    x.from_numpy(xs)
    f()
    y.grad.fill(1)
    f.grad()
    np.testing.assert_array_equal(x.grad.to_numpy(), np.zeros(N))
    y.grad.fill(0)
    z.grad.fill(1)
    f.grad()
    np.testing.assert_array_equal(x.grad.to_numpy(), y.to_numpy())


def test_float_mod_gradient():
    """x % y on floats (Python semantics): d/dx = 1, d/dy = -floor(x / y)."""
    f64()
    x = ti.field(ti.f64, shape=N, needs_grad=True)
    m = ti.field(ti.f64, shape=N, needs_grad=True)
    y = ti.field(ti.f64, shape=N, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = x[i] % m[i]

    rng = np.random.default_rng(0)
    xs, ms = rng.uniform(-5, 5, N), rng.uniform(0.7, 2.0, N)
    x.from_numpy(xs)
    m.from_numpy(ms)
    f()
    np.testing.assert_allclose(y.to_numpy(), np.mod(xs, ms), rtol=1e-12, atol=1e-12)
    y.grad.fill(1)
    f.grad()
    np.testing.assert_allclose(x.grad.to_numpy(), np.ones(N), rtol=1e-12)
    np.testing.assert_allclose(m.grad.to_numpy(), -np.floor(xs / ms), rtol=1e-12)


def test_op_without_derivative_rule_raises():
    """A float op with no rule never yields a silent zero: bit_cast to a float names the op."""
    f64()
    x = ti.field(ti.f64, shape=4, needs_grad=True)
    y = ti.field(ti.f64, shape=4, needs_grad=True)

    @ti.kernel
    def f():
        for i in x:
            y[i] = ti.bit_cast(ti.bit_cast(x[i], ti.i64) + 1, ti.f64) * x[i]

    f()
    with pytest.raises(GradientError, match="bitcast"):
        f.grad()
