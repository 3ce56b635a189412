"""Python forms Taichi programs use: walrus expressions, compile-time slices of local vectors/matrices
(read and assigned), ti.grouped(ti.ndrange(...)); each against numpy / plain Python."""

import numpy as np
import pytest

import simgrad as ti


def test_walrus_assigns_and_yields_the_value():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def k(n: ti.i32) -> ti.i32:
        s = 0
        for i in range(n):
            if (y := i * 2) > 4:
                s += y
        m = n
        while (m := m - 3) > 0:  # re-evaluated at every test
            s += 100
        return s

    assert k(5) == sum(2 * i for i in range(5) if 2 * i > 4) + 100
    assert k(10) == sum(2 * i for i in range(10) if 2 * i > 4) + 300


def test_slices_of_local_vectors_and_matrices_read_and_write():
    ti.init(arch=ti.cpu)
    out = ti.field(ti.f32, shape=8)

    @ti.kernel
    def k(a: ti.f32):
        v = ti.Vector([a, 2 * a, 3 * a, 4 * a])
        m = ti.Matrix([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
        u = v[1:3] + m[1, :2]  # (2a + 4, 3a + 5)
        v[:2] = ti.Vector([-1.0, -2.0])
        m[:, 2] = ti.Vector([7.0, 8.0])
        out[0], out[1] = u[0], u[1]
        out[2], out[3] = v[0], v[1]
        out[4], out[5] = m[0, 2], m[1, 2]
        w = m[:2, 1:]
        out[6], out[7] = w[0, 0] + w[1, 1], v[3]  # v[-1] is refused, as in Taichi

    k(1.5)
    np.testing.assert_allclose(out.to_numpy(), [2 * 1.5 + 4, 3 * 1.5 + 5, -1, -2, 7, 8, 2 + 8, 6.0])


def test_grouped_ndrange_with_bounds():
    ti.init(arch=ti.cpu)
    f = ti.field(ti.i32, shape=(5, 6))

    @ti.kernel
    def k():
        for I in ti.grouped(ti.ndrange((1, 4), 6)):
            f[I] = I[0] * 10 + I[1]

    k()
    want = np.zeros((5, 6), np.int32)
    for i in range(1, 4):
        for j in range(6):
            want[i, j] = i * 10 + j
    np.testing.assert_array_equal(f.to_numpy(), want)


def test_dict_comprehension_and_static_grouped_unrolling():
    ti.init(arch=ti.cpu)
    f = ti.field(ti.i32, shape=(2, 3))

    @ti.kernel
    def k(v: ti.i32):
        d = {i: i * 10 for i in range(3) if i != 1}
        for I in ti.static(ti.grouped(ti.ndrange(2, 3))):
            f[I] = I[0] * 100 + d.get(I[1], v)

    k(7)
    np.testing.assert_array_equal(f.to_numpy(), [[0, 7, 20], [100, 107, 120]])


def test_forms_taichi_refuses_run_with_python_semantics():
    """Taichi 1.7.4 refuses these three; simgrad gives them their Python meaning (the yardstick lists the
    Taichi tests that expect the refusal as excluded, naming this test)."""
    a = ti.field(ti.i32, shape=10)

    @ti.kernel
    def stepped(x: ti.i32):
        for i in range(3, 9, 2):  # range with a step
            a[i] = x

    @ti.kernel
    def static_list() -> ti.i32:
        b = ti.static([1, 2, 3])
        b[0] = ti.static(5)  # a compile-time list, assigned at compile time
        return b[0] + b[2]

    @ti.kernel
    def reassign() -> ti.i32:
        c = 1
        c = ti.static(2)
        d = {5: 6, **{1: 2}}
        return c * 10 + d[1]

    stepped(7)
    np.testing.assert_array_equal(a.to_numpy(), [0, 0, 0, 7, 0, 7, 0, 7, 0, 0])
    assert static_list() == 8
    assert reassign() == 22


def test_list_elements_are_variables_assigned_under_runtime_control_flow():
    # Taichi's expr_init makes each element of a list bound in a kernel a local variable, so `v[1] = v[2]`
    # under a run-time `if` happens only where the condition holds (implicit_fem.py swaps triangle corners so)
    V = ti.Vector.field(4, ti.i32, shape=3)
    out = ti.field(ti.i32, shape=(3, 3))
    flag = ti.field(ti.f32, shape=3)

    @ti.kernel
    def k():
        for c in V:
            verts = [V[c][j] for j in range(3)]
            if flag[c] < 0:
                tmp = verts[1]
                verts[1] = verts[2]
                verts[2] = tmp
            a, b, d = verts
            out[c, 0], out[c, 1], out[c, 2] = a, b, d

    V.from_numpy(np.array([[10, 11, 12, 13], [20, 21, 22, 23], [30, 31, 32, 33]], np.int32))
    flag.from_numpy(np.array([1.0, -1.0, 0.0], np.float32))
    k()
    assert out.to_numpy().tolist() == [[10, 11, 12], [20, 22, 21], [30, 31, 32]]
    assert V[1][1] == 21  # the field itself is untouched


def test_python_values_in_a_list_assigned_under_runtime_control_flow_are_an_error():
    x = ti.field(ti.i32, shape=2)

    @ti.kernel
    def k():
        counts = [0, 0]
        for i in x:
            if x[i] > 0:
                counts[0] = x[i]
        x[0] = counts[0]

    with pytest.raises(ti.SimgradSyntaxError, match="run-time control flow") as e:
        k()
    assert "counts[0] = x[i]" in str(e.value)


def test_negative_indices_of_kernel_values_are_taichis_syntax_error():
    """Taichi refuses a negative compile-time index or slice bound on a local matrix or an ndarray (not Python's
    count from the end); a field's index and a Python list's stay as they are. Values from taichi 1.7.4."""
    ti.init(arch=ti.cpu)
    a = ti.ndarray(ti.f32, 4)
    f = ti.field(ti.f32, 4)

    @ti.kernel
    def local_slice(i: int):
        x = ti.Vector([i, i + 1, i + 2])
        print(x[:-1])

    @ti.kernel
    def local_index(i: int) -> int:
        x = ti.Vector([i, i + 1, i + 2])
        return x[-1]

    @ti.kernel
    def temporary(i: int) -> int:
        x = ti.Vector([i, i + 1, i + 2])
        return (x * 2)[:-1].sum()

    @ti.kernel
    def array(a: ti.types.ndarray()) -> float:
        return a[-1]

    @ti.kernel
    def python_list(i: int) -> int:
        x = [i, i + 1, i + 2]
        return x[-1] + x[:-1][0]

    @ti.kernel
    def positive(i: int) -> int:
        x = ti.Vector([i, i + 1, i + 2])
        return x[1:].sum() + x[::2].sum()

    for kernel, args in ((local_slice, (0,)), (local_index, (0,)), (temporary, (1,)), (array, (a,))):
        with pytest.raises(ti.TaichiSyntaxError, match="Negative indices are not supported in Taichi kernels"):
            kernel(*args)
    assert python_list(1) == 4 and positive(1) == 5 + 4
    f[3] = 2.0
    assert f[3] == 2.0
