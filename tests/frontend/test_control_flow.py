"""Control flow: if/while/for in all their forms, static unrolling, loop nesting, atomics."""

import numpy as np
import pytest

import simgrad as ti


def test_if_elif_else_nested_in_loops():
    n = 40
    out = ti.field(ti.i32, shape=n)

    @ti.kernel
    def k(t: ti.i32):
        for i in range(n):
            if i < t:
                out[i] = 1
            elif i % 3 == 0:
                if i % 2 == 0:
                    out[i] = 2
                else:
                    out[i] = 3
            elif i > 30:
                out[i] = 4
            else:
                v = 0
                for j in range(i):
                    if j % 5 == 0:
                        v += j
                out[i] = v

    def ref(i, t):
        if i < t:
            return 1
        if i % 3 == 0:
            return 2 if i % 2 == 0 else 3
        if i > 30:
            return 4
        return sum(j for j in range(i) if j % 5 == 0)

    for t in (0, 7):
        k(t)
        assert out.to_numpy().tolist() == [ref(i, t) for i in range(n)]


def test_while_break_continue_in_serial_loops():
    n = 30
    steps = ti.field(ti.i32, shape=n)
    acc = ti.field(ti.i32, shape=n)

    @ti.kernel
    def collatz():
        for i in range(n):
            x = i + 1
            c = 0
            while x != 1:
                if x % 2 == 0:
                    x //= 2
                else:
                    x = 3 * x + 1
                c += 1
            steps[i] = c
            s = 0
            for j in range(100):
                if j > i:
                    break
                if j % 3 == 1:
                    continue
                s += j
            w = 0
            while True:
                w += 1
                if w >= i:
                    break
            acc[i] = s * 1000 + w

    collatz()

    def ref_steps(x):
        c = 0
        while x != 1:
            x = x // 2 if x % 2 == 0 else 3 * x + 1
            c += 1
        return c

    assert steps.to_numpy().tolist() == [ref_steps(i + 1) for i in range(n)]
    assert acc.to_numpy().tolist() == [sum(j for j in range(i + 1) if j % 3 != 1) * 1000 + max(i, 1)
                                       for i in range(n)]


def test_range_for_runtime_bounds_empty_ranges_and_steps():
    out = ti.field(ti.i32, shape=8)

    @ti.kernel
    def k(a: ti.i32, b: ti.i32):
        s = 0
        for i in range(a, b):
            s += i
        out[0] = s
        c = 0
        for _ in range(5, 2):  # empty: does nothing
            c += 1
        for _ in range(b, a):  # empty at run time when a <= b
            c += 100
        out[1] = c
        s = 0
        for i in range(a, b, 3):
            s += i
        out[2] = s
        s = 0
        for i in range(b, a, -2):
            s += i
        out[3] = s
        s = 0
        for i in range(10, 0, -3):
            s = s * 100 + i
        out[4] = s
        s = 0
        for _ in range(b):
            s += 1
        out[5] = s
        out[6] = 0
        for _ in range(a, a):
            out[6] = 1
        s = 0
        for i in range(-3, 3, 2):
            s = s * 10 + i + 5
        out[7] = s

    def ref(a, b):
        step3 = sum(range(a, b, 3))
        return [sum(range(a, b)), len(range(b, a)) * 100, step3, sum(range(b, a, -2)),
                int("".join(f"{i:02d}" for i in range(10, 0, -3))), len(range(b)), 0,
                int("".join(str(i + 5) for i in range(-3, 3, 2)))]

    for a, b in [(2, 11), (7, 3), (-4, 4), (5, 5)]:
        k(a, b)
        assert out.to_numpy().tolist() == ref(a, b), (a, b)


def test_parallel_range_for_with_runtime_bounds_and_step():
    n = 1000
    x = ti.field(ti.i32, shape=n)

    @ti.kernel
    def k(a: ti.i32, b: ti.i32):
        for i in range(a, b, 7):
            x[i] += i

    k(3, 900)
    k(900, 3)  # empty
    want = np.zeros(n, np.int32)
    want[3:900:7] = np.arange(3, 900, 7)
    np.testing.assert_array_equal(x.to_numpy(), want)


