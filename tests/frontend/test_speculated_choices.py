"""`a and b`, `a or b` and `x if c else y` whose sides may run unchosen (frontend/speculate.py) are one select,
not a branch: pure arithmetic and loads of field elements known in bounds (the element a struct-for visits).
The values and types are those of the short-circuit lowering; a side with effects, a load that may leave the
field, an ndarray element, or a debug overflow report keeps the branch."""

import numpy as np
import pytest

import simgrad as ti
import simgrad.frontend.speculate as speculate
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


@pytest.fixture
def short_circuit(monkeypatch):
    """Turns the speculation of loads off: every choice that loads is a branch again (the reference)."""
    def off():
        monkeypatch.setattr(speculate, "in_bounds", lambda ptr: False)
    return off


def _ifs(kernel, *args) -> int:
    return sum(1 for s in walk(kernel.instance(args).ir.body) if s.op is Op.IF)


def _bool_ops_program(serial: bool):
    n = 12
    x = ti.field(ti.f32, shape=(n, n))
    k_ = ti.field(ti.i32, shape=(n, n))
    b = ti.field(ti.u1, shape=(n, n))
    out_f = ti.field(ti.f32, shape=(n, n))
    out_i = ti.field(ti.i32, shape=(n, n))
    out_m = ti.field(ti.f32, shape=(n, n))

    @ti.func
    def inner(i, j):
        return (k_[i, j] > 3 or x[i, j] < -0.5) and not (j > 8 and b[i, j])

    @ti.kernel
    def run():
        ti.loop_config(serialize=serial)
        for i, j in x:
            out_f[i, j] = (i < 3 and x[i, j]) or (j > n - 3 and x[i, j] * 2.0)  # floats, values not bools
            out_i[i, j] = (k_[i, j] and j) or (b[i, j] and 7) or inner(i, j)  # ints, u1, nested, ti.func
            out_m[i, j] = (x[i, j] > 0 and k_[i, j]) + (i % 2 == 0 or x[i, j]) + (x[i, j] if j < 5 else k_[i, j])

    rng = np.random.default_rng(1)
    x.from_numpy(rng.uniform(-1, 1, (n, n)).astype(np.float32) * (rng.uniform(0, 1, (n, n)) > 0.3))
    k_.from_numpy(rng.integers(-2, 6, (n, n)).astype(np.int32))
    b.from_numpy((rng.uniform(0, 1, (n, n)) > 0.5).astype(np.uint8))
    run()
    return run, [f.to_numpy() for f in (out_f, out_i, out_m)], (x.to_numpy(), k_.to_numpy(), b.to_numpy())


def _python_reference(xs, ks, bs):
    n = xs.shape[0]
    f = np.zeros((n, n), np.float32)
    i_ = np.zeros((n, n), np.int32)
    m = np.zeros((n, n), np.float32)
    for i in range(n):
        for j in range(n):
            x, k, b = xs[i, j], int(ks[i, j]), int(bs[i, j])
            f[i, j] = (i < 3 and x) or (j > n - 3 and x * np.float32(2.0))
            inner = (k > 3 or x < -0.5) and not (j > 8 and b)
            i_[i, j] = (k and j) or (b and 7) or inner
            m[i, j] = (x > 0 and k) + (i % 2 == 0 or x) + (x if j < 5 else k)
    return f, i_, m


@pytest.mark.parametrize("serial", [False, True], ids=["parallel", "serial"])
def test_selects_equal_short_circuit_and_python(serial, short_circuit):
    ti.init(arch=ti.cpu)
    run, got, data = _bool_ops_program(serial)
    assert _ifs(run) == 0  # every choice is a select: its loads are the loop's own elements
    for g, want in zip(got, _python_reference(*data)):
        np.testing.assert_array_equal(g, want)
    short_circuit()
    ti.init(arch=ti.cpu)
    run_ref, ref, _ = _bool_ops_program(serial)
    assert _ifs(run_ref) > 0
    for g, r in zip(got, ref):
        assert g.dtype == r.dtype
        np.testing.assert_array_equal(g, r)


