"""bool / ti.u1 wherever Taichi 1.7.4 allows it: kernel arguments and returns (a byte in the context, read back
as an int as Taichi returns it), struct members, ndarrays, atomics (one byte updated), Python-scope writes.
Expected values are what taichi 1.7.4 gives for the same program (run on the CPU)."""

import numpy as np

import simgrad as ti


def test_u1_return_and_local():
    @ti.kernel
    def k(a: ti.i32) -> ti.u1:
        b = ti.u1(a)
        return b

    assert (k(3), k(0)) == (1, 0)
    assert type(k(3)) is int


def test_u1_and_or_not_and_ternary():
    @ti.kernel
    def logic(a: ti.u1, b: ti.u1) -> ti.u1:
        return (a and b) or not a

    @ti.kernel
    def tern(a: ti.u1, b: ti.u1) -> ti.u1:
        return a if b else not a

    assert [logic(x, y) for x in (0, 1) for y in (0, 1)] == [1, 1, 0, 1]
    assert (tern(True, True), tern(True, False)) == (1, 0)


def test_u1_argument_is_its_truth_value():
    """Taichi converts a u1 argument to 0/1 (256 is 1, not its low byte); u1 arithmetic wraps at one bit."""

    @ti.kernel
    def as_int(a: ti.u1) -> ti.i32:
        return ti.i32(a)

    @ti.kernel
    def add(a: ti.u1, b: ti.u1) -> ti.i32:
        c = a + b
        return c

    @ti.kernel
    def neg(a: ti.u1) -> ti.i32:
        return -a

    assert [as_int(v) for v in (0, 1, 2, 256, True, np.int32(3))] == [0, 1, 1, 1, 1, 1]
    assert add(True, True) == 0
    assert neg(True) == 1


def test_u1_bitops_compare_assign():
    @ti.kernel
    def bits(a: ti.u1, b: ti.u1) -> ti.u1:
        return (a & b) | (a ^ b)

    @ti.kernel
    def cmp(a: ti.i32) -> ti.u1:
        c = ti.u1(False)
        c = a > 3
        c |= a < -3
        return c

    @ti.kernel
    def conv(x: ti.u32) -> ti.u1:
        return bool(x)

    assert [bits(x, y) for x in (0, 1) for y in (0, 1)] == [0, 1, 1, 1]
    assert (cmp(5), cmp(0), cmp(-5)) == (1, 0, 1)
    assert (conv(4294967295), conv(0)) == (1, 0)


def test_u1_struct_members_args_and_returns():
    S = ti.types.struct(a=ti.i32, b=ti.u1)
    s = S.field(shape=2)

    @ti.kernel
    def k() -> ti.u1:
        s[0].b = True
        s[1].a = 3
        t = S(a=1, b=False)
        return s[0].b and not t.b

    @ti.kernel
    def arg(v: S) -> ti.i32:
        return v.a if v.b else -v.a

    @ti.kernel
    def ret() -> S:
        return S(a=3, b=True)

    assert k() == 1
    d = s.to_numpy()
    assert d["b"].dtype == np.bool_ and d["b"].tolist() == [True, False] and d["a"].tolist() == [0, 3]
    assert (arg(S(a=3, b=True)), arg(S(a=3, b=False))) == (3, -3)
    r = ret()
    assert (r.a, r.b) == (3, 1)


def test_bool_is_u1():
    """Taichi's cook_dtype makes the Python `bool` a u1: a struct member declared `bool` is one byte."""
    S = ti.types.struct(a=ti.i32, b=bool)
    s = S.field(shape=2)

    @ti.kernel
    def k():
        s[1].b = True

    k()
    assert s.to_numpy()["b"].dtype == np.bool_
    assert (s[1].b, s[0].b) == (1, 0)


def test_u1_ndarray_elements_are_bytes():
    a = ti.ndarray(ti.u1, shape=3)
    v = ti.Vector.ndarray(2, ti.u1, shape=2)

    @ti.kernel
    def k(x: ti.types.ndarray(), y: ti.types.ndarray()):
        for i in x:
            x[i] = i == 1
        for i in y:
            y[i] = ti.Vector([i == 0, i == 1])

    k(a, v)
    assert a.to_numpy().tolist() == [False, True, False]
    assert v.to_numpy().tolist() == [[True, False], [False, True]]
    b = np.zeros(3, dtype=bool)
    k(b, v)
    assert b.tolist() == [False, True, False]


def test_u1_atomics_update_one_byte():
    """LLVM has no atomics on i1 (its verifier refused the kernel); Taichi 1.7.4 aborts the process here.
    The byte is updated with u1's wrap-around: += is xor, max is or, min is and."""
    x = ti.field(ti.u1, shape=4)

    @ti.kernel
    def k():
        for i in range(10):
            ti.atomic_or(x[0], i == 7)
            ti.atomic_add(x[1], True)
            ti.atomic_max(x[2], i == 3)
            ti.atomic_min(x[3], i != 5)

    x[3] = 1
    k()
    assert x.to_numpy().tolist() == [True, False, True, False]


def test_u1_python_scope_write_and_read():
    x = ti.field(ti.u1, shape=3)
    x[1] = 5
    x[2] = True
    assert x.to_numpy().tolist() == [False, True, True]
    assert x[1] == 1 and type(x[1]) is int
    x.fill(1)
    assert x.to_numpy().tolist() == [True, True, True]
