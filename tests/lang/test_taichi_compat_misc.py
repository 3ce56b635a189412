"""Smaller Taichi behaviours found by running Taichi's own tests: Tape(grad_check=...), `v(0)` element calls,
0-d numpy arrays as compile-time constants, a for loop under a plain `if` is serial (break allowed), and
run-time access-rule violations are TaichiAssertionErrors."""

import numpy as np
import pytest

import simgrad as ti


def test_grad_check_passes_a_correct_gradient_and_catches_a_wrong_one():
    ti.init(arch=ti.cpu, default_fp=ti.f64)
    x = ti.field(ti.f64, shape=(2, 2), needs_grad=True)
    y = ti.field(ti.f64, shape=(), needs_grad=True)
    x.from_numpy(np.array([[1.0, 2.0], [3.0, 4.0]]))

    @ti.kernel
    def compute():
        for i, j in x:
            y[None] += ti.cos(x[i, j])

    with ti.ad.Tape(y, grad_check=[x]):
        compute()
    np.testing.assert_allclose(x.grad.to_numpy(), -np.sin([[1.0, 2.0], [3.0, 4.0]]))
    assert y[None] == pytest.approx(np.cos([1.0, 2.0, 3.0, 4.0]).sum())  # the state after backward is kept

    @ti.kernel
    def wrong_grad():
        for i, j in x:
            y[None] += x[i, j] * 2.0  # the adjoint below says 3

    @ti.ad.grad_replaced
    def forward():
        wrong_grad()

    @ti.ad.grad_for(forward)
    def backward():
        for i in range(2):
            for j in range(2):
                x.grad[i, j] += 3.0 * y.grad[None]

    with pytest.raises(ti.GradientError, match="grad check failed for field"):
        with ti.ad.Tape(y, grad_check=[x]):
            forward()
    with pytest.raises(ti.SimgradError, match="f64"):
        ti.ad.Tape(ti.field(ti.f32, shape=(), needs_grad=True), grad_check=[x])


def test_call_syntax_numpy_0d_constants_and_nested_loops():
    ti.init(arch=ti.cpu)
    out = ti.field(ti.f32, shape=4)
    begin = np.array(2, dtype=np.int32)

    @ti.kernel
    def k() -> ti.i32:
        v = ti.Vector([1.0, 2.0, 3.0])
        m = ti.Matrix([[1.0, 2.0], [3.0, 4.0]])
        out[0] = v(1) + m(1, 0)
        for i in range(begin, 4):
            out[i] = i
        a = 0
        if True:
            for i in range(1000):  # not an outermost loop: serial, so break is allowed (as Taichi)
                if i == 100:
                    break
                a += 1
        return a

    assert k() == 100
    np.testing.assert_array_equal(out.to_numpy(), [5.0, 0.0, 2.0, 3.0])


def test_access_rule_violation_is_a_taichi_assertion_error():
    ti.init(arch=ti.cpu)
    x = ti.field(ti.f32, shape=4, needs_grad=True)
    loss = ti.field(ti.f32, shape=(), needs_grad=True)

    @ti.kernel
    def read():
        for i in x:
            loss[None] += x[i] ** 2

    @ti.kernel
    def overwrite():
        for i in x:
            x[i] = 0.0

    x.fill(1.0)
    with pytest.raises(ti.TaichiAssertionError, match="global data access rule"):
        with ti.ad.Tape(loss=loss, validation=True):
            read()
            overwrite()


def test_matrix_compared_with_nested_lists_elementwise_in_both_scopes():
    """Was silently wrong: a list beside a matrix was taken as one scalar operand (every entry compared
    with the whole list, giving all zeros)."""
    ti.init(arch=ti.cpu)
    m = ti.Matrix([[0, 1], [2, 3]])
    assert (m == [[0, 1], [2, 3]]).all() and not (m == [[0, 1], [2, 4]]).all()
    np.testing.assert_array_equal((ti.Vector([1, 2]) * (3, 4)).to_numpy(), [3, 8])
    f = ti.Matrix.field(2, 2, ti.i32, shape=3)
    ok = ti.field(ti.i32, shape=2)

    @ti.kernel
    def k():
        for i in range(3):
            f[i] = [[i, i + 1], [i + 2, i + 3]]
        ok[0] = all(f[1] == [[1, 2], [3, 4]])
        ok[1] = any(f[2] == [[0, 0], [0, 0]])

    k()
    assert (f[1] == [[1, 2], [3, 4]]).all() and list(ok.to_numpy()) == [1, 0]


def test_break_and_continue_in_static_loops_and_asserts_only_in_debug():
    ti.init(arch=ti.cpu)
    x = ti.field(ti.i32, 5)
    y = ti.field(ti.i32, 5)

    @ti.kernel
    def k(v: ti.i32):
        for i in ti.static(range(5)):
            x[i] = 1
            if ti.static(i == 2):
                break
        for i in ti.static(range(5)):
            if ti.static(i == 2):
                continue
            y[i] = v
        assert v < 0, "evaluated but not checked without debug=True, as in Taichi"

    k(7)
    np.testing.assert_array_equal(x.to_numpy(), [1, 1, 1, 0, 0])
    np.testing.assert_array_equal(y.to_numpy(), [7, 7, 0, 7, 7])
    ti.init(arch=ti.cpu, debug=True)

    @ti.kernel
    def known_false():
        assert 1 == 2, "known at compile time"

    with pytest.raises(ti.TaichiAssertionError, match="known at compile time"):
        known_false()