def test_types_of_selected_choices_are_the_short_circuit_ones():
    """`k and x` with i64 k and f64 x is f64 (fractions kept), `c or k` with an i64 k is i64 (2**40 kept)."""
    ti.init(arch=ti.cpu)
    x = ti.field(ti.f64, shape=4)
    k = ti.field(ti.i64, shape=4)

    @ti.kernel
    def run() -> ti.f64:
        s = 0.0
        for i in x:
            s += (k[i] and x[i]) + (x[i] > 0 or k[i])
        return s

    x.from_numpy(np.array([0.1, 0.0, -2.25, 3.0]))
    k.from_numpy(np.array([0, 2, 3, 2**40]))
    assert run() == sum((kk and xx) + (xx > 0 or kk) for xx, kk in zip(x.to_numpy(), k.to_numpy().tolist()))
    assert _ifs(run) == 0


def test_grid_boundary_condition_has_no_branch_for_its_and():
    """mpm's `if i < 3 and grid_v[i, j][0] < 0:`: the `and` is a select, only the `if` stays."""
    ti.init(arch=ti.cpu)
    n = 16
    v = ti.Vector.field(2, ti.f32, shape=(n, n))

    @ti.kernel
    def bc():
        for i, j in v:
            if i < 3 and v[i, j][0] < 0:
                v[i, j][0] = 0
            if j > n - 3 and v[i, j][1] > 0:
                v[i, j][1] = 0

    vs = np.random.default_rng(0).uniform(-1, 1, (n, n, 2)).astype(np.float32)
    v.from_numpy(vs)
    bc()
    want = vs.copy()
    want[:3, :, 0] = np.where(want[:3, :, 0] < 0, 0, want[:3, :, 0])
    want[:, n - 2:, 1] = np.where(want[:, n - 2:, 1] > 0, 0, want[:, n - 2:, 1])
    np.testing.assert_array_equal(v.to_numpy(), want)
    assert _ifs(bc) == 2


def test_load_that_may_leave_the_field_stays_guarded():
    """`i < n and x[i] > 0` over range(n + 1) must not read x[n]: debug mode would report it."""
    ti.init(arch=ti.cpu, debug=True)
    n = 5
    x = ti.field(ti.f32, shape=n)
    out = ti.field(ti.i32, shape=n + 1)

    @ti.kernel
    def run():
        for i in range(n + 1):
            out[i] = i < n and x[i] > 0

    x.from_numpy(np.array([1, -1, 2, 0, 3], np.float32))
    run()  # no IndexError
    np.testing.assert_array_equal(out.to_numpy(), [1, 0, 1, 0, 1, 0])
    assert _ifs(run) == 1


def test_neighbour_and_run_time_indices_stay_guarded():
    ti.init(arch=ti.cpu)
    n = 6
    x = ti.field(ti.f32, shape=n)
    out = ti.field(ti.f32, shape=n)

    @ti.kernel
    def run(m: ti.i32):
        for i in x:
            a = i > 0 and x[i - 1]  # i - 1 is -1 for i == 0
            b = m < n and x[m]  # a run-time index
            out[i] = a + b

    x.from_numpy(np.arange(1, n + 1, dtype=np.float32))
    run(2)
    np.testing.assert_array_equal(out.to_numpy(), [3, 4, 5, 6, 7, 8])
    assert _ifs(run, 2) == 2


def test_sides_with_effects_run_only_when_chosen():
    ti.init(arch=ti.cpu)
    n = 8
    x = ti.field(ti.f32, shape=n)
    hits = ti.field(ti.i32, shape=n)
    out = ti.field(ti.i32, shape=n)

    @ti.func
    def touch(i):
        hits[i] += 1
        return 1

    @ti.kernel
    def run():
        for i in x:
            out[i] = (x[i] > 0 and touch(i)) + 2 * (x[i] > 0 or touch(i))

    x.from_numpy(np.array([1, -1, 2, 0, 3, -4, 5, 0], np.float32))
    run()
    pos = x.to_numpy() > 0
    np.testing.assert_array_equal(hits.to_numpy(), np.ones(n, np.int32))  # once by `and` or once by `or`
    np.testing.assert_array_equal(out.to_numpy(), np.where(pos, 3, 2))
    assert _ifs(run) == 2


