"""Math functions on scalars (f32 and f64) and element-wise on vectors, against numpy."""

import math

import numpy as np
import pytest

import simgrad as ti

UNARY = {
    "sqrt": (np.sqrt, (0.0, 50.0)),
    "sin": (np.sin, (-10.0, 10.0)),
    "cos": (np.cos, (-10.0, 10.0)),
    "tan": (np.tan, (-1.4, 1.4)),
    "asin": (np.arcsin, (-1.0, 1.0)),
    "acos": (np.arccos, (-1.0, 1.0)),
    "exp": (np.exp, (-20.0, 20.0)),
    "log": (np.log, (1e-3, 1e3)),
    "tanh": (np.tanh, (-5.0, 5.0)),
    "floor": (np.floor, (-10.0, 10.0)),
    "ceil": (np.ceil, (-10.0, 10.0)),
    "abs": (np.abs, (-10.0, 10.0)),
}
N = 257
RTOL = {ti.f32: 2e-6, ti.f64: 1e-14}


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_unary_math_functions(t):
    rng = np.random.default_rng(3)
    names = list(UNARY)
    xs = np.stack([rng.uniform(*UNARY[n][1], size=N) for n in names]).astype(t.np)
    xs[names.index("floor"), :4] = [-2.0, -1.5, 2.5, -0.0]
    xs[names.index("ceil"), :4] = [-2.0, -1.5, 2.5, -0.5]
    x = ti.field(t, shape=xs.shape)
    y = ti.field(t, shape=xs.shape)
    x.from_numpy(xs)
    fns = [getattr(ti, n) for n in names]

    @ti.kernel
    def k():
        for j in range(N):
            for r in ti.static(range(len(fns))):
                y[r, j] = fns[r](x[r, j])

    k()
    got = y.to_numpy()
    assert got.dtype == t.np
    for r, n in enumerate(names):
        want = UNARY[n][0](xs[r].astype(np.float64))
        atol = 2 * np.finfo(t.np).eps if n in ("sin", "cos") else 0  # near the zeros of sin/cos
        rtol = RTOL[t] * (4 if n == "tan" else 1)
        np.testing.assert_allclose(got[r], want, rtol=rtol, atol=atol, err_msg=n)


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_binary_math_functions(t):
    rng = np.random.default_rng(4)
    a_np = rng.uniform(-5, 5, size=N).astype(t.np)
    b_np = rng.uniform(-5, 5, size=N).astype(t.np)
    a_np[:4] = [0.0, -1.0, 1.0, 0.0]
    b_np[:4] = [-1.0, 0.0, 0.0, 1.0]
    a, b = ti.field(t, shape=N), ti.field(t, shape=N)
    out = ti.field(t, shape=(6, N))
    a.from_numpy(a_np)
    b.from_numpy(b_np)

    @ti.kernel
    def k():
        for i in a:
            out[0, i] = ti.atan2(a[i], b[i])
            out[1, i] = ti.pow(ti.abs(a[i]), b[i])
            out[2, i] = ti.abs(a[i]) ** b[i]
            out[3, i] = ti.min(a[i], b[i], 0.5)
            out[4, i] = ti.max(a[i], b[i], -0.5, a[i] * b[i])
            out[5, i] = a[i] ** 2

    k()
    got = out.to_numpy()
    a64, b64 = a_np.astype(np.float64), b_np.astype(np.float64)
    np.testing.assert_allclose(got[0], np.arctan2(a64, b64), rtol=RTOL[t], atol=1e-7)
    with np.errstate(divide="ignore"):
        powers = np.abs(a64) ** b64  # 0 ** -1 == inf
    np.testing.assert_allclose(got[1], powers, rtol=RTOL[t] * 8)
    np.testing.assert_allclose(got[2], powers, rtol=RTOL[t] * 8)
    np.testing.assert_array_equal(got[3], np.minimum(np.minimum(a_np, b_np), t.np.type(0.5)))
    want4 = np.maximum.reduce([a_np, b_np, np.full(N, -0.5, t.np), a_np * b_np])
    np.testing.assert_array_equal(got[4], want4)
    np.testing.assert_array_equal(got[5], a_np * a_np)


def _half_away(v):
    return np.sign(v) * np.floor(np.abs(v) + 0.5)


