"""The vector versions of libm's math functions (ir/vecmath.py's algorithms, codegen/vecmath.py's LLVM text): a
vectorised loop calls them in place of libm (LLVM's vector-function ABI), a scalar loop keeps libm.

- accuracy: on a dense sweep of f32 bit patterns (and special values), each function is within 1 ulp of the
  exact value (numpy's float64 function), NaN where it is NaN, and the special values (zeros of both signs,
  infinities, NaN, atan2's quadrants, pow's C99 cases) equal the float64 result rounded, sign of zero included;
  f64 sin/cos/atan2 within 1 ulp of a long double reference (libm's own lanes: libm's bits);
- the numpy model is what the vectorised loop computes, bit for bit; the scalar remainder and a loop-free kernel
  are libm's;
- the optimised LLVM IR of a loop calling them has vector calls of our functions and no libm call in its vector
  body (fails if the mapping is lost), and fast_math=False has neither the mapping nor our functions;
- gradients of kernels using them agree with central differences in float64.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import simgrad as ti
from simgrad import dtypes as dt
from simgrad.ir import numeric
from simgrad.ir import vecmath as vm
from simgrad.runtime.jit import get_jit

UNARY = {"sin": np.sin, "cos": np.cos, "tan": np.tan, "atan": np.arctan, "exp": np.exp, "log": np.log,
         "tanh": np.tanh}
ALGO = {name: fn for _, (name, fn) in vm.FUNCTIONS.items()} | {"atan": vm.ATAN[1]}
SPECIAL = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1.0, -1.0, 0.5, -0.5, 2.0, -2.0, 3.0, -3.0, 1e-45, -1e-45,
                    1.1754944e-38, 3.4028235e38, -3.4028235e38, 1e-7, 88.72, 88.73, -103.9, -104.0, 1.5707964,
                    3.1415927, 1e7, 16777216.0, 16777217.0, 2.5, -2.5], dtype=np.float32)


def _sweep(stride: int = 8191) -> np.ndarray:
    return np.arange(0, 2**32, stride, dtype=np.uint64).astype(np.uint32).view(np.float32)


def _ulp_error(got: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """|got - exact| in units of the f32 ulp at `exact`; 0 where both are NaN or got is `exact` rounded."""
    with np.errstate(all="ignore"):
        e = np.floor(np.log2(np.maximum(np.abs(exact), 2.0**-126)))
        ulp = 2.0 ** (np.minimum(e, 127) - 23)
        err = np.abs(got.astype(np.float64) - exact) / ulp
        same = (got == exact.astype(np.float32)) | (np.isnan(got) & np.isnan(exact))
    return np.where(same, 0.0, np.where(np.isnan(err), np.inf, err))


def _same_bits(got: np.ndarray, want: np.ndarray) -> np.ndarray:
    return (got.view(np.uint32) == want.view(np.uint32)) | (np.isnan(got) & np.isnan(want))


@pytest.mark.parametrize("name", sorted(UNARY))
def test_unary_within_one_ulp_on_a_dense_sweep(name):
    x = np.concatenate([_sweep(), SPECIAL])
    got = vm.evaluate(ALGO[name], x)
    with np.errstate(all="ignore"):
        exact = UNARY[name](x.astype(np.float64))
    err = _ulp_error(got, exact)
    assert err.max() <= 1.0, f"{name}({x[err.argmax()]!r}) = {got[err.argmax()]!r}, exact {exact[err.argmax()]!r}"
    with np.errstate(all="ignore"):
        want = exact.astype(np.float32)
    n = len(SPECIAL)
    assert _same_bits(got[-n:], want[-n:]).all(), list(zip(SPECIAL, got[-n:], want[-n:]))


@pytest.mark.parametrize("name,ref", [("atan2", np.arctan2), ("pow", np.power)])
def test_binary_within_one_ulp_and_special_cases(name, ref):
    rng = np.random.default_rng(1)
    x = _sweep(16381)
    if name == "atan2":
        a, b = x, rng.standard_normal(x.size).astype(np.float32) * np.float32(10) ** rng.integers(-30, 30, x.size)
    else:  # every base; exponents that keep |result| mostly finite, integers for negative bases
        a = x
        b = (rng.standard_normal(x.size) * 4).astype(np.float32)
        b = np.where(a < 0, np.round(b), b).astype(np.float32)
    b = b.astype(np.float32)
    got = vm.evaluate(ALGO[name], a, b)
    with np.errstate(all="ignore"):
        exact = ref(a.astype(np.float64), b.astype(np.float64))
    err = _ulp_error(got, exact)
    i = err.argmax()
    assert err.max() <= 1.0, f"{name}({a[i]!r}, {b[i]!r}) = {got[i]!r}, exact {exact[i]!r}"
    sa, sb = (s.reshape(-1).astype(np.float32) for s in np.meshgrid(SPECIAL, SPECIAL))
    got = vm.evaluate(ALGO[name], sa, sb)
    with np.errstate(all="ignore"):
        exact = ref(sa.astype(np.float64), sb.astype(np.float64))
    err = _ulp_error(got, exact)
    assert err.max() <= 1.0
    with np.errstate(over="ignore"):
        want = exact.astype(np.float32)
    zero = want == 0  # signed zeros and the rest of the exact cases
    bad = [(a, b, g, w) for a, b, g, w in zip(sa[zero], sb[zero], got[zero], want[zero]) if not _same_bits(g, w)]
    assert not bad
    ok = _same_bits(got, want) | ~(np.isinf(want) | np.isnan(want) | (np.abs(want) == 1) | (want == 0))
    assert ok.all(), list(zip(sa[~ok], sb[~ok], got[~ok], want[~ok]))


def test_sin_cos_reduce_huge_arguments_exactly():
    """Every f32 exponent from 2**20 up: the reduction by 2/pi is exact, not only Cody-Waite's small range."""
    rng = np.random.default_rng(2)
    bits = (rng.integers(147 << 23, 255 << 23, 200000)).astype(np.uint32)
    x = bits.view(np.float32)
    for name in ("sin", "cos", "tan"):
        err = _ulp_error(vm.evaluate(ALGO[name], x), UNARY[name](x.astype(np.float64)))
        assert err.max() <= 1.0, name