def test_integer_division_by_zero_side():
    """`d != 0 and 12 // d > 2`: the division may run with d == 0 (it does not trap), the value is the
    short-circuit one."""
    ti.init(arch=ti.cpu)
    d = ti.field(ti.i32, shape=6)
    out = ti.field(ti.i32, shape=6)

    @ti.kernel
    def run():
        for i in d:
            out[i] = d[i] != 0 and 12 // d[i] > 2

    d.from_numpy(np.array([0, 1, 0, 5, 4, -3], np.int32))
    run()
    np.testing.assert_array_equal(out.to_numpy(), [0, 1, 0, 0, 1, 0])


def test_debug_overflow_report_is_not_speculated(capfd):
    """A checked `+` in debug mode prints when it overflows: it runs only when its side is chosen."""
    ti.init(arch=ti.cpu, debug=True)
    big = ti.field(ti.i32, shape=4)
    out = ti.field(ti.i32, shape=4)

    @ti.kernel
    def run():
        for i in big:
            out[i] = i > 10 and big[i] + big[i] > 0

    @ti.kernel
    def pure(a: ti.i32) -> ti.i32:  # a side of pure arithmetic was hoisted before: its report printed
        return a < 0 and a + a > 0

    big.fill(2**30 + 5)
    capfd.readouterr()
    run()
    assert pure(2**30 + 5) == 0
    assert "overflow" not in capfd.readouterr().out
    np.testing.assert_array_equal(out.to_numpy(), [0, 0, 0, 0])
    assert pure(-(2**30) - 5) == 1  # the side runs: the sum wraps to a positive value, and is reported
    assert "overflow" in capfd.readouterr().out


def test_gradients_through_selected_choices_match_finite_differences():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    n = 10
    x = ti.field(ti.f64, shape=n, needs_grad=True)
    y = ti.field(ti.f64, shape=n, needs_grad=True)
    loss = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.func
    def pick(i):
        return (x[i] > 0.2 and x[i] * y[i]) or (y[i] < 0 and y[i] ** 2)

    @ti.kernel
    def f():
        for i in x:
            loss[None] += pick(i) + (x[i] * x[i] if i % 3 == 0 else ti.sin(y[i])) + (i < 4 and x[i] or y[i])

    rng = np.random.default_rng(3)
    xs, ys = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    x.from_numpy(xs)
    y.from_numpy(ys)
    assert _ifs(f) == 0
    with ti.ad.Tape(loss):
        f()
    gx, gy = x.grad.to_numpy(), y.grad.to_numpy()

    def value(xv, yv):
        x.from_numpy(xv)
        y.from_numpy(yv)
        loss[None] = 0
        f()
        return loss[None]

    h = 1e-6
    for k in range(n):
        e = np.zeros(n)
        e[k] = h
        assert gx[k] == pytest.approx((value(xs + e, ys) - value(xs - e, ys)) / (2 * h), rel=1e-6, abs=1e-8)
        assert gy[k] == pytest.approx((value(xs, ys + e) - value(xs, ys - e)) / (2 * h), rel=1e-6, abs=1e-8)


def test_local_index_written_later_in_a_loop_stays_guarded():
    """`j` is written once before the loop when the choice is lowered, but again after it in the loop: its
    value at the load is not 0, so x[j] may leave the field (debug mode would report x[4])."""
    ti.init(arch=ti.cpu, debug=True)
    n = 4
    x = ti.field(ti.f32, shape=n)
    out = ti.field(ti.f32, shape=())

    @ti.kernel
    def run():
        j = 0
        ti.loop_config(serialize=True)
        for _k in range(10):
            out[None] += j < n and x[j]
            j = j + 1

    x.from_numpy(np.array([1, 2, 3, 4], np.float32))
    run()
    assert out[None] == 10


def test_ti_func_parameter_index_is_known():
    """A ti.func's parameter is a local written once where the call is inlined: its range is its argument's."""
    ti.init(arch=ti.cpu)
    n = 6
    x = ti.field(ti.f32, shape=n)
    out = ti.field(ti.f32, shape=n)

    @ti.func
    def positive(i):
        return i > 1 and x[i] > 0

    @ti.kernel
    def run():
        for i in x:
            out[i] = positive(i)

    x.from_numpy(np.array([1, -1, 2, -2, 3, 0], np.float32))
    run()
    np.testing.assert_array_equal(out.to_numpy(), [0, 0, 1, 0, 1, 0])
    assert _ifs(run) == 0