def test_static_unrolling_and_static_if():
    out = ti.field(ti.i32, shape=6)
    mat = [[1, 2], [3, 4]]

    @ti.kernel
    def k(flag: ti.template()):
        s = 0
        for i in ti.static(range(4)):
            s += i * 10 ** i
        out[0] = s
        for i, row in ti.static(enumerate(mat)):
            for j in ti.static(range(len(row))):
                out[1 + 2 * i + j] = row[j] * (i + 1)
        if ti.static(flag > 0):
            out[5] = 100
        else:
            out[5] = -100

    k(1)
    assert out.to_numpy().tolist() == [3210, 1, 2, 6, 8, 100]
    k(0)
    assert out[5] == -100


def test_static_if_skips_code_that_would_not_compile():
    v = ti.Vector.field(2, ti.f32, shape=())
    s = ti.field(ti.f32, shape=())

    @ti.kernel
    def k(x: ti.template()):
        if ti.static(isinstance(x, ti.Field) and x.ndim == 0 and hasattr(x, "n")):
            x[None][1] = 5.0  # only valid for a vector field
        else:
            x[None] = 3.0

    k(v)
    k(s)
    assert v[None][1] == 5.0 and s[None] == 3.0


def test_ndrange_with_begin_end_pairs():
    x = ti.field(ti.i32, shape=(6, 7))
    cnt = ti.field(ti.i32, shape=())

    @ti.kernel
    def k(n: ti.i32):
        for i, j in ti.ndrange((1, 5), (2, n)):
            x[i, j] = i * 10 + j
        for _i, _j, _q in ti.ndrange(2, (3, 3), 4):  # an empty axis: no iterations
            cnt[None] += 1
        for i, j in ti.ndrange((-2, 1), 3):
            cnt[None] += (i + 2) * 3 + j + 100

    k(6)
    want = np.zeros((6, 7), np.int32)
    for i in range(1, 5):
        for j in range(2, 6):
            want[i, j] = i * 10 + j
    np.testing.assert_array_equal(x.to_numpy(), want)
    assert cnt[None] == sum(i * 3 + j + 100 for i in range(3) for j in range(3))


def test_grouped_over_fields_and_ndrange():
    x = ti.field(ti.i32, shape=(3, 4))
    y = ti.field(ti.i32, shape=(3, 4))
    z = ti.field(ti.i32, shape=(4, 5, 2))

    @ti.kernel
    def k():
        for I in ti.grouped(x):
            x[I] = I[0] * 10 + I[1]
        for I in ti.grouped(ti.ndrange((1, 3), (2, 4))):
            y[I] = I.sum() + 100
        for I in ti.grouped(z):
            z[I] = I.dot(ti.Vector([100, 10, 1]))

    k()
    i, j = np.meshgrid(np.arange(3), np.arange(4), indexing="ij")
    np.testing.assert_array_equal(x.to_numpy(), i * 10 + j)
    want = np.zeros((3, 4), np.int32)
    want[1:3, 2:4] = (i + j)[1:3, 2:4] + 100
    np.testing.assert_array_equal(y.to_numpy(), want)
    a, b, c = np.meshgrid(np.arange(4), np.arange(5), np.arange(2), indexing="ij")
    np.testing.assert_array_equal(z.to_numpy(), a * 100 + b * 10 + c)


def test_struct_for_over_fields_of_every_rank():
    s0 = ti.field(ti.f32, shape=())
    s1 = ti.field(ti.f32, shape=5)
    s2 = ti.field(ti.f32, shape=(3, 4))
    s3 = ti.field(ti.f32, shape=(2, 3, 4))
    v2 = ti.Vector.field(2, ti.i32, shape=(2, 3))

    @ti.kernel
    def k():
        for I in ti.grouped(s0):
            s0[I] += 7
        for i in s1:
            s1[i] = i * 1.5
        for i, j in s2:
            s2[i, j] = i - j
        for i, j, q in s3:
            s3[i, j, q] = i * 100 + j * 10 + q
        for i, j in v2:
            v2[i, j] = [i, j]

    k()
    assert s0[None] == 7
    np.testing.assert_array_equal(s1.to_numpy(), np.arange(5) * 1.5)
    np.testing.assert_array_equal(s2.to_numpy(), np.arange(3)[:, None] - np.arange(4)[None, :])
    np.testing.assert_array_equal(s3.to_numpy(), np.fromfunction(lambda i, j, q: i * 100 + j * 10 + q,
                                                                 (2, 3, 4)))
    np.testing.assert_array_equal(v2.to_numpy(), np.stack(np.meshgrid(np.arange(2), np.arange(3),
                                                                      indexing="ij"), axis=-1))