_KERNEL_OPS = {"sin": ti.sin, "cos": ti.cos, "tan": ti.tan, "exp": ti.exp, "log": ti.log, "tanh": ti.tanh}


def _libm(name: str, t: dt.DataType, *cols: np.ndarray) -> np.ndarray:
    return np.array([numeric.libm(name, t, *map(float, v)) for v in zip(*cols)], dtype=t.np)


def test_vector_lanes_are_the_model_and_scalar_ones_libm():
    """n = 16k + 13: the vectorised body gives the model's bits, every element is the model's or libm's (the
    remainder), and a loop-free kernel calls libm. Without flushing, so subnormal operands and results count."""
    ti.init(arch=ti.cpu, flush_denormals=False, cpu_max_num_threads=1)
    rng = np.random.default_rng(3)
    n = 16 * 300 + 13
    xs = np.concatenate([SPECIAL, rng.integers(0, 2**32, n - len(SPECIAL), dtype=np.uint64).astype(np.uint32)
                         .view(np.float32)]).astype(np.float32)
    ys = (rng.standard_normal(n) * 3).astype(np.float32)
    x, y = ti.field(ti.f32, n), ti.field(ti.f32, n)
    out = ti.field(ti.f32, (8, n))
    x.from_numpy(xs)
    y.from_numpy(ys)

    @ti.kernel
    def run():
        for i in range(n):
            out[0, i] = ti.sin(x[i])
            out[1, i] = ti.cos(x[i])
            out[2, i] = ti.tan(x[i])
            out[3, i] = ti.exp(x[i])
            out[4, i] = ti.log(x[i])
            out[5, i] = ti.tanh(x[i])
            out[6, i] = ti.atan2(x[i], y[i])
            out[7, i] = ti.pow(ti.abs(x[i]), y[i])

    run()
    got = out.to_numpy()
    body = n - 128  # certainly in the vector body (at most 16 lanes x 4 interleaved, plus an epilogue)
    cases = [(k, name, (xs,)) for k, name in enumerate(["sin", "cos", "tan", "exp", "log", "tanh"])]
    cases += [(6, "atan2", (xs, ys)), (7, "pow", (np.abs(xs), ys))]
    for k, name, args in cases:
        want = vm.evaluate(ALGO[name], *args)
        same = _same_bits(got[k], want)
        assert same[:body].all(), (name, args[0][:body][~same[:body]][:5])
        rest = ~same
        assert _same_bits(got[k][rest], _libm(name, dt.f32, *(a[rest] for a in args))).all(), name

    s = ti.field(ti.f32, ())
    r = ti.field(ti.f32, ())

    @ti.kernel
    def one():
        r[None] = ti.cos(s[None])

    for v in (0.3, -2.5, 1e30, 7.0):
        s[None] = v
        one()
        assert r[None] == numeric.libm("cos", dt.f32, float(np.float32(v)))


