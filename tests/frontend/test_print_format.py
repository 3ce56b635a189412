"""Format specs in kernel print (Taichi's printf-style specs) and formatted assert messages.

Kernel prints go through the C library's printf; the reference is Python's own printf-style `%`
formatting of the same values (f32 values rounded to f32 first, as the kernel holds them)."""

# the kernels use str.format and % on purpose: they are what is tested
# ruff: noqa: UP030, UP031, UP032, F522, F523, F524, F525

import inspect
import re

import numpy as np
import pytest

import simgrad as ti


def _out(capfd) -> str:
    return capfd.readouterr().out


def _c(spec: str, value, kind: str) -> str:
    """printf of `value` (kind: 'i' signed, 'u' unsigned, 'f' f32, 'd' f64) under a Taichi spec, by
    Python's % operator: no conversion means the type's own (d, u, f; f64 keeps 12 digits)."""
    conv = spec[-1] if spec[-1:].isalpha() else {"i": "d", "u": "d", "f": "f", "d": "f"}[kind]
    body = spec[:-1] if spec[-1:].isalpha() else spec
    if kind == "d" and "." not in body:
        body += ".12"
    if conv == "u":
        conv = "d"
    return ("%" + body + conv) % value


def _fields(var: str, specs) -> str:
    return "|".join(f"{{{var}:{s}}}" for s in specs)


def _check_source(kernel, text: str) -> None:
    # the kernel's f-string must be the one the expectation is built from
    assert text in inspect.getsource(kernel)


I32_SPECS = ["d", "5d", "-5d", "+d", "05d", ".10d", ".2", "i", "8", "hd", "lld"]
U32_SPECS = ["u", "x", "#x", "X", "o", "012x", "-12u", "llx"]
I64_SPECS = ["d", "+022d", ".3"]
U64_SPECS = ["u", "x", "#X"]


def test_integer_specs_match_printf(capfd):
    @ti.kernel
    def k(a: ti.i32, u: ti.u32, l: ti.i64, w: ti.u64):
        print(f"{a:d}|{a:5d}|{a:-5d}|{a:+d}|{a:05d}|{a:.10d}|{a:.2}|{a:i}|{a:8}|{a:hd}|{a:lld}")
        print(f"{u:u}|{u:x}|{u:#x}|{u:X}|{u:o}|{u:012x}|{u:-12u}|{u:llx}")
        print(f"{l:d}|{l:+022d}|{l:.3}")
        print(f"{w:u}|{w:x}|{w:#X}")

    for var, specs in (("a", I32_SPECS), ("u", U32_SPECS), ("l", I64_SPECS), ("w", U64_SPECS)):
        _check_source(k, _fields(var, specs))
    for a in (-42, 7):
        u, l, w = 3_000_000_000, -(2**40) - 3, 2**64 - 1
        k(a, u, l, w)
        expect = ["|".join(_c(s.replace("hd", "d").replace("ll", ""), v, kind) for s in specs)
                  for v, kind, specs in ((a, "i", I32_SPECS), (u, "u", U32_SPECS), (l, "i", I64_SPECS),
                                         (w, "u", U64_SPECS))]
        assert _out(capfd).splitlines() == expect
    k(3, 1, 1, 1)
    assert _out(capfd).splitlines()[0].split("|")[5] == "0000000003"  # Taichi's own expectation


F32_SPECS = [".2f", "e", ".3e", "10.4f", "-10.2f", "+.1f", "g", ".3G", ".1", "E", "012.3f", "F", "lf"]
F64_SPECS = ["f", "e", ".3", "g", "20.15f"]


def test_float_specs_match_printf(capfd):
    @ti.kernel
    def k(f: ti.f32, d: ti.f64):
        print(f"{f:.2f}|{f:e}|{f:.3e}|{f:10.4f}|{f:-10.2f}|{f:+.1f}|{f:g}|{f:.3G}|{f:.1}|{f:E}|{f:012.3f}|{f:F}|{f:lf}")
        print(f"{d:f}|{d:e}|{d:.3}|{d:g}|{d:20.15f}")

    _check_source(k, _fields("f", F32_SPECS))
    _check_source(k, _fields("d", F64_SPECS))
    for f, d in ((233.3, 0.1), (-4.286326e-03, -12345.678901234)):
        k(f, d)
        f32 = float(np.float32(f))
        assert _out(capfd).splitlines() == [
            "|".join(_c(s.replace("lf", "f"), f32, "f") for s in F32_SPECS),
            "|".join(_c(s, d, "d") for s in F64_SPECS),
        ]


