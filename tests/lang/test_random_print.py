"""print() inside kernels (C printf, captured with capfd) and ti.random / ti.randn statistics."""

import numpy as np
import pytest

import simgrad as ti


def _printed(capfd) -> str:
    return capfd.readouterr().out


def test_print_scalars_and_strings(capfd):
    @ti.kernel
    def k(a: ti.i32, b: ti.f32, c: ti.f64, d: ti.i64, e: ti.u32):
        print("values:", a, b, c)
        print(d, e, sep=",")
        print("no newline", end="")
        print("|100%")

    k(-3, 1.5, 0.25, -(2**40), 2**32 - 1)
    out = _printed(capfd).splitlines()
    head = out[0].split()
    assert head[0] == "values:" and int(head[1]) == -3
    assert float(head[2]) == 1.5 and float(head[3]) == 0.25
    assert out[1] == f"{-(2**40)},{2**32 - 1}"
    assert out[2] == "no newline|100%"


def test_print_small_int_types(capfd):
    @ti.kernel
    def k(a: ti.i8, b: ti.u8, c: ti.i16, d: ti.u16):
        print(a, b, c, d)

    k(-5, 250, -300, 65000)
    assert _printed(capfd).split() == ["-5", "250", "-300", "65000"]


def test_print_fstrings_vectors_and_loops(capfd):
    x = ti.field(ti.i32, shape=3)

    @ti.kernel
    def k(v: ti.math.vec2):
        ti.loop_config(serialize=True)
        for i in range(3):
            x[i] = i * i
            print(f"x[{i}] = {x[i]}")
        print("v =", v)
        print(f"{v[0]:.3f}|{x[2]:4d}|")

    k([0.5, -2.0])
    out = _printed(capfd).splitlines()
    assert out[:3] == ["x[0] = 0", "x[1] = 1", "x[2] = 4"]
    nums = out[3].replace("v =", "").strip(" []").split(",")
    assert [float(s) for s in nums] == [0.5, -2.0]
    assert out[4] == "0.500|   4|"


def test_print_f64_keeps_precision(capfd):
    @ti.kernel
    def k(a: ti.f64):
        print(a)

    k(0.123456789012)
    assert abs(float(_printed(capfd)) - 0.123456789012) < 1e-12


def test_print_format_specs_on_64_bit_and_int_values(capfd):
    # specs are Taichi's printf specs (tests/frontend/test_print_format.py has the rest)
    @ti.kernel
    def k(a: ti.i64, b: ti.i32, c: ti.u64):
        print(f"{a:d}|{b:.2}|{c:x}")

    k(2**40 + 5, 7, 2**40 + 5)
    assert _printed(capfd).strip() == "%d|%.2d|%x" % (2**40 + 5, 7, 2**40 + 5)  # noqa: UP031 (printf's reference)


def test_print_unsupported_format_spec_is_a_located_error():
    @ti.kernel
    def k(a: ti.f32):
        print(f"{a:,}")

    with pytest.raises(SyntaxError, match="',' is not a valid printf specifier") as info:
        k(1.0)
    assert 'print(f"{a:,}")' in str(info.value)


def test_random_uniform_mean_and_range():
    n = 1_000_000
    x = ti.field(ti.f32, shape=n)
    y = ti.field(ti.f64, shape=n)

    @ti.kernel
    def k():
        for i in x:
            x[i] = ti.random()
            y[i] = ti.random(ti.f64)

    k()
    for a in (x.to_numpy(), y.to_numpy()):
        assert a.min() >= 0.0 and a.max() < 1.0
        assert abs(a.mean() - 0.5) < 3e-3  # std of the mean ~ 0.29 / 1000
        assert abs(a.var() - 1 / 12) < 2e-3
        hist = np.histogram(a, bins=10, range=(0, 1))[0]
        assert np.all(np.abs(hist - n / 10) < 5 * np.sqrt(n / 10))  # roughly uniform over the bins
    assert len(np.unique(y.to_numpy())) > n * 0.999  # no repeated stream across threads


def test_random_integers():
    n = 200_000
    x = ti.field(ti.i32, shape=n)

    @ti.kernel
    def k():
        for i in x:
            x[i] = ti.random(ti.i32) % 6

    k()
    counts = np.bincount(x.to_numpy() % 6, minlength=6)  # python % of the raw value: 0..5
    assert np.all(np.abs(counts - n / 6) < 5 * np.sqrt(n / 6))


def test_randn_mean_and_variance():
    n = 1_000_000
    x = ti.field(ti.f32, shape=n)

    @ti.kernel
    def k():
        for i in x:
            x[i] = ti.randn()

    k()
    a = x.to_numpy().astype(np.float64)
    assert np.isfinite(a).all()
    assert abs(a.mean()) < 5e-3 and abs(a.var() - 1) < 1e-2
    assert abs(np.mean(np.abs(a) < 1) - 0.6827) < 3e-3  # normal, not just mean 0 / variance 1


def _serial_draws():
    out = ti.field(ti.f32, shape=8)

    @ti.kernel
    def k():
        ti.loop_config(serialize=True)
        for i in range(8):
            out[i] = ti.random()

    k()
    return out.to_numpy()


def test_random_seed_is_deterministic():
    ti.init(arch=ti.cpu, random_seed=123)
    a = _serial_draws()
    ti.init(arch=ti.cpu, random_seed=123)
    b = _serial_draws()
    ti.init(arch=ti.cpu, random_seed=7)
    c = _serial_draws()
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert len(set(a.tolist())) == 8


def test_random_advances_between_launches():
    @ti.kernel
    def k() -> ti.f32:
        return ti.random()

    draws = [k() for _ in range(5)]
    assert len(set(draws)) == 5


@pytest.mark.parametrize("t", [ti.f32, ti.f64], ids=str)
def test_random_in_python_literal_expressions(t):
    n = 100_000
    x = ti.field(t, shape=n)

    @ti.kernel
    def k():
        for i in x:
            x[i] = ti.random(t) * 2 - 1  # uniform in [-1, 1)

    k()
    a = x.to_numpy()
    assert a.dtype == t.np and a.min() >= -1 and a.max() < 1 and abs(a.mean()) < 0.01
