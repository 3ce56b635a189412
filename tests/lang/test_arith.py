"""Arithmetic, bit operations, comparisons, casts and type promotion, checked against numpy."""

import numpy as np
import pytest

import simgrad as ti

INT_TYPES = [ti.i8, ti.i16, ti.i32, ti.i64, ti.u8, ti.u32, ti.u64]
N = 64


def _int_operands(t, rng):
    info = np.iinfo(t.np)
    a = rng.integers(info.min, info.max, size=N, dtype=t.np, endpoint=True)
    b = rng.integers(info.min, info.max, size=N, dtype=t.np, endpoint=True)
    # the edges: wrap-around of the extremes, and small values of both signs for // and %
    a[:6] = np.array([info.max, info.min, info.max, 7, 0, 1], dtype=object).astype(t.np)
    b[:6] = np.array([1, info.max, info.max, 2, 3, info.max], dtype=object).astype(t.np)
    if info.min < 0:
        a[6:10] = [-7, 7, -7, -1]
        b[6:10] = [2, -2, -2, 3]
        bad = (a == info.min) & (b == -1)  # INT_MIN // -1 overflows in C and numpy alike
        b[bad] = 1
    b[b == 0] = 1
    return a, b


@pytest.mark.parametrize("t", INT_TYPES, ids=str)
def test_integer_ops_wrap_like_numpy(t):
    rng = np.random.default_rng(1)
    a_np, b_np = _int_operands(t, rng)
    a, b = ti.field(t, shape=N), ti.field(t, shape=N)
    names = ["add", "sub", "mul", "floordiv", "mod", "and", "or", "xor", "neg", "not", "min", "max"]
    out = {k: ti.field(t, shape=N) for k in names}
    cmp = ti.field(ti.i32, shape=(6, N))
    a.from_numpy(a_np)
    b.from_numpy(b_np)

    @ti.kernel
    def k():
        for i in a:
            x, y = a[i], b[i]
            out["add"][i] = x + y
            out["sub"][i] = x - y
            out["mul"][i] = x * y
            out["floordiv"][i] = x // y
            out["mod"][i] = x % y
            out["and"][i] = x & y
            out["or"][i] = x | y
            out["xor"][i] = x ^ y
            out["neg"][i] = -x
            out["not"][i] = ~x
            out["min"][i] = ti.min(x, y)
            out["max"][i] = max(x, y)
            cmp[0, i] = x < y
            cmp[1, i] = x <= y
            cmp[2, i] = x > y
            cmp[3, i] = x >= y
            cmp[4, i] = x == y
            cmp[5, i] = x != y

    k()
    with np.errstate(over="ignore"):
        want = {
            "add": a_np + b_np, "sub": a_np - b_np, "mul": a_np * b_np, "floordiv": a_np // b_np,
            "mod": a_np % b_np, "and": a_np & b_np, "or": a_np | b_np, "xor": a_np ^ b_np,
            "neg": (-a_np.astype(object)).astype(object) % (1 << t.bits), "not": ~a_np,
            "min": np.minimum(a_np, b_np), "max": np.maximum(a_np, b_np),
        }
    want["neg"] = np.array([int(v) - (1 << t.bits) if t.is_signed and v >= 1 << (t.bits - 1) else int(v)
                            for v in want["neg"]], dtype=object).astype(t.np)
    for name in names:
        got = out[name].to_numpy()
        assert got.dtype == t.np, name
        np.testing.assert_array_equal(got, want[name], err_msg=name)
    want_cmp = np.stack([a_np < b_np, a_np <= b_np, a_np > b_np, a_np >= b_np, a_np == b_np, a_np != b_np])
    np.testing.assert_array_equal(cmp.to_numpy(), want_cmp.astype(np.int32))


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_float_ops_like_numpy(t):
    rng = np.random.default_rng(2)
    a_np = (rng.standard_normal(N) * 100).astype(t.np)
    b_np = (rng.standard_normal(N) * 10).astype(t.np)
    a_np[:4] = [-7.5, 7.5, -7.5, 0.1]
    b_np[:4] = [2.0, -2.0, -2.0, 0.03]
    a, b = ti.field(t, shape=N), ti.field(t, shape=N)
    out = ti.field(t, shape=(8, N))
    cmp = ti.field(ti.i32, shape=(6, N))
    a.from_numpy(a_np)
    b.from_numpy(b_np)

    @ti.kernel
    def k():
        for i in a:
            x, y = a[i], b[i]
            out[0, i] = x + y
            out[1, i] = x - y
            out[2, i] = x * y
            out[3, i] = x / y
            out[4, i] = x // y
            out[5, i] = x % y
            out[6, i] = -x
            out[7, i] = ti.min(x, y) + ti.max(x, y)
            cmp[0, i] = x < y
            cmp[1, i] = x <= y
            cmp[2, i] = x > y
            cmp[3, i] = x >= y
            cmp[4, i] = x == y
            cmp[5, i] = x != y

    k()
    got = out.to_numpy()
    assert got.dtype == t.np
    # + - * / of two values of type t are correctly rounded in t: exact agreement with numpy
    for row, want in enumerate([a_np + b_np, a_np - b_np, a_np * b_np, a_np / b_np]):
        np.testing.assert_array_equal(got[row], want, err_msg=str(row))
    np.testing.assert_allclose(got[4], np.floor_divide(a_np, b_np), rtol=0, atol=1)  # floor(a/b) vs fmod
    np.testing.assert_allclose(got[5], np.mod(a_np, b_np), rtol=1e-5, atol=1e-4 * np.abs(b_np).max())
    np.testing.assert_array_equal(got[6], -a_np)
    np.testing.assert_array_equal(got[7], a_np + b_np)
    want_cmp = np.stack([a_np < b_np, a_np <= b_np, a_np > b_np, a_np >= b_np, a_np == b_np, a_np != b_np])
    np.testing.assert_array_equal(cmp.to_numpy(), want_cmp.astype(np.int32))


