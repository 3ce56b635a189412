"""Recursive ti.real_func (frontend/realfuncs.py): a real function that calls itself at run time becomes an IR
Function that the kernel CALLs, checked against numpy / Python and Taichi 1.7.4's values and errors."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.ops import Op


def _max_depth() -> int:
    """The target's recursion limit (codegen): the CPU's, or the GPU's (also when TI_ARCH=cuda runs this file on
    the simulated GPU)."""
    from simgrad.codegen.llvm import KernelCodegen
    from simgrad.codegen.nvptx import GpuCodegen

    return GpuCodegen.max_call_depth if ti.lang.impl.current_cfg().arch == ti.cuda else KernelCodegen.max_call_depth


def _fib(n: int) -> int:
    return n if n < 2 else _fib(n - 1) + _fib(n - 2)


def test_taichis_recursion_tests():
    """tests/python/test_function.py test_recursion and test_deep_recursion (taichi 1.7.4: 4950 and 5050)."""
    ti.init(arch=ti.cpu)

    @ti.real_func
    def sum(f: ti.template(), l: ti.i32, r: ti.i32) -> ti.i32:  # noqa: A001 (Taichi's test names it so)
        if l == r:
            return f[l]
        else:
            return sum(f, l, (l + r) // 2) + sum(f, (l + r) // 2 + 1, r)

    f = ti.field(ti.i32, shape=100)
    f.from_numpy(np.arange(100, dtype=np.int32))

    @ti.kernel
    def get_sum() -> ti.i32:
        return sum(f, 0, 99)

    @ti.real_func
    def sum_func(n: ti.i32) -> ti.i32:
        if n == 0:
            return 0
        return sum_func(n - 1) + n

    @ti.kernel
    def total(n: ti.i32) -> ti.i32:
        return sum_func(n)

    assert get_sum() == 99 * 50
    deep = _max_depth() // 2
    assert total(100) == 5050 and total(0) == 0 and total(deep) == deep * (deep + 1) // 2
    ir = get_sum.instance(()).ir
    assert len(ir.functions) == 1 and ir.functions[0].params == [ti.i32, ti.i32]
    assert any(s.op is Op.CALL for s in _walk(ir.body)) and any(s.op is Op.CALL for s in _walk(ir.functions[0].body))


def _walk(block):
    from simgrad.ir.nodes import walk

    return walk(block)


def test_recursion_in_a_parallel_loop_with_atomics_and_matrices():
    """Every thread of a parallel loop recurses on its own stack; updates inside the function are atomic;
    matrices travel as their entries, in and out."""
    ti.init(arch=ti.cpu)
    n = 2000
    out = ti.field(ti.i32, shape=n)
    calls = ti.field(ti.i32, shape=())
    pw = ti.Vector.field(2, ti.f64, shape=n)

    @ti.real_func
    def fib(k: ti.i32) -> ti.i32:
        calls[None] += 1
        r = k
        if k >= 2:
            r = fib(k - 1) + fib(k - 2)
        return r

    @ti.real_func
    def power(v: ti.math.vec2, k: ti.i32) -> ti.types.vector(2, ti.f64):
        r = ti.Vector([1.0, 1.0], ti.f64)
        if k > 0:
            r = v * power(v, k - 1)
        return r

    @ti.kernel
    def run():
        for i in out:
            out[i] = fib(i % 12)
            pw[i] = power(ti.math.vec2(1.0 + i % 64 * 0.25, 0.5), i % 7)  # exact in f32

    run()
    i = np.arange(n)
    np.testing.assert_array_equal(out.to_numpy(), [_fib(k) for k in i % 12])
    ncalls = {0: 1, 1: 1}
    for k in range(2, 12):
        ncalls[k] = 1 + ncalls[k - 1] + ncalls[k - 2]
    assert calls[None] == sum(ncalls[k] for k in i % 12)  # no update lost between threads
    base = np.stack([1.0 + i % 64 * 0.25, np.full(n, 0.5)], 1)
    np.testing.assert_allclose(pw.to_numpy(), base ** (i % 7)[:, None], rtol=1e-12)


def test_mutual_recursion_and_specialisations():
    """is_even/is_odd call each other; one function per compile-time argument (two fields, two Functions)."""
    ti.init(arch=ti.cpu)
    a = ti.field(ti.i32, shape=8)
    b = ti.field(ti.i32, shape=8)
    a.from_numpy(np.arange(8, dtype=np.int32))
    b.from_numpy(np.arange(8, dtype=np.int32) * 10)

    @ti.real_func
    def is_even(k: ti.i32) -> ti.i32:
        r = 1
        if k > 0:
            r = is_odd(k - 1)
        return r

    @ti.real_func
    def is_odd(k: ti.i32) -> ti.i32:
        r = 0
        if k > 0:
            r = is_even(k - 1)
        return r

    @ti.real_func
    def total(f: ti.template(), k: ti.i32) -> ti.i32:
        r = 0
        if k >= 0:
            r = f[k] + total(f, k - 1)
        return r

    @ti.kernel
    def run(k: ti.i32) -> ti.types.vector(4, ti.i32):
        return ti.Vector([is_even(k), is_odd(k), total(a, 7), total(b, k)])

    for k in (0, 1, 6, 7, 200):
        got = run(k).to_numpy()
        want = [k % 2 == 0, k % 2 == 1, 28, 10 * sum(range(min(k, 7) + 1))]
        if k > 7:  # total(b, 200) reads past b's 8 cells: not compared
            got, want = got[:3], want[:3]
        np.testing.assert_array_equal(got, want)
    assert len(run.instance((0,)).ir.functions) == 3  # is_even (is_odd inlined in it), total over a, over b


def test_too_deep_recursion_is_a_located_error_and_the_kernel_still_works():
    ti.init(arch=ti.cpu)

    @ti.real_func
    def depth(n: ti.i32) -> ti.i32:
        r = 0
        if n > 0:
            r = depth(n - 1) + 1
        return r

    @ti.kernel
    def run(n: ti.i32) -> ti.i32:
        return depth(n)

    limit = _max_depth()
    with pytest.raises(ti.TaichiRuntimeError, match=f"recursed deeper than {limit} calls") as e:
        run(10 ** 6)  # a native stack overflow would kill the interpreter
    assert e.value.loc is not None and "r = depth(n - 1) + 1" in str(e.value)
    assert run(limit - 1) == limit - 1  # the kernel's own call is inlined: limit - 1 calls deep
    with pytest.raises(ti.TaichiRuntimeError, match="recursed deeper"):
        run(limit + 1)


def test_gradient_through_recursion_is_refused_as_in_taichi():
    """Taichi refuses any real function in a gradient kernel ("Real function in gradient kernels unsupported.");
    simgrad inlines the non-recursive ones, whose gradient stays (checked against finite differences)."""
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, shape=(), needs_grad=True)
    y = ti.field(ti.f64, shape=(), needs_grad=True)

    @ti.real_func
    def power(n: ti.i32, a: ti.f64) -> ti.f64:
        r = 1.0
        if n > 0:
            r = a * power(n - 1, a)
        return r

    @ti.real_func
    def cube(a: ti.f64) -> ti.f64:
        return a * a * a

    @ti.kernel
    def recursive():
        y[None] = power(3, x[None])

    @ti.kernel
    def plain():
        y[None] = cube(x[None])

    x[None] = 1.5
    recursive()
    assert y[None] == 1.5 ** 3
    with pytest.raises(ti.TaichiSyntaxError, match="Real function in gradient kernels unsupported") as e:
        recursive.grad()
    assert "r = a * power(n - 1, a)" in str(e.value)  # the call that stays a call (the first one is inlined)
    plain()
    y.grad[None] = 1.0
    plain.grad()
    h = 1e-6
    assert x.grad[None] == pytest.approx(((1.5 + h) ** 3 - (1.5 - h) ** 3) / (2 * h), rel=1e-8)


def test_what_a_recursive_real_function_cannot_take_is_located():
    ti.init(arch=ti.cpu)

    @ti.real_func
    def bump(a: ti.ref(ti.i32), n: ti.i32):
        if n > 0:
            a += 1
            bump(a, n - 1)

    @ti.kernel
    def run() -> ti.i32:
        a = 0
        bump(a, 3)
        return a

    with pytest.raises(ti.TaichiSyntaxError, match="parameter a of the recursive real function bump is a ti.ref"):
        run()


def test_recursion_in_debug_mode_checks_indices_and_asserts_inside_the_function():
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.f32, shape=8)

    @ti.real_func
    def walk(k: ti.i32, n: ti.i32) -> ti.f32:
        r = 0.0
        if k > 0:
            assert k < 50, "too deep"
            r = 1.0 + walk(k - 1, n)
            x[n] += 1.0
        return r

    @ti.kernel
    def run(k: ti.i32, n: ti.i32) -> ti.f32:
        s = 0.0
        for _ in range(4):
            s += walk(k, n)
        return s

    assert run(5, 3) == 20.0
    np.testing.assert_array_equal(x.to_numpy(), [0, 0, 0, 20, 0, 0, 0, 0])
    with pytest.raises(ti.TaichiAssertionError, match="too deep"):
        run(60, 3)
    with pytest.raises(Exception, match="index 9 is out of bounds"):
        run(5, 9)
