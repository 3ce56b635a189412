"""Debug mode's integer overflow reports, as Taichi 1.7.4 prints them (its runtime's debug_add/sub/mul/shl):
`<Op> overflow detected in File "...", line N, in <function>:` then the source line and carets, on stdout;
the kernel goes on with the wrapped value. Only the + - * << the user wrote are checked, only with debug=True."""

import pytest

import simgrad as ti

_TYPES = [ti.i8, ti.u8, ti.i16, ti.u16, ti.i32, ti.u32, ti.i64, ti.u64]


def _run(capfd, fn, *args):
    capfd.readouterr()
    r = fn(*args)
    return r, capfd.readouterr().out


@pytest.mark.parametrize("t", _TYPES, ids=str)
def test_add_sub_mul_shl_overflow_reported_with_line(capfd, t):
    ti.init(arch=ti.cpu, debug=True)
    bits = t.bits - (1 if t.is_signed else 0)  # the value bits

    @ti.kernel
    def add(x: t, y: t) -> t:
        return x + y

    @ti.kernel
    def sub(x: t, y: t) -> t:
        return x - y

    @ti.kernel
    def mul(x: t, y: t) -> t:
        return x * y

    @ti.kernel
    def shl(x: t, y: t) -> t:
        return x << y

    half = 2 ** (bits - 1)
    r, out = _run(capfd, add, half, half)
    assert "Addition overflow detected in File" in out and "return x + y" in out and ", in add:" in out
    m = 2**t.bits
    assert r == ((2 * half + m // 2) % m - m // 2 if t.is_signed else 2 * half % m)  # the wrapped value
    lo, hi = (-half, half + 1) if t.is_signed else (1, 2)
    _, out = _run(capfd, sub, lo, hi)
    assert "Subtraction overflow detected" in out and "return x - y" in out
    _, out = _run(capfd, mul, 2 ** (bits // 2) + 1, 2 ** (bits - bits // 2) + 1)
    assert "Multiplication overflow detected" in out and "return x * y" in out
    _, out = _run(capfd, shl, 2, bits - 1)
    assert "Shift left overflow detected" in out and "return x << y" in out
    # just inside the range: nothing printed
    for fn, a, b in ((add, half, half - 1), (sub, -half, half) if t.is_signed else (sub, 2, 2),
                     (mul, 2 ** (bits - bits // 2) + 1, 2 ** (bits // 2) - 1), (shl, 2, bits - 2)):
        _, out = _run(capfd, fn, a, b)
        assert "overflow" not in out, (fn, a, b)


def test_report_text_matches_taichi(capfd):
    ti.init(arch=ti.cpu, debug=True)

    @ti.kernel
    def foo(x: ti.i32) -> ti.i32:
        a = ti.i32(x)
        b = ti.i32(1073741824)
        return a + b

    r, out = _run(capfd, foo, 1073741824)
    assert r == -2147483648
    assert out.startswith(f'Addition overflow detected in File "{__file__}", line ')
    text = out.split(", line ", 1)[1]
    assert text.split("\n", 1)[0].endswith(", in foo:")
    assert text.split("\n", 1)[1] == "        return a + b\n               ^^^^^\n\n"


def test_no_report_without_debug(capfd):
    @ti.kernel
    def foo(x: ti.i32) -> ti.i32:
        return x + 1073741824

    r, out = _run(capfd, foo, 1073741824)
    assert r == -2147483648 and out == ""


def test_simgrads_own_arithmetic_is_not_checked(capfd):
    """An integer power's squarings overflow on purpose, an index's offset is simgrad's: no report; a report
    from a parallel loop names the loop body's line."""
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.i32, shape=8)

    @ti.kernel
    def k(e: ti.i32) -> ti.i32:
        for i in x:
            x[i] = 3 ** e
        return x[7]

    @ti.kernel
    def big():
        for i in x:
            x[i] = i * 1000000000

    r, out = _run(capfd, k, 3)
    assert r == 27 and out == ""
    _, out = _run(capfd, big)
    assert out.count("Multiplication overflow detected") == 5  # i = 3 .. 7
    assert "x[i] = i * 1000000000" in out


def test_report_only_where_the_code_runs(capfd):
    """A loop-invariant product in a parallel loop stays in the loop (passes/hoist.py): no iteration, no
    report; one per iteration that computes it otherwise."""
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.i32, shape=4)

    @ti.kernel
    def k(n: ti.i32, a: ti.i32):
        for i in range(n):
            x[i] = a * a

    _, out = _run(capfd, k, 0, 100000)
    assert out == ""
    _, out = _run(capfd, k, 3, 100000)
    assert out.count("Multiplication overflow detected") == 3


def test_augmented_multiplication_is_checked(capfd):
    """`a *= 3` and `x[i] *= 4` are plain updates (load, multiply, store): reported with the statement, as
    Taichi does (taichi names the second a shift: it strength-reduces * 4); `x[i] += v` is an atomic, unchecked
    in both."""
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.i32, shape=2)

    @ti.kernel
    def foo(v: ti.i32) -> ti.i32:
        a = v
        a *= 3
        x[0] += v
        x[1] = v
        x[1] *= 4
        return a

    r, out = _run(capfd, foo, 1073741824)
    assert r == -1073741824
    assert out.count("Multiplication overflow detected") == 2
    assert "        a *= 3\n        ^^^^^^\n" in out and "        x[1] *= 4\n        ^^^^^^^^^\n" in out