def test_floordiv_and_mod_follow_python_on_negative_operands():
    """`//` and `%` follow Python (floor division, remainder takes the divisor's sign) for ints and floats:
    -7 // 2 == -4 and -7 % 2 == 1. C truncation is available as ti.raw_div / ti.raw_mod.

    We follow Python deliberately. (Checked against Taichi 1.7.4 on x64: it gives the same numbers for
    field operands in a parallel loop, -7 // 2 == -4, -7.5 % -2 == -1.5, so no difference here.)"""
    pairs = [(-7, 2), (7, -2), (-7, -2), (7, 2), (-6, 3), (0, -5), (-1, 1000), (2**31 - 1, -1)]
    n = len(pairs)
    ia, ib = ti.field(ti.i32, shape=n), ti.field(ti.i32, shape=n)
    fa, fb = ti.field(ti.f64, shape=n), ti.field(ti.f64, shape=n)
    iq, ir = ti.field(ti.i32, shape=n), ti.field(ti.i32, shape=n)
    fq, fr = ti.field(ti.f64, shape=n), ti.field(ti.f64, shape=n)
    ia.from_numpy(np.array([p[0] for p in pairs], np.int32))
    ib.from_numpy(np.array([p[1] for p in pairs], np.int32))
    fa.from_numpy(np.array([p[0] + 0.5 for p in pairs], np.float64))
    fb.from_numpy(np.array([p[1] for p in pairs], np.float64))

    @ti.kernel
    def k():
        for i in range(n):
            iq[i] = ia[i] // ib[i]
            ir[i] = ia[i] % ib[i]
            fq[i] = fa[i] // fb[i]
            fr[i] = fa[i] % fb[i]

    k()
    assert iq.to_numpy().tolist() == [a // b for a, b in pairs]
    assert ir.to_numpy().tolist() == [a % b for a, b in pairs]
    assert fq.to_numpy().tolist() == [(a + 0.5) // b for a, b in pairs]
    np.testing.assert_allclose(fr.to_numpy(), [(a + 0.5) % b for a, b in pairs], rtol=1e-12, atol=1e-9)


def test_floordiv_mod_with_literals_and_raw_ops():
    @ti.kernel
    def k(a: ti.i32, b: ti.i32) -> ti.math.ivec4:
        return ti.math.ivec4(a // b, a % b, ti.raw_div(a, b), ti.raw_mod(a, b))

    assert list(k(-7, 2)) == [-4, 1, -3, -1]  # raw_div/raw_mod are C's truncating ops
    assert list(k(7, -2)) == [-4, -1, -3, 1]
    assert list(k(9, 3)) == [3, 0, 3, 0]

    @ti.kernel
    def fk(a: ti.f64, b: ti.f64) -> ti.f64:
        return ti.raw_div(a, b)

    assert fk(-7.5, 2.0) == -3.75

    @ti.kernel
    def fmod(a: ti.f64, b: ti.f64) -> ti.f64:
        return ti.raw_mod(a, b)

    with pytest.raises(TypeError, match="raw_mod needs integer operands"):  # Taichi 1.7.4 aborts in LLVM
        fmod(-7.5, 2.0)

    @ti.kernel
    def lit(x: ti.i32) -> ti.math.ivec2:
        return ti.math.ivec2(x // -3, -x % 5)

    assert list(lit(10)) == [10 // -3, -10 % 5]
    assert list(lit(7)) == [7 // -3, -7 % 5]


def test_true_division_is_always_floating():
    r = ti.field(ti.f32, shape=4)
    r64 = ti.field(ti.f64, shape=2)

    @ti.kernel
    def k(a: ti.i32, b: ti.i32, c: ti.i64):
        q = a / b  # int/int -> default fp
        r[0] = q
        r[1] = 7 / 2  # two literals: folded in Python
        r[2] = a / 4
        r[3] = ti.cast(q == 3.5, ti.f32)
        r64[0] = c / 3
        r64[1] = 1 / c

    k(7, 2, 9)
    np.testing.assert_array_equal(r.to_numpy(), np.float32([3.5, 3.5, 1.75, 1.0]))
    np.testing.assert_allclose(r64.to_numpy(), [3.0, 1 / 9], rtol=1e-6)

    @ti.kernel
    def typ(a: ti.i32, b: ti.i32) -> ti.f64:
        return a / b  # f32 division (default_fp) widened only at the return

    assert typ(1, 3) == float(np.float32(1) / np.float32(3))


def test_true_division_uses_default_fp_f64():
    ti.init(arch=ti.cpu, default_fp=ti.f64)

    @ti.kernel
    def typ(a: ti.i32, b: ti.i32) -> ti.f64:
        return a / b

    assert typ(1, 3) == 1 / 3


def test_division_by_zero_does_not_crash():
    """Integer division or modulo by zero gives an unspecified value but never traps the process."""
    out = ti.field(ti.i32, shape=4)
    f = ti.field(ti.f32, shape=2)

    @ti.kernel
    def k(a: ti.i32, b: ti.i32):
        out[0] = a // b
        out[1] = a % b
        out[2] = ti.raw_div(a, b)
        out[3] = ti.raw_mod(a, b)
        f[0] = a / b
        f[1] = ti.cast(a, ti.f32) / ti.cast(b, ti.f32)

    k(5, 0)
    k(-2**31, -1)  # the other trapping case of x86 idiv: the quotient wraps, the remainder is 0
    assert out.to_numpy().tolist() == [-2**31, 0, -2**31, 0]
    k(6, 3)
    assert out.to_numpy().tolist() == [2, 0, 2, 0]
    k(5, 0)
    assert np.isinf(f.to_numpy()).all()


def test_shifts_and_logical_shift_right():
    out = ti.field(ti.i32, shape=6)
    u = ti.field(ti.u32, shape=2)
    i8 = ti.field(ti.i8, shape=2)

    @ti.kernel
    def k(x: ti.i32, s: ti.i32):
        out[0] = x << s
        out[1] = x >> s  # arithmetic for signed
        out[2] = ti.bit_shr(x, s)  # logical
        out[3] = x << 3
        out[4] = 1 << s
        out[5] = ti.bit_shr(x | -16, 28)
        u[0] = ti.cast(x, ti.u32) >> s  # unsigned: logical
        u[1] = ti.cast(x, ti.u32) << s
        i8[0] = ti.bit_shr(ti.cast(x, ti.i8), 1)
        i8[1] = ti.cast(x, ti.i8) >> 1

    k(-100, 4)
    assert out.to_numpy().tolist() == [-1600, -100 >> 4, (-100 & 0xFFFFFFFF) >> 4, -800, 16, 15]
    assert u.to_numpy().tolist() == [(-100 & 0xFFFFFFFF) >> 4, (-100 << 4) & 0xFFFFFFFF]
    assert i8.to_numpy().tolist() == [(-100 & 0xFF) >> 1, -100 >> 1]


def test_comparisons_and_not_give_0_or_1_and_or_give_python_values():
    """Comparisons and `not` give i32 1/0; `a and b` / `a or b` give Python's (and Taichi's) values:
    b if a else a / a if a else b, promoted like a + b."""
    out = ti.field(ti.i32, shape=9)

    @ti.kernel
    def k(a: ti.i32, b: ti.i32):
        out[0] = a and b
        out[1] = a or b
        out[2] = not a
        out[3] = not b
        out[4] = (a > 1) and (b > 1)
        out[5] = (a > 1) or (b > 1)
        out[6] = 0 < a < 10  # chained comparison
        out[7] = a == 3
        out[8] = ti.logical_or(ti.logical_not(a), b < 0)

    for a, b in [(3, 2), (0, 2), (3, 0), (0, 0), (-5, -7)]:
        k(a, b)
        want = [a and b, a or b, int(not a), int(not b), int(a > 1 and b > 1), int(a > 1 or b > 1),
                int(0 < a < 10), int(a == 3), int(not a or b < 0)]
        assert out.to_numpy().tolist() == want, (a, b)

    @ti.kernel
    def mixed(a: ti.i32, b: ti.i64, f: ti.f64) -> ti.f64:
        return (a and b) + (f or a) * 0.5 + (a and 7 or 9) * 1000

    for a, b, f in [(3, 2**40, 0.0), (0, 5, 1.5), (2, 0, -2.5)]:
        assert mixed(a, b, f) == (a and b) + (f or a) * 0.5 + (a and 7 or 9) * 1000


def test_and_or_short_circuit_guards_memory_reads():
    """The right operand is not evaluated when the left decides (a guard like `i < n and x[i] > 0`):
    checked in debug mode, where evaluating x[5] would raise an IndexError."""
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.i32, shape=3)
    x.from_numpy(np.array([4, 0, 6], np.int32))
    hits = ti.field(ti.i32, shape=())

    @ti.kernel
    def k(i: ti.i32) -> ti.i32:
        a = i < 3 and x[i] > 0
        b = i >= 3 or x[i] == 0
        c = x[i] if i < 3 else -1
        d = 0
        j = i
        while j < 3 and x[j] != 0:
            d += 1
            j += 2
        return a * 1000 + b * 100 + c * 10 + d

    def ref(i):
        xs = [4, 0, 6]
        a = i < 3 and xs[i] > 0
        b = i >= 3 or xs[i] == 0
        c = xs[i] if i < 3 else -1
        d = 0
        while i < 3 and xs[i] != 0:
            d += 1
            i += 2
        return a * 1000 + b * 100 + c * 10 + d

    for i in range(6):
        assert k(i) == ref(i), i

    @ti.kernel
    def effects(i: ti.i32) -> ti.i32:
        r = i > 0 and ti.atomic_add(hits[None], 1) >= 0  # the atomic runs only when i > 0
        return r

    effects(0)
    effects(1)
    effects(-3)
    effects(2)
    assert hits[None] == 2


def test_ternary_and_select():
    out = ti.field(ti.f32, shape=(3, 8))

    @ti.kernel
    def k():
        for i in range(8):
            out[0, i] = i * 2 if i % 2 == 0 else -i
            out[1, i] = ti.select(i > 3, 1.5, -1)
            v = ti.select(ti.Vector([i, -i]) > 0, ti.Vector([1.0, 2.0]), ti.Vector([3.0, 4.0]))
            out[2, i] = v[0] * 10 + v[1]

    k()
    i = np.arange(8)
    np.testing.assert_array_equal(out.to_numpy()[0], np.where(i % 2 == 0, i * 2, -i))
    np.testing.assert_array_equal(out.to_numpy()[1], np.where(i > 3, 1.5, -1))
    np.testing.assert_array_equal(out.to_numpy()[2], np.where(i > 0, 10, 30) + np.where(-i > 0, 2, 4))


def test_casts():
    fo = ti.field(ti.f32, shape=4)
    io = ti.field(ti.i32, shape=8)
    u8 = ti.field(ti.u8, shape=2)

    @ti.kernel
    def k(x: ti.f32, n: ti.i32):
        io[0] = int(x)  # truncation toward zero
        io[1] = ti.cast(x, ti.i32)
        io[2] = ti.i32(x)
        io[3] = ti.floor(x, ti.i32)
        io[4] = ti.ceil(x, int)
        io[5] = ti.cast(ti.cast(n, ti.i8), ti.i32)  # wraps
        io[6] = ti.cast(ti.cast(n, ti.u8), ti.i32)
        io[7] = ti.bit_cast(x, ti.i32)
        fo[0] = float(n)
        fo[1] = ti.cast(n, ti.f32) / 2
        fo[2] = n / 2
        fo[3] = ti.cast(ti.cast(n, ti.u32), ti.f32)
        u8[0] = n
        u8[1] = ti.cast(x, ti.u8)

    k(-2.75, 300)
    want = [-2, -2, -2, -3, -2, np.int8(np.int32(300).astype(np.int8)), 300 % 256,
            np.float32(-2.75).view(np.int32)]
    assert io.to_numpy().tolist() == [int(v) for v in want]
    np.testing.assert_array_equal(fo.to_numpy(), [300.0, 150.0, 150.0, 300.0])
    assert u8.to_numpy()[0] == 300 % 256
    k(2.75, -1)
    assert io.to_numpy()[:5].tolist() == [2, 2, 2, 2, 3]
    assert fo.to_numpy()[3] == np.float32(2**32 - 1)
    assert u8.to_numpy().tolist() == [255, 2]


def test_type_promotion():
    @ti.kernel
    def k(a: ti.i32, b: ti.f32, c: ti.f64, d: ti.i64, e: ti.u32) -> ti.f64:
        # each probe is 1/3 computed in the promoted type: f32 gives 0.3333333432674408
        r = 0.0
        s = a + b  # i32 + f32 -> f32
        r += (s / 3 - 1 / 3) * 0 + s / 3  # f32 division: rounded to f32
        return r

    got = k(0, 1.0, 0.0, 0, 0)
    assert got == float(np.float32(1) / np.float32(3))

    out = ti.field(ti.f64, shape=6)
    iout = ti.field(ti.i64, shape=3)

    @ti.kernel
    def p(a: ti.i32, b: ti.f32, c: ti.f64, d: ti.i64, e: ti.u32):
        out[0] = (a + b) / 3  # f32
        out[1] = (b + c) / 3  # f64 wins
        out[2] = (a + c) / 3  # f64
        out[3] = (d + b) / 3  # f32 (float wins over any int)
        out[4] = c / 3  # int literal adopts f64
        out[5] = b * 0.1  # float literal adopts f32
        iout[0] = a + d  # i32 + i64 -> i64: no wrap
        iout[1] = e + a  # u32 + i32 -> u32 wraps at 2**32
        iout[2] = d * 3

    p(0, 1.0, 1.0, 2**40, 2**32 - 1)
    third32 = float(np.float32(1) / np.float32(3))
    o = out.to_numpy()
    assert o[0] == third32
    assert o[1] == 2 / 3
    assert o[2] == 1 / 3
    assert o[3] == float((np.float32(2**40) + np.float32(1)) / np.float32(3))
    assert o[4] == 1 / 3
    assert o[5] == float(np.float32(1) * np.float32(0.1))
    p(2**31 - 1, 1.0, 1.0, 2**40, 2**32 - 1)
    assert iout.to_numpy().tolist() == [2**31 - 1 + 2**40, (2**32 - 1 + 2**31 - 1) % 2**32, 3 * 2**40]


def test_int_literal_with_float_value_stays_float():
    out = ti.field(ti.f64, shape=3)

    @ti.kernel
    def k(x: ti.f64):
        y = x * 3  # 3 adopts f64
        out[0] = y
        out[1] = x + 16777217  # 2**24 + 1 is exact in f64, not in f32
        out[2] = 2 ** -1 * x

    k(0.1)
    assert out.to_numpy().tolist() == [0.1 * 3, 0.1 + 16777217, 0.05]


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_float_precision_of_locals_and_fields(t):
    out = ti.field(t, shape=2)

    @ti.kernel
    def k():
        s = ti.cast(0.0, t)
        for _ in range(10):
            s += ti.cast(0.1, t)
        out[0] = s
        out[1] = ti.cast(1.0, t) + ti.cast(1e-8, t)

    k()
    s = t.np.type(0)
    for _ in range(10):
        s = t.np.type(s + t.np.type(0.1))
    assert out.to_numpy()[0] == s
    assert out.to_numpy()[1] == t.np.type(1.0) + t.np.type(1e-8)
    assert (out.to_numpy()[1] == 1.0) == (t is ti.f32)


@pytest.mark.parametrize("t", [ti.i8, ti.u8, ti.i16, ti.u32], ids=str)
def test_small_int_locals_wrap(t):
    out = ti.field(t, shape=3)

    @ti.kernel
    def k(n: ti.i32):
        x = ti.cast(0, t)
        for _ in range(n):
            x += 1
        out[0] = x
        y = ti.cast(n, t)
        y *= 3
        out[1] = y
        out[2] = x - 1 - n

    k(300)
    with np.errstate(over="ignore"):
        x = t.np.type(300 % 2**t.bits if not t.is_signed else np.int64(300).astype(t.np))
        want = [x, t.np.type(np.int64(900).astype(t.np)), np.int64(int(x) - 1 - 300).astype(t.np)]
    assert out.to_numpy().tolist() == [int(w) for w in want]


def test_local_typed_at_first_assignment_truncates():
    out = ti.field(ti.f32, shape=4)

    @ti.kernel
    def k(x: ti.f32):
        a = 1  # i32 local
        a = x  # a float assigned to it truncates toward zero
        b = 1.0
        b = 3  # stays f32
        c = 0
        c += x  # augmented assignment also keeps the type
        d: ti.f32 = 2  # annotated local
        d /= 4
        out[0] = a
        out[1] = b / 2
        out[2] = c
        out[3] = d

    k(-2.7)
    np.testing.assert_array_equal(out.to_numpy(), np.float32([-2, 1.5, -2, 0.5]))


def test_augmented_assignment_operators():
    out = ti.field(ti.i32, shape=10)
    fo = ti.field(ti.f32, shape=3)

    @ti.kernel
    def k(v: ti.i32):
        for i in ti.static(range(10)):
            out[i] = 100
        out[0] += v
        out[1] -= v
        out[2] *= v
        out[3] //= v
        out[4] %= v
        out[5] &= v
        out[6] |= v
        out[7] ^= v
        out[8] <<= 2
        out[9] >>= 2
        x = 5
        x **= 2
        fo[0] = x
        y = 7.0
        y /= 2
        fo[1] = y
        z = 2.0
        z **= 0.5
        fo[2] = z

    k(-7)
    assert out.to_numpy().tolist() == [93, 107, -700, 100 // -7, 100 % -7, 100 & -7, 100 | -7, 100 ^ -7,
                                       400, 25]
    np.testing.assert_allclose(fo.to_numpy(), [25, 3.5, np.sqrt(2)], rtol=1e-6)


def test_python_scope_constant_folding_matches_runtime():
    """Literal-only expressions fold in Python; the same expression on run-time values must agree."""
    out = ti.field(ti.i32, shape=(2, 4))

    @ti.kernel
    def k(a: ti.i32, b: ti.i32):
        out[0, 0] = -7 // 2
        out[0, 1] = -7 % 2
        out[0, 2] = 7 // -2
        out[0, 3] = 2 ** 10
        out[1, 0] = a // b
        out[1, 1] = a % b
        out[1, 2] = -a // -b
        out[1, 3] = b ** 10

    k(-7, 2)
    assert out.to_numpy().tolist() == [[-4, 1, -4, 1024], [-4, 1, -4, 1024]]


def test_integer_power():
    out = ti.field(ti.i64, shape=4)
    fo = ti.field(ti.f32, shape=2)

    @ti.kernel
    def k(x: ti.i64, n: ti.i32):
        out[0] = x ** 3
        out[1] = x ** n
        out[2] = 3 ** n
        out[3] = x ** 0
        fo[0] = ti.cast(x, ti.f32) ** -1
        fo[1] = ti.pow(ti.cast(x, ti.f32), 2)

    @ti.kernel
    def negative(x: ti.i64):
        fo[0] = x ** -1  # Taichi 1.7.4: "Negative exponent in pow(int, int) is not allowed." when compiling

    k(-3, 5)
    assert out.to_numpy().tolist() == [-27, -243, 243, 1]
    np.testing.assert_allclose(fo.to_numpy(), [-1 / 3, 9], rtol=1e-6)
    k(1000, 5)
    assert out.to_numpy()[:2].tolist() == [10**9, 10**15]
    with pytest.raises(ti.TaichiRuntimeError, match=r"Negative exponent in pow\(int, int\)"):
        negative(3)


def test_int_literals_promote_like_taichi():
    """An int literal is default_ip (i32) promoted with the value it meets, as in Taichi 1.7.4: with a u8
    value the result is i32 (no u8 wrap-around); with i64/u32 values the wider/unsigned type wins; with a
    float value the literal takes the float type. (Checked against Taichi 1.7.4.)"""
    o = ti.field(ti.f64, shape=10)

    @ti.kernel
    def k(e: ti.u8, c: ti.i8, h: ti.i16, f: ti.f32, w: ti.u32, n: ti.i64):
        o[0] = e * 10000
        o[1] = c * 1000
        o[2] = h + 40000
        o[3] = f * 16777217  # the literal becomes f32: 2**24 + 1 rounds to 2**24
        o[4] = e - 4
        o[5] = w - 4  # u32 wins over i32: wraps
        o[6] = e + e * 200
        o[7] = e < 300  # compared as i32, not after wrapping 300 to u8
        o[8] = n * 2**31  # i64 stays i64
        x = e
        x += 300  # a u8 local stays u8
        o[9] = x

    k(3, 3, 3, 1.0, 3, 3)
    assert o.to_numpy().tolist() == [30000, 3000, 40003, 2**24, -1, 2**32 - 1, 603, 1, 3 * 2**31, 47]


@pytest.mark.parametrize("t", [ti.i32, ti.i64])
def test_floordiv_mod_by_constant_powers_of_two_are_python_floor(t):
    """x // 2**k and x % 2**k by a literal compile to a shift and a mask: Python's values for negative x
    and at the type's extremes, as numpy computes them."""
    bits = 32 if t == ti.i32 else 64
    np_t = np.int32 if t == ti.i32 else np.int64
    xs = np.array([-(2 ** (bits - 1)), -(2 ** (bits - 1)) + 1, -9, -8, -7, -5, -4, -3, -1, 0, 1, 3, 4, 7, 8, 9,
                   2 ** (bits - 1) - 1], np_t)
    x = ti.field(t, shape=len(xs))
    out = ti.field(t, shape=(len(xs), 10))
    x.from_numpy(xs)

    @ti.kernel
    def k():
        for i in x:
            out[i, 0], out[i, 1] = x[i] // 1, x[i] % 1
            out[i, 2], out[i, 3] = x[i] // 4, x[i] % 4
            out[i, 4], out[i, 5] = x[i] // 8, x[i] % 8
            out[i, 6], out[i, 7] = x[i] // 1024, x[i] % 1024
            out[i, 8], out[i, 9] = x[i] // (2 ** 30), x[i] % (2 ** 30)

    k()
    want = np.stack([f(xs, np_t(d)) for d in (1, 4, 8, 1024, 2 ** 30) for f in (np.floor_divide, np.mod)], 1)
    np.testing.assert_array_equal(out.to_numpy(), want)