def test_round_is_half_away_from_zero():
    """ti.round rounds half away from zero, like Taichi 1.7.4 does for run-time values (x = 2.5 gives 3.0,
    -2.5 gives -3.0, 0.5 gives 1.0).

    Taichi folds literals half to even instead (ti.round(2.5) + ti.round(3.5) * 10 == 42 there), so its
    two paths disagree; simgrad uses the run-time rule for both (== 43 here)."""
    vals = np.array([0.5, 1.5, 2.5, -0.5, -1.5, -2.5, 2.4, 2.6, -2.6, 1e7 + 0.5], np.float64)
    x = ti.field(ti.f64, shape=len(vals))
    y = ti.field(ti.f64, shape=len(vals))
    yi = ti.field(ti.i32, shape=len(vals))
    y32 = ti.field(ti.f32, shape=len(vals))
    x.from_numpy(vals)

    @ti.kernel
    def k():
        for i in x:
            y[i] = ti.round(x[i])
            yi[i] = ti.round(x[i], ti.i32)
            y32[i] = round(ti.cast(x[i], ti.f32))

    k()
    np.testing.assert_array_equal(y.to_numpy(), _half_away(vals))
    np.testing.assert_array_equal(yi.to_numpy(), _half_away(vals).astype(np.int32))
    np.testing.assert_array_equal(y32.to_numpy(), _half_away(vals.astype(np.float32)))

    @ti.kernel
    def folded() -> ti.f32:
        return ti.round(2.5) + ti.round(3.5) * 10  # literals fold in Python with the same rule

    assert folded() == 3 + 40


def test_math_on_integers_promotes_to_default_fp():
    out = ti.field(ti.f32, shape=4)
    iout = ti.field(ti.i32, shape=3)

    @ti.kernel
    def k(n: ti.i32):
        out[0] = ti.sqrt(n)
        out[1] = ti.exp(n) / ti.exp(n - 1)
        out[2] = ti.atan2(n, 0)
        out[3] = ti.sqrt(2)  # folded in Python
        iout[0] = ti.abs(-n)
        iout[1] = ti.min(n, 3, -n)
        iout[2] = ti.max(n, 3) * 2

    k(9)
    np.testing.assert_allclose(out.to_numpy(), [3, math.e, math.pi / 2, math.sqrt(2)], rtol=1e-6)
    assert iout.to_numpy().tolist() == [9, -9, 18]


def test_special_values():
    out = ti.field(ti.f64, shape=6)

    @ti.kernel
    def k(z: ti.f64):
        out[0] = ti.sqrt(z - 1)  # nan
        out[1] = ti.log(z)  # -inf
        out[2] = 1 / z  # inf
        out[3] = ti.exp(z - 1000)  # underflow to 0
        out[4] = ti.exp(z + 1000)  # inf
        out[5] = ti.abs(-z)  # +0.0

    k(0.0)
    o = out.to_numpy()
    assert np.isnan(o[0])
    assert o[1] == -np.inf and o[2] == np.inf and o[3] == 0 and o[4] == np.inf
    assert o[5] == 0 and math.copysign(1, o[5]) == 1


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_elementwise_math_on_vectors(t):
    vec3 = ti.types.vector(3, t)
    v = ti.Vector.field(3, t, shape=4)
    out = ti.Vector.field(3, t, shape=(8, 4))
    vals = np.array([[0.1, 0.7, 2.5], [1.2, -0.3, 0.9], [-0.5, 0.4, 3.3], [2.0, 0.01, -1.5]], t.np)
    v.from_numpy(vals)

    @ti.kernel
    def k():
        for i in v:
            a = v[i]
            out[0, i] = ti.sin(a)
            out[1, i] = ti.exp(a)
            out[2, i] = ti.sqrt(ti.abs(a))
            out[3, i] = ti.floor(a)
            out[4, i] = ti.max(a, vec3(0.5, 0.5, 0.5))
            out[5, i] = ti.min(a, 0.0)
            out[6, i] = a ** 2 + ti.cos(a) * 2
            out[7, i] = ti.atan2(a, vec3(1.0, -1.0, 1.0))

    k()
    o = out.to_numpy()
    v64 = vals.astype(np.float64)
    want = [np.sin(v64), np.exp(v64), np.sqrt(np.abs(v64)), np.floor(v64), np.maximum(v64, 0.5),
            np.minimum(v64, 0.0), v64 ** 2 + np.cos(v64) * 2, np.arctan2(v64, [1.0, -1.0, 1.0])]
    for r, w in enumerate(want):
        np.testing.assert_allclose(o[r], w, rtol=RTOL[t] * 4, atol=RTOL[t], err_msg=str(r))


def test_math_module_functions():
    out = ti.field(ti.f32, shape=6)

    @ti.kernel
    def k(x: ti.f32):
        v = ti.math.vec3(x, 2 * x, 2.0)
        out[0] = v.norm()
        out[1] = v.dot(ti.math.vec3(1.0, 1.0, 1.0))
        out[2] = ti.math.clamp(x, 0.0, 0.5)
        out[3] = ti.math.mix(1.0, 3.0, 0.25)
        out[4] = ti.math.pi
        out[5] = ti.math.fract(x + 2)

    k(1.25)
    want = [math.sqrt(1.25**2 + 2.5**2 + 4), 1.25 + 2.5 + 2, 0.5, 1.5, math.pi, 0.25]
    np.testing.assert_allclose(out.to_numpy(), want, rtol=1e-6)
