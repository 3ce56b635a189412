"""fast_math (Taichi's default) divides by a float constant as taichi 1.7.4 does: `a / c` is `a * (1 / c)`, the
reciprocal rounded once at the division's type (taichi's alg_simp; side by side with taichi 1.7.4 on 20000
values, f32 and f64, `x / 3.0` and `x / 0.15625`: 0 of 80000 results differ, 24358 did with an exact division).
fast_math=False divides exactly. The adjoint's `g / c` is rewritten too."""

import numpy as np
import pytest

import simgrad as ti


def _values(dtype):
    rng = np.random.default_rng(2)
    x = rng.standard_normal(4000) * 10 ** rng.uniform(-3, 3, 4000)
    return np.concatenate([x, [0.0, -0.0, np.inf, -np.inf, 3e38]]).astype(dtype)  # (subnormals flush)


@pytest.mark.parametrize("T, npt", [(ti.f32, np.float32), (ti.f64, np.float64)])
@pytest.mark.parametrize("fast", [True, False])
def test_division_by_a_constant(T, npt, fast):
    ti.init(arch=ti.cpu, fast_math=fast)
    xs = _values(npt)
    x, y, z = (ti.field(T, len(xs)) for _ in range(3))
    x.from_numpy(xs)

    @ti.kernel
    def k():
        for i in x:
            y[i] = x[i] / 3.0
            z[i] = x[i] / (2 * 0.078125)  # a constant expression: folded, then rewritten

    with np.errstate(over="ignore", under="ignore"):
        if fast:
            want_y, want_z = xs * (npt(1) / npt(3)), xs * (npt(1) / npt(0.15625))
        else:
            want_y, want_z = xs / npt(3), xs / npt(0.15625)
    k()
    np.testing.assert_array_equal(y.to_numpy(), want_y)
    np.testing.assert_array_equal(z.to_numpy(), want_z)
    if fast:  # the test can tell the two apart
        assert (want_y != xs / npt(3)).any()


def test_division_by_a_variable_or_zero_stays_a_division():
    ti.init(arch=ti.cpu)  # fast_math
    xs = _values(np.float32)
    x, y = ti.field(ti.f32, len(xs)), ti.field(ti.f32, len(xs))
    x.from_numpy(xs)

    @ti.kernel
    def k(c: ti.f32):
        for i in x:
            y[i] = x[i] / c + x[i] / 0.0

    k(3.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        np.testing.assert_array_equal(y.to_numpy(), xs / np.float32(3) + xs / np.float32(0))


@pytest.mark.parametrize("fast", [True, False])
def test_gradient_of_a_division_by_a_constant(fast):
    ti.init(arch=ti.cpu, fast_math=fast, default_fp=ti.f64)
    x = ti.field(ti.f64, 5, needs_grad=True)
    loss = ti.field(ti.f64, (), needs_grad=True)
    x.from_numpy(np.array([0.5, -1.25, 3.0, 7.5, -0.1]))

    @ti.kernel
    def f():
        for i in x:
            loss[None] += ti.sin(x[i] / 3.0)

    with ti.ad.Tape(loss):
        f()
    xs = x.to_numpy()
    want = np.cos(xs * (1 / 3)) * (1 / 3) if fast else np.cos(xs / 3) / 3
    np.testing.assert_array_equal(x.grad.to_numpy(), want)
    assert (np.cos(xs * (1 / 3)) * (1 / 3) != np.cos(xs / 3) / 3).any()  # the test can tell the two apart
    eps = 1e-6  # and the gradient is the derivative
    for i in range(5):
        xp, xm = xs.copy(), xs.copy()
        xp[i] += eps
        xm[i] -= eps
        fd = (np.sin(xp / 3).sum() - np.sin(xm / 3).sum()) / (2 * eps)
        assert abs(fd - x.grad[i]) < 1e-8