def _optimized_task(kernel) -> str:
    text = kernel._instance_for((), "").llvm_text
    opt = str(get_jit()._optimized(text, 0))
    return opt.split("define internal void @sg_kernel_task1")[1].split("\n}")[0]


def _vector_body(task: str) -> str:
    return task.split("vector.body:")[1].split("middle.block:")[0]


@pytest.mark.parametrize("fast_math", [True, False])
def test_a_loop_calling_cos_and_atan2_vectorises_with_our_functions(fast_math):
    """fast_math: the vector body calls our vector functions and no libm (fails if the lowering or the mapping
    is lost); fast_math=False: libm calls as before, no mapping, none of our functions."""
    if ti.lang.impl.current_cfg().arch == ti.cuda:
        pytest.skip("the CPU task's LLVM IR is checked on the CPU")
    ti.init(arch=ti.cpu, fast_math=fast_math)
    n = 4096
    x, y = ti.field(ti.f32, n), ti.field(ti.f32, n)

    @ti.kernel
    def k():
        for i in x:
            y[i] = ti.cos(x[i]) * ti.atan2(x[i], 2.0) + ti.exp(x[i])

    k()
    task = _optimized_task(k)
    if fast_math:
        body = _vector_body(task)
        for name in ("cosf", "atan2f", "expf"):
            assert re.search(rf"call <\d+ x float> @sg_vm_{name}_v\d+\(", body), name
        assert not re.search(r"call [^\n]*@(cosf|atan2f|expf|llvm\.cos|llvm\.exp)", body)
    else:
        assert re.search(r"call [^\n]*@(cosf|llvm\.cos\.f32)", task) and "@atan2f" in task
        assert "sg_vm_" not in k._instance_for((), "").llvm_text


_GRAD_CASES = {
    "sin": (lambda b, x, y: b.sin(x), lambda x, y: np.sin(x)),
    "cos": (lambda b, x, y: b.cos(x * 3.0), lambda x, y: np.cos(x * 3.0)),
    "tan": (lambda b, x, y: b.tan(x), lambda x, y: np.tan(x)),
    "exp": (lambda b, x, y: b.exp(x), lambda x, y: np.exp(x)),
    "log": (lambda b, x, y: b.log(x + 2.0), lambda x, y: np.log(x + 2.0)),
    "tanh": (lambda b, x, y: b.tanh(x * 2.0), lambda x, y: np.tanh(x * 2.0)),
    "atan2": (lambda b, x, y: b.atan2(x, y), lambda x, y: np.arctan2(x, y)),
    "pow": (lambda b, x, y: b.pow(x + 2.0, y), lambda x, y: np.power(x + 2.0, y)),
}


def _tape_gradients(name, dtype, xs, ys):
    """(dloss/dx, dloss/dy) of loss = sum of _GRAD_CASES[name] over xs, ys, by a Tape over a kernel of dtype."""
    ti.init(arch=ti.cpu, default_fp=dtype)
    expr = _GRAD_CASES[name][0]
    x = ti.field(dtype, len(xs), needs_grad=True)
    y = ti.field(dtype, len(xs), needs_grad=True)
    loss = ti.field(dtype, (), needs_grad=True)
    x.from_numpy(xs)
    y.from_numpy(ys)

    @ti.kernel
    def f():
        for i in x:
            loss[None] += expr(ti, x[i], y[i])

    with ti.ad.Tape(loss):
        f()
    return x.grad.to_numpy(), y.grad.to_numpy()