def test_small_int_types_and_python_alignment(capfd):
    @ti.kernel
    def k(a: ti.i8, b: ti.u8, c: ti.i16, e: ti.u16, x: ti.i32, f: ti.f32):
        print(f"{a:4d}|{b:x}|{c:+d}|{e:o}|{x:<6d}|{x:>6d}|{f:<9.2f}|")

    k(-5, 250, -300, 65000, 42, 1.5)
    assert _out(capfd).rstrip("\n") == "%4d|%x|%+d|%o|%-6d|%6d|%-9.2f|" % (-5, 250, -300, 65000, 42, 42, 1.5)


def test_matrix_specs_apply_entry_by_entry(capfd):
    @ti.kernel
    def k(s: ti.f32):
        m = ti.Matrix([[2e1, 3e2, 4e3], [5e4, 6e5, 7e6]], ti.f32) * s
        v = ti.Vector([1, -2, 3])
        print(f"m = {m:.1f}", "m = {:e}".format(m))
        print(f"v = {v:+04d}", "{:.3}".format(v))

    k(1.5)
    rows = [[2e1 * 1.5, 3e2 * 1.5, 4e3 * 1.5], [5e4 * 1.5, 6e5 * 1.5, 7e6 * 1.5]]

    def mat(spec, m):
        return "[" + ", ".join("[" + ", ".join(spec % x for x in r) + "]" for r in m) + "]"

    def vec(spec, v):
        return "[" + ", ".join(spec % x for x in v) + "]"

    out = _out(capfd).splitlines()
    assert out[0] == f"m = {mat('%.1f', rows)} m = {mat('%e', rows)}"
    assert out[1] == f"v = {vec('%+04d', [1, -2, 3])} {vec('%.3d', [1, -2, 3])}"


def test_str_format_fields(capfd):
    @ti.kernel
    def k(a: ti.i32, f: ti.f32):
        print("{0} {1} {2}".format(a, 2, f))
        print("{2} {1} {}".format(3, 2, a))
        print("{2} {} {1} {k} {0} {k}".format(3, a, 1, k=f))
        print("{:.2} {name:i} {value:.3f} {{literal}} {} 100%".format(f, a, name=999, value=f))
        print("{:i} {:.1} {:.10d} {} {} {}".format(1, 2, 3, True, 1.25, "text"))

    k(7, 233.3)
    f = float(np.float32(233.3))
    assert _out(capfd).splitlines() == [
        "7 2 %f" % f,
        "7 2 3",  # `{}` counts from 0 whatever the numbered fields (as Taichi)
        "1 3 7 %f 3 %f" % (f, f),
        "%.2f 999 %.3f {literal} 7 100%%" % (f, f),
        "1 2 0000000003 True 1.25 text",
    ]


def test_fstring_constants_and_escapes(capfd):
    @ti.kernel
    def k(i: ti.i32):
        print(f"[{4:.3d}] [{1.23:.1f}] {{{i}}} [{i=}] {4} {True} {1.23} {'s'!r}")

    k(3)
    assert _out(capfd).strip() == "[004] [1.2] {3} [i=3] 4 True 1.23 's'"


def test_percent_formatting_in_print(capfd):
    @ti.kernel
    def k(i: ti.i32, f: ti.f32, u: ti.u32):
        print("%d|%5.2f|%x|%.3d|%%|%d|%e" % (i, f, u, i, f, i))
        print("static %d %s" % (3, "x"))

    k(-7, 2.75, 255)
    assert _out(capfd).splitlines() == ["%d|%5.2f|%x|%.3d|%%|%d|%e" % (-7, 2.75, 255, -7, 2, -7.0), "static 3 x"]


# -- compile-time errors, with Taichi's wording, located at the print ------------------------------------
def _located(info, text: str) -> None:
    msg = str(info.value)
    assert __file__ in msg and text in msg


def test_spec_type_mismatch_errors():
    @ti.func
    def plus1(x):
        return x + 1

    @ti.kernel
    def bad_u(i: ti.i32):
        print("{:u}".format(plus1(i)))

    @ti.kernel
    def bad_d(u: ti.u32):
        print(f"{plus1(u):d}")

    @ti.kernel
    def bad_i(f: ti.f32):
        print("{:i}".format(plus1(f)))

    @ti.kernel
    def bad_matrix():
        print("{:- #0.233lli} world".format(ti.Vector([1.0, 2.0])))

    @ti.kernel
    def bad_e():
        print(f"hello {ti.Vector([1, 2]):.2e} world!")

    @ti.kernel
    def bad_x(i: ti.i32):
        print(f"{i:x}")  # Taichi: x/X/o only for unsigned values

    @ti.kernel
    def bad_float_literal():
        print("{:.3f}".format(2))

    cases = [(bad_u, (1,), "'u' doesn't match 'i32'.", 'print("{:u}".format(plus1(i)))'),
             (bad_d, (1,), "'d' doesn't match 'u32'.", 'print(f"{plus1(u):d}")'),
             (bad_i, (1.0,), "'i' doesn't match 'f32'.", 'print("{:i}".format(plus1(f)))'),
             (bad_matrix, (), "'- #0.233lli' doesn't match 'f32'.", "{:- #0.233lli} world"),
             (bad_e, (), "'.2e' doesn't match 'i32'.", "{ti.Vector([1, 2]):.2e}"),
             (bad_x, (1,), "'x' doesn't match 'i32'.", 'print(f"{i:x}")'),
             (bad_float_literal, (), "'.3f' doesn't match 'i32'.", '"{:.3f}".format(2)')]
    for kernel, args, message, line in cases:
        with pytest.raises(ti.TaichiTypeError, match=re.escape(message)) as info:
            kernel(*args)
        _located(info, line)