def test_struct_for_over_0d_field_without_grouped():
    s0 = ti.field(ti.i32, shape=())

    @ti.kernel
    def k():
        for _ in ti.grouped(s0):
            s0[None] += 1

    k()
    k()
    assert s0[None] == 2


def test_nested_loops_outer_parallel_inner_serial():
    n, m = 50, 40
    a = ti.field(ti.f64, shape=(n, m))
    rows = ti.field(ti.f64, shape=n)
    rng = np.random.default_rng(5)
    a_np = rng.standard_normal((n, m))
    a.from_numpy(a_np)

    @ti.kernel
    def prefix():
        for i in range(n):  # parallel
            s = ti.cast(0.0, ti.f64)  # a bare 0.0 would make an f32 (default_fp) local
            for j in range(m):  # serial: order matters for the prefix sum
                s += a[i, j]
                a[i, j] = s
            rows[i] = s

    prefix()
    np.testing.assert_allclose(a.to_numpy(), np.cumsum(a_np, axis=1), rtol=1e-12)
    np.testing.assert_allclose(rows.to_numpy(), a_np.sum(axis=1), rtol=1e-12)


def test_kernel_mixing_top_level_statements_and_several_loops():
    n = 100
    x = ti.field(ti.f32, shape=n)
    total = ti.field(ti.f32, shape=())
    log = ti.field(ti.i32, shape=4)

    @ti.kernel
    def k(scale: ti.f32):
        total[None] = 0  # serial statements between parallel loops run in program order
        log[0] = 1
        for i in x:
            x[i] = i * scale
        log[1] = log[0] + 1
        for i in range(n):
            total[None] += x[i]
        log[2] = ti.cast(total[None], ti.i32)
        for i in range(n // 2):
            x[i] = -x[n - 1 - i]
        log[3] = ti.cast(x[0], ti.i32)

    k(2.0)
    s = sum(i * 2.0 for i in range(n))
    assert total[None] == s
    assert log.to_numpy().tolist() == [1, 2, int(s), -198]
    want = np.arange(n) * 2.0
    want[: n // 2] = -want[::-1][: n // 2]
    np.testing.assert_array_equal(x.to_numpy(), want)


def test_loop_config_serialize_allows_break_in_outermost_loop():
    x = ti.field(ti.i32, shape=10)
    first = ti.field(ti.i32, shape=())

    @ti.kernel
    def k(target: ti.i32):
        first[None] = -1
        ti.loop_config(serialize=True)
        for i in range(10):
            if x[i] == target:
                first[None] = i
                break

    x.from_numpy(np.array([5, 3, 8, 3, 1, 9, 3, 2, 0, 7], np.int32))
    k(3)
    assert first[None] == 1
    k(42)
    assert first[None] == -1


def test_atomic_add_on_globals_under_contention_histogram():
    n, bins = 1_000_000, 10
    data = ti.field(ti.i32, shape=n)
    hist = ti.field(ti.i32, shape=bins)
    fsum = ti.field(ti.f64, shape=())
    rng = np.random.default_rng(6)
    d = rng.integers(0, bins, size=n, dtype=np.int32)
    data.from_numpy(d)

    @ti.kernel
    def k():
        for i in data:
            hist[data[i]] += 1
            fsum[None] += 0.5

    k()
    np.testing.assert_array_equal(hist.to_numpy(), np.bincount(d, minlength=bins))
    assert fsum[None] == n * 0.5


def test_atomic_operations_return_old_value():
    x = ti.field(ti.i32, shape=7)
    old = ti.field(ti.i32, shape=7)
    f = ti.field(ti.f32, shape=3)
    fold = ti.field(ti.f32, shape=3)

    @ti.kernel
    def k():
        for i in ti.static(range(7)):
            x[i] = 12  # 0b1100
        old[0] = ti.atomic_add(x[0], 5)
        old[1] = ti.atomic_sub(x[1], 5)
        old[2] = ti.atomic_min(x[2], 3)
        old[3] = ti.atomic_max(x[3], 30)
        old[4] = ti.atomic_and(x[4], 10)
        old[5] = ti.atomic_or(x[5], 3)
        old[6] = ti.atomic_xor(x[6], 10)
        f[0] = 1.5
        f[1] = 1.5
        f[2] = 1.5
        fold[0] = ti.atomic_add(f[0], 0.25)
        fold[1] = ti.atomic_min(f[1], -2.0)
        fold[2] = ti.atomic_max(f[2], 1.0)

    k()
    assert old.to_numpy().tolist() == [12] * 7
    assert x.to_numpy().tolist() == [17, 7, 3, 30, 12 & 10, 12 | 3, 12 ^ 10]
    assert fold.to_numpy().tolist() == [1.5] * 3
    assert f.to_numpy().tolist() == [1.75, -2.0, 1.5]


def test_atomics_on_locals_and_in_parallel_loops():
    n = 10000
    x = ti.field(ti.i32, shape=n)
    res = ti.field(ti.i32, shape=6)
    x.from_numpy(np.random.default_rng(7).integers(-10**6, 10**6, size=n, dtype=np.int32))

    @ti.kernel
    def k():
        lo = 2**31 - 1
        hi = -2**31
        s = 0
        bits_or = 0
        bits_xor = 0
        bits_and = -1
        for i in x:
            ti.atomic_min(lo, x[i])
            ti.atomic_max(hi, x[i])
            ti.atomic_add(s, x[i] % 7)
            ti.atomic_or(bits_or, x[i] & 0xFF)
            ti.atomic_xor(bits_xor, x[i])
            ti.atomic_and(bits_and, x[i] | 0xF0F0)
        res[0], res[1], res[2] = lo, hi, s
        res[3], res[4], res[5] = bits_or, bits_xor, bits_and

    k()
    xs = x.to_numpy()
    assert res[0] == xs.min() and res[1] == xs.max() and res[2] == int((xs % 7).sum())
    assert res[3] == int(np.bitwise_or.reduce(xs & 0xFF))
    assert res[4] == int(np.bitwise_xor.reduce(xs))
    assert res[5] == int(np.bitwise_and.reduce(xs | 0xF0F0))


def test_parallel_sub_and_minmax_on_globals():
    n = 100_000
    acc = ti.field(ti.i64, shape=3)
    facc = ti.field(ti.f32, shape=2)

    @ti.kernel
    def k():
        acc[1] = 2**40
        acc[2] = -(2**40)
        facc[0] = 1e9
        facc[1] = -1e9
        for i in range(n):
            acc[0] -= i
            ti.atomic_min(acc[1], ti.cast(i, ti.i64) * 3 - 7)
            ti.atomic_max(acc[2], ti.cast(i, ti.i64) * 3 - 7)
            ti.atomic_min(facc[0], i * 0.5 - 3.0)
            facc[1] = ti.max(facc[1], -1e9)  # plain read-modify-write of the same value

    k()
    assert acc.to_numpy().tolist() == [-(n * (n - 1) // 2), -7, 3 * (n - 1) - 7]
    assert facc[0] == -3.0


@pytest.mark.parametrize("t", [ti.i32, ti.f32, ti.f64, ti.u32], ids=str)
def test_reduction_into_local_in_parallel_loop(t):
    n = 300_000

    @ti.kernel
    def k() -> t:
        s = ti.cast(0, t)
        for i in range(n):
            s += ti.cast(i % 4, t)
        return s

    assert k() == sum(i % 4 for i in range(n))


def test_runtime_index_into_local_vectors():
    out = ti.field(ti.f32, shape=4)

    @ti.kernel
    def k(j: ti.i32):
        v = ti.Vector([1.0, 2.0, 3.0])
        for i in range(3):
            v[i] += i * 10  # store through a run-time index
        v *= 2
        out[0] = v[j]  # load through a run-time index
        m = ti.Matrix([[1, 2], [3, 4]])
        for r in range(2):
            m[r, r] = 0
        out[1] = m[1, 0] * 10 + m[j % 2, 1]
        w = ti.Vector([0, 0, 0, 0])
        for i in range(8):
            w[i % 4] += i
        out[2] = w[j]
        out[3] = ti.atomic_add(w[j], 100) + w[j]

    for j in range(3):
        k(j)
        v = (np.array([1.0, 2.0, 3.0]) + np.arange(3) * 10) * 2
        w = [0 + 4, 1 + 5, 2 + 6, 3 + 7]
        mj = [[0, 2], [3, 0]][j % 2][1]
        assert out.to_numpy().tolist() == [v[j], 30 + mj, w[j], w[j] + w[j] + 100]


def test_guarded_ternary_and_bool_ops_are_differentiable():
    """A ternary or bool op whose sides read memory (a branch, or a select when the loads are in bounds:
    frontend/speculate.py): gradients flow."""
    n = 6
    x = ti.field(ti.f32, shape=n, needs_grad=True)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)
    xs = np.arange(n, dtype=np.float32) + 1
    x.from_numpy(xs)

    @ti.kernel
    def k():
        for i in x:
            v = x[i] * 2 if i % 2 == 0 else x[i] * x[i]
            w = i > 2 and x[i] > 4
            loss[None] += v + w

    with ti.ad.Tape(loss):
        k()
    assert loss[None] == sum(xs[i] * 2 if i % 2 == 0 else xs[i] ** 2 for i in range(n)) + 2
    np.testing.assert_array_equal(x.grad.to_numpy(), [2 if i % 2 == 0 else 2 * xs[i] for i in range(n)])


def test_early_returns_from_ti_func_inside_runtime_control_flow():
    """`return` inside run-time if/for/while of a ti.func (Taichi allows it only in real_func): the value and
    a flag are locals at the function's entry, loops of the function are left, the rest is guarded."""
    ti.init(arch=ti.cpu)
    x = ti.field(ti.i32, shape=())

    @ti.func
    def foo(val: ti.i32) -> ti.i32:
        if x[None] > 10:
            if x[None] > 20:
                return 1
            x[None] += 1
        x[None] += val
        return 0

    @ti.func
    def first_over(n: ti.i32, limit: ti.i32) -> ti.i32:
        for i in range(n):
            for j in range(3):
                if i * 3 + j > limit:
                    return i * 10 + j
        return -1

    @ti.func
    def count_to(k: ti.i32) -> ti.i32:
        i = 1
        while i:
            if i == k:
                return i * 100
            i += 1
        return 0

    @ti.kernel
    def run() -> ti.i32:
        return foo(15) * 100 + foo(10) * 10 + foo(100)

    @ti.kernel
    def par(limit: ti.i32) -> ti.i32:
        s = 0
        for n in range(8):
            s += first_over(n, limit) + count_to(n + 1)
        return s

    assert run() == 1 and x[None] == 26

    def first_over_py(n, limit):
        for i in range(n):
            for j in range(3):
                if i * 3 + j > limit:
                    return i * 10 + j
        return -1

    for limit in (0, 7, 30):
        assert par(limit) == sum(first_over_py(n, limit) + (n + 1) * 100 for n in range(8))


def test_early_return_inside_a_ti_static_loop_skips_the_later_iterations():
    """A run-time `return` in one unrolled iteration of a ti.static loop (here inside a while, inside an if)
    ends the function: the later iterations are guarded by the returned flag (fuzz case sfwd:11816:5 returned
    from the last iteration instead), and a ti.static break/continue after the guard is still the static
    loop's."""
    ti.init(arch=ti.cpu)
    a = ti.field(ti.i32, shape=4)
    a.from_numpy(np.array([30, -7, 23, 19], np.int32))
    out = ti.field(ti.i32, shape=(3, 8))

    @ti.func
    def in_while(c):
        for k in ti.static(range(3)):
            w = 0
            while w < 1:
                w += 1
                if c > k:
                    return a[k]
        return 1000

    @ti.func
    def then_static_jumps(c):
        acc = 0
        for k in ti.static(range(4)):
            if c == k:
                return acc * 10 + k
            if ti.static(k == 1):
                continue
            acc += a[k] // 10
            if ti.static(k == 2):
                break
        return acc + 500

    @ti.func
    def in_serial_loop(c):
        s = 0
        for j in range(2):
            for k in ti.static(range(2)):
                if c + j > k + 1:
                    return s * 100 + j * 10 + k
                s += 1
        return s

    @ti.kernel
    def run():
        for c in range(8):
            out[0, c] = in_while(c)
            out[1, c] = then_static_jumps(c)
            out[2, c] = in_serial_loop(c)

    def in_while_py(c):
        for k in range(3):
            if c > k:
                return int(a[k])
        return 1000

    def then_static_jumps_py(c):
        acc = 0
        for k in range(4):
            if c == k:
                return acc * 10 + k
            if k == 1:
                continue
            acc += int(a[k]) // 10
            if k == 2:
                break
        return acc + 500

    def in_serial_loop_py(c):
        s = 0
        for j in range(2):
            for k in range(2):
                if c + j > k + 1:
                    return s * 100 + j * 10 + k
                s += 1
        return s

    run()
    want = [[f(c) for c in range(8)] for f in (in_while_py, then_static_jumps_py, in_serial_loop_py)]
    np.testing.assert_array_equal(out.to_numpy(), want)


def test_returns_at_compile_time_and_their_errors():
    """A return in a taken ti.static branch or unrolled loop ends the function there; a bare return ends a
    kernel without a value; a kernel or ti.func annotated with a return type must return (Taichi's words)."""

    @ti.kernel
    def pick(a: ti.template()) -> ti.i32:
        if ti.static(a == 1):
            return 10
        elif ti.static(a == 2):
            return 20
        return 30

    @ti.kernel
    def squares() -> ti.i32:
        s = 0
        for i in ti.static(range(10)):
            s += i * i
            if ti.static(i == 4):
                return s

    out = ti.field(ti.i32, shape=())

    @ti.kernel
    def bare():
        out[None] = 5
        return

    assert (pick(1), pick(2), pick(7)) == (10, 20, 30)
    assert squares() == sum(i * i for i in range(5))
    bare()
    assert out[None] == 5

    @ti.kernel
    def no_return() -> ti.i32:
        out[None] = 1

    with pytest.raises(ti.TaichiSyntaxError, match="Kernel has a return type but does not have a return"):
        no_return()

    @ti.func
    def f() -> ti.i32:
        out[None] = 2

    @ti.kernel
    def calls_f() -> ti.i32:
        return f()

    with pytest.raises(ti.TaichiCompilationError, match="Function has a return type but does not have a return"):
        calls_f()


def test_template_and_ref_parameters_take_the_callers_variable():
    @ti.func
    def set_one(x: ti.template()):
        x = 1

    @ti.func
    def bump(x: ti.template()):
        x += 1

    @ti.func
    def by_value(x):
        x = 100

    @ti.real_func
    def double(a: ti.ref(ti.f32)):
        a += a

    @ti.kernel
    def run() -> ti.f32:
        a = 0
        set_one(a)
        bump(a)
        by_value(a)
        b = 2.5
        double(b)
        return a * 10.0 + b

    assert run() == 25.0


def test_real_func_rules_and_serial_loops():
    with pytest.raises(ti.TaichiSyntaxError, match="must be type annotated"):

        @ti.real_func
        def add(a, b: ti.i32) -> ti.i32:
            return a + b

    @ti.real_func
    def first_square_over(n: ti.i32) -> ti.i32:
        for i in range(100):  # a real function's loop is serial: returning from it is allowed
            if i * i > n:
                return i
        return -1

    @ti.real_func
    def unannotated(a: ti.i32):
        return a + 1

    @ti.kernel
    def run(n: ti.i32, flag: ti.u1) -> ti.i32:
        r = first_square_over(n)
        if flag:
            r += 1000
        return r

    @ti.kernel
    def bad() -> ti.i32:
        return unannotated(1)

    assert run(50, False) == 8 and run(50, True) == 1008
    with pytest.raises(ti.TaichiCompilationError, match="return value must be annotated"):
        bad()