@pytest.mark.parametrize("name", sorted(_GRAD_CASES))
def test_gradients_match_central_differences_in_f64(name):
    """The adjoint of an f32 kernel (its derivatives call the same vectorisable functions) against central
    differences of the expression in float64."""
    rng = np.random.default_rng(4)
    xs = rng.uniform(-1.2, 1.2, 64).astype(np.float32)
    ys = rng.uniform(0.3, 2.0, 64).astype(np.float32)
    ref = _GRAD_CASES[name][1]
    gx_got, gy_got = _tape_gradients(name, ti.f32, xs, ys)
    h = 1e-6
    xd, yd = xs.astype(np.float64), ys.astype(np.float64)
    gx = (ref(xd + h, yd) - ref(xd - h, yd)) / (2 * h)
    gy = (ref(xd, yd + h) - ref(xd, yd - h)) / (2 * h)
    np.testing.assert_allclose(gx_got, gx, rtol=2e-5, atol=2e-5)
    if name in ("atan2", "pow"):
        np.testing.assert_allclose(gy_got, gy, rtol=2e-5, atol=2e-5)


# -- f64: sin, cos, atan2 (libm for the lanes outside the fast path) ------------------------------------------

ALGO64 = {name: fn for _, (name, fn) in vm.FUNCTIONS64.items()}
SPECIAL64 = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1.0, -1.0, np.pi / 2, np.pi, -np.pi, 2 * np.pi, 1e-310,
                      -5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, 2.0 ** 30, -(2.0 ** 30) + 0.5, 1e22,
                      6381956970095103 * 2.0 ** 797, 1e-8, 0.5, -3.0, 7.0])


def _ulp_error64(got: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """As _ulp_error, for doubles against a long double (64-bit significand) reference."""
    with np.errstate(all="ignore"):
        e = np.floor(np.log2(np.maximum(np.abs(exact.astype(np.float64)), 2.0**-1022)))
        ulp = np.ldexp(np.longdouble(1), (np.nan_to_num(np.minimum(e, 1023), nan=0.0) - 52).astype(int))
        err = (np.abs(got.astype(np.longdouble) - exact) / ulp).astype(np.float64)
        same = (got == exact.astype(np.float64)) | (np.isnan(got) & np.isnan(exact.astype(np.float64)))
    return np.where(same, 0.0, np.where(np.isnan(err), np.inf, err))


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 63, reason="needs an 80-bit long double reference")
@pytest.mark.parametrize("name,ref", [("sin", np.sin), ("cos", np.cos)])
def test_f64_sin_cos_within_one_ulp(name, ref):
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(-4, 4, 100000), rng.uniform(-1e6, 1e6, 50000),
                        rng.uniform(-2.0**30, 2.0**30, 50000), np.pi / 2 * np.arange(-2000, 2000), SPECIAL64])
    got = vm.evaluate(ALGO64[name], x, f64=True)
    fast = np.abs(x) < 2.0**30  # beyond, and inf and NaN, the lane is libm's own (on this glibc, cos of the
    # classic worst case 6381956970095103 * 2**797 is 8 ulp off): equal to it bit for bit
    with np.errstate(all="ignore"):
        err = _ulp_error64(got[fast], ref(x[fast].astype(np.longdouble)))
    assert err.max() <= 1.0, f"{name}({x[fast][err.argmax()]!r}): {err.max()} ulp"
    libm = np.array([numeric.libm(name, dt.f64, float(v)) for v in x[~fast]])
    assert _same64(got[~fast], libm).all()
    zeros = x == 0
    assert _same64(got[zeros], np.sin(x[zeros]) if name == "sin" else np.ones(zeros.sum())).all()


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 63, reason="needs an 80-bit long double reference")
def test_f64_exp_within_one_ulp():
    rng = np.random.default_rng(9)
    x = np.concatenate([rng.uniform(-708, 708, 200000), rng.uniform(-1, 1, 100000), rng.uniform(-1e-9, 1e-9, 1000)])
    got = vm.evaluate(ALGO64["exp"], x, f64=True)
    err = _ulp_error64(got, np.exp(x.astype(np.longdouble)))
    assert err.max() <= 1.0, (x[err.argmax()], err.max())
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 709.7, 710.0, -745.0, -746.0, 1e-310, 708.0, -708.0])
    assert _same64(vm.evaluate(ALGO64["exp"], special, f64=True), _libm("exp", dt.f64, special)).all()