def test_unsupported_conversions_and_invalid_specs():
    @ti.kernel
    def conv_c(i: ti.i32):
        print(f"{i:c}")

    @ti.kernel
    def comma(a: ti.f32):
        print(f"{a:,}")

    @ti.kernel
    def nested(a: ti.f32, w: ti.i32):
        print(f"{a:{w}f}")

    with pytest.raises(ti.TaichiTypeError, match="conversion 'c' is not supported.") as info:
        conv_c(1)
    _located(info, 'print(f"{i:c}")')
    with pytest.raises(SyntaxError, match="',' is not a valid printf specifier") as info:
        comma(1.0)
    _located(info, 'print(f"{a:,}")')
    with pytest.raises(SyntaxError, match="format spec in a kernel must be known at compile time"):
        nested(1.0, 3)


def test_str_format_argument_errors():
    @ti.kernel
    def more():
        print("{0} {1} {2}".format(1, 2, 3, 4))

    @ti.kernel
    def fewer():
        print("{0} {1} {2}".format(1, 2))

    @ti.kernel
    def unused(k: ti.f32):
        print("".format(k=k))

    @ti.kernel
    def missing():
        print("{k}".format())

    cases = [(more, (), r"Expected 3 positional argument\(s\), but received 4 instead."),
             (fewer, (), r"Expected 3 positional argument\(s\), but received 2 instead."),
             (unused, (1.0,), r"Keyword 'k' not used."),
             (missing, (), r"Keyword 'k' not found.")]
    for kernel, args, message in cases:
        with pytest.raises(ti.TaichiSyntaxError, match=message) as info:
            kernel(*args)
        assert __file__ in str(info.value)


# -- assert messages with kernel values ------------------------------------------------------------------
def test_assert_messages_show_the_failing_values():
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.i32, shape=16)
    x[10] = 42

    @ti.kernel
    def percent():
        for i in x:
            assert x[i] == 0, "x[%d] expect=%d got=%d" % (i, 0, x[i])

    @ti.kernel
    def fstring(f: ti.f32, d: ti.f64, b: ti.u8, l: ti.i64, u: ti.u32):
        assert f < 0, f"f={f} d={d} b={b} l={l} u={u} {f:.3f} {u:#x} {d:e} {'s'} {2}"

    @ti.kernel
    def fmt(i: ti.i32, f: ti.f32):
        assert i == 0, "i={} f={:.2f} v={}".format(i, f, ti.Vector([i, i + 1]))

    with pytest.raises(AssertionError, match=r"x\[10\] expect=0 got=42") as info:
        percent()
    assert __file__ in str(info.value)
    with pytest.raises(ti.TaichiAssertionError) as info:
        fstring(0.1, 1.25, 200, -(2**40), 4_000_000_000)
    expect = (f"f={str(np.float32(0.1))} d={1.25!r} b=200 l={-(2**40)} u=4000000000 "
              f"{'%.3f' % np.float32(0.1)} {'%#x' % 4_000_000_000} {'%.12e' % 1.25} s 2")
    assert str(info.value).endswith(expect)
    with pytest.raises(AssertionError, match=re.escape("i=3 f=2.50 v=[3, 4]")):
        fmt(3, 2.5)
    x[10] = 0
    percent()  # no failure, no stale message
    fmt(0, 1.0)


def test_assert_message_value_limit():
    ti.init(arch=ti.cpu, debug=True)

    @ti.kernel
    def k(i: ti.i32):
        assert i == 0, "{}".format(ti.Vector([i] * 33))

    with pytest.raises(SyntaxError, match="at most 32 kernel values"):
        k(1)


def test_static_assert_needs_a_static_condition():
    @ti.kernel
    def k():
        value = False
        ti.static_assert(value, "Oh, no!")

    with pytest.raises(ti.TaichiTypeError, match="Static assert with non-static condition"):
        k()
