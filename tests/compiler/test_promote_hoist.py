"""Local promotion (passes/promote.py) and hoisting (passes/hoist.py): results against numpy, and the IR
shape they promise (a once-assigned local is read as its value; invariant index arithmetic leaves the
parallel loop; nothing that can trap is hoisted)."""

import numpy as np

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


def _ir(kernel, *args):
    return kernel._instance_for(args, "").ir


def test_locals_assigned_once_reassigned_or_updated_keep_python_semantics():
    n = 64
    x = ti.field(ti.f64, shape=n)
    y = ti.field(ti.f64, shape=n)

    @ti.kernel
    def run(t: ti.i32):
        for i in x:
            once = i * 2 + t  # one store: promoted
            again = 1.0
            if i % 2 == 0:
                again = 3.0  # a second store (in a nested block): stays a local
            acc = 0.0
            for k in range(4):
                acc += k * once  # updated in a loop: stays a local
            j = 0
            while j < i % 5:
                j += 1
            x[i] = once * again + acc + j
            y[i] = once

    run(3)
    i = np.arange(n)
    once = i * 2 + 3
    again = np.where(i % 2 == 0, 3.0, 1.0)
    np.testing.assert_array_equal(x.to_numpy(), once * again + 6 * once + i % 5)
    np.testing.assert_array_equal(y.to_numpy(), once)


def test_a_once_assigned_local_is_read_as_its_value():
    x = ti.field(ti.i32, shape=8)

    @ti.kernel
    def run(t: ti.i32):
        for i in x:
            a = t * 3 + 1
            x[i] = a + i

    run(2)
    np.testing.assert_array_equal(x.to_numpy(), np.arange(8) + 7)
    loads = [s for s in walk(_ir(run, 2).body) if s.op is Op.LOCAL_LOAD]
    assert loads == []


def test_invariant_index_arithmetic_is_hoisted_out_of_the_parallel_loop():
    p = ti.field(ti.f32, shape=(10, 16))

    @ti.kernel
    def run(t: ti.i32, k: ti.i32):
        for i in range(16):
            a = t * 3 + k
            p[a, i] = i

    run(2, 1)
    expect = np.zeros((10, 16), np.float32)
    expect[7] = np.arange(16)
    np.testing.assert_array_equal(p.to_numpy(), expect)
    body = _ir(run, 2, 1).body.stmts
    loop = next(s for s in body if s.op is Op.RANGE_FOR)
    ptr = next(s for s in walk(loop.blocks[0]) if s.op is Op.GLOBAL_PTR)
    assert ptr.operands[0] in body[:body.index(loop)]  # the slice index is computed before the loop


def test_a_division_that_could_trap_is_not_hoisted_out_of_an_empty_loop():
    x = ti.field(ti.i32, shape=4)

    @ti.kernel
    def run(n: ti.i32, d: ti.i32):
        for i in range(n):
            x[i] = 100 // d + 7 % d

    run(0, 0)  # the loop never runs: dividing by zero must not happen either
    np.testing.assert_array_equal(x.to_numpy(), np.zeros(4))
    run(4, 3)
    np.testing.assert_array_equal(x.to_numpy(), np.full(4, 100 // 3 + 7 % 3))
    loop = next(s for s in _ir(run, 4, 3).body.stmts if s.op is Op.RANGE_FOR)
    assert any(s.op is Op.FLOORDIV for s in walk(loop.blocks[0]))