@pytest.mark.skipif(np.finfo(np.longdouble).nmant < 63, reason="needs an 80-bit long double reference")
def test_f64_atan2_within_one_ulp_and_special_cases():
    rng = np.random.default_rng(6)
    n = 200000
    y = rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20, n)
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20, n)
    got = vm.evaluate(ALGO64["atan2"], y, x, f64=True)
    err = _ulp_error64(got, np.arctan2(y.astype(np.longdouble), x.astype(np.longdouble)))
    assert err.max() <= 1.0, (y[err.argmax()], x[err.argmax()], err.max())
    a, b = (v.reshape(-1) for v in np.meshgrid(SPECIAL64, SPECIAL64))
    got = vm.evaluate(ALGO64["atan2"], a, b, f64=True)
    want = np.arctan2(a, b)
    assert (_ulp_error64(got, np.arctan2(a.astype(np.longdouble), b.astype(np.longdouble))) <= 1).all()
    exact = (want == 0) | np.isnan(want) | (np.abs(want) == np.float64(np.pi)) | (np.abs(want) == np.pi / 2)
    assert _same64(got[exact], want[exact]).all()


def _same64(got: np.ndarray, want: np.ndarray) -> np.ndarray:
    return (got.view(np.int64) == want.view(np.int64)) | (np.isnan(got) & np.isnan(want))


def test_f64_vector_lanes_are_the_model_with_libm_lanes():
    """The vectorised body, including the lanes its fast path leaves to libm (huge, inf, NaN, zeros), gives the
    model's bits; the rest (the remainder) libm's."""
    ti.init(arch=ti.cpu, flush_denormals=False, cpu_max_num_threads=1)
    rng = np.random.default_rng(7)
    n = 16 * 500 + 11
    xs = np.concatenate([SPECIAL64, rng.uniform(-50, 50, n - 2 * len(SPECIAL64)), SPECIAL64[::-1]])
    ys = np.concatenate([rng.standard_normal(n - len(SPECIAL64)), SPECIAL64])
    x, y = ti.field(ti.f64, n), ti.field(ti.f64, n)
    out = ti.field(ti.f64, (4, n))
    x.from_numpy(xs)
    y.from_numpy(ys)

    @ti.kernel
    def run():
        for i in range(n):
            out[0, i] = ti.sin(x[i])
            out[1, i] = ti.cos(x[i])
            out[2, i] = ti.atan2(y[i], x[i])
            out[3, i] = ti.exp(x[i] * 20.0)

    run()
    got = out.to_numpy()
    body = n - 128
    for k, name, args in ((0, "sin", (xs,)), (1, "cos", (xs,)), (2, "atan2", (ys, xs)), (3, "exp", (xs * 20.0,))):
        want = vm.evaluate(ALGO64[name], *args, f64=True)
        same = _same64(got[k], want)
        assert same[:body].all(), name
        assert _same64(got[k][~same], _libm(name, dt.f64, *(a[~same] for a in args))).all(), name
    assert not _same64(got[1][:body], _libm("cos", dt.f64, xs[:body])).all()  # not libm's: ours differ somewhere


def test_f64_loop_vectorises_with_libm_only_in_the_masked_fallback():
    """snow_phaseField's shape: f64 atan2 then cos in a loop. The vector body calls our functions (which call
    libm only for lanes outside their fast path), never libm directly."""
    if ti.lang.impl.current_cfg().arch == ti.cuda:
        pytest.skip("the CPU task's LLVM IR is checked on the CPU")
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    n = 4096
    x, y = ti.field(ti.f64, n), ti.field(ti.f64, n)

    @ti.kernel
    def k():
        for i in x:
            a = ti.atan2(x[i], 0.7)
            y[i] = 0.006 * (1.0 + 0.12 * ti.cos(6 * a)) - ti.sin(6 * a) + ti.exp(a)

    k()
    body = _vector_body(_optimized_task(k))
    for name in ("atan2", "cos", "sin", "exp"):
        assert re.search(rf"call <\d+ x double> @sg_vm_{name}_v\d+\(", body), name
    assert not re.search(r"call [^\n]*@(cos|sin|atan2|exp|llvm\.(cos|sin|exp)\.f64)\(", body)


@pytest.mark.parametrize("name", ["sin", "cos", "atan2", "exp"])
def test_f64_gradients_match_central_differences(name):
    rng = np.random.default_rng(8)
    xs, ys = rng.uniform(-3, 3, 64), rng.uniform(-2, 2, 64)
    ref = _GRAD_CASES[name][1]
    gx_got, gy_got = _tape_gradients(name, ti.f64, xs, ys)
    h = 1e-6
    np.testing.assert_allclose(gx_got, (ref(xs + h, ys) - ref(xs - h, ys)) / (2 * h), rtol=1e-7, atol=1e-8)
    if name == "atan2":
        np.testing.assert_allclose(gy_got, (ref(xs, ys + h) - ref(xs, ys - h)) / (2 * h), rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_vectors_of_zeros_take_the_exact_value_at_zero(dtype):
    """A vector whose lanes are all zeros returns the value at zero without the full algorithm (snow_phaseField's
    flat field: a zero gradient's angle and its cosine). Blocks of 64 elements (whole vectors): +0, -0 (sin and
    atan2 keep the sign), +-0 mixed, zeros with one nonzero lane, random values; atan2's x +0 (the value is y),
    -0 (+-pi: no shortcut) and random. Every element is libm's bits where both operands are zeros, the model's
    in the vector body elsewhere."""
    ti.init(arch=ti.cpu, flush_denormals=False, cpu_max_num_threads=1, default_fp=dtype)
    single = dtype is ti.f32  # (f64 has no vector tan)
    t = dt.f32 if single else dt.f64
    f = t.np
    rng = np.random.default_rng(5)
    blocks = [np.zeros(64), np.full(64, -0.0), np.where(rng.random(64) < 0.5, 0.0, -0.0),
              np.where(np.arange(64) == 37, 0.25, 0.0), rng.uniform(-3, 3, 64)]
    ys = np.concatenate(blocks * 3).astype(f)
    xs = np.concatenate([np.zeros(320), np.full(320, -0.0), np.full(64, np.nan), rng.uniform(-3, 3, 256)]).astype(f)
    n = len(ys) + 7  # a scalar remainder
    ys, xs = np.concatenate([ys, np.zeros(7, f)]), np.concatenate([xs, np.zeros(7, f)])
    y, x = ti.field(dtype, n), ti.field(dtype, n)
    out = ti.field(dtype, (5, n))
    y.from_numpy(ys)
    x.from_numpy(xs)

    @ti.kernel
    def run():
        for i in range(n):
            out[0, i] = ti.sin(y[i])
            out[1, i] = ti.cos(y[i])
            out[2, i] = ti.exp(y[i])
            out[3, i] = ti.atan2(y[i], x[i])
            out[4, i] = ti.tan(y[i]) if ti.static(single) else ti.sin(y[i])

    run()
    got = out.to_numpy()
    same = _same_bits if dtype is ti.f32 else _same64
    algos = ALGO if dtype is ti.f32 else ALGO64
    zero_y = ys == 0
    for k, name, args in ((0, "sin", (ys,)), (1, "cos", (ys,)), (2, "exp", (ys,)), (3, "atan2", (ys, xs)),
                          (4, "tan" if dtype is ti.f32 else "sin", (ys,))):
        zeros = zero_y & (xs == 0) if name == "atan2" else zero_y
        assert same(got[k][zeros], _libm(name, t, *(a[zeros] for a in args))).all(), name
        body = ~zeros & (np.arange(n) < n - 128)
        assert same(got[k][body], vm.evaluate(algos[name], *(a[body] for a in args),
                                               **({} if dtype is ti.f32 else {"f64": True}))).all(), name
