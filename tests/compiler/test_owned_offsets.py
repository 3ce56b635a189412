"""Ownership through constant shifts of a flattened loop's digits (passes/parallel_strategy.py): a loop over
`ti.ndrange((1, n - 1), (1, m - 1))` that updates `rho[i, j] += ...` at its own element needs no atomics
(karman_vortex_street's update_macro_var: 9 CAS loops per cell at 2 threads). Results against numpy."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op


@pytest.mark.parametrize("threads", [1, 4])
def test_interior_accumulation_through_shifted_digits_is_plain_and_exact(threads):
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads)
    nx, ny, q = 40, 23, 9
    f = ti.Vector.field(q, ti.f64, shape=(nx, ny))
    rho = ti.field(ti.f64, shape=(nx, ny))
    vel = ti.Vector.field(2, ti.f64, shape=(nx, ny))
    rng = np.random.default_rng(11)
    fs = rng.random((nx, ny, q))
    f.from_numpy(fs)
    rho.from_numpy(np.full((nx, ny), -3.0))
    vel.from_numpy(np.full((nx, ny, 2), 5.0))
    e = np.array([[0, 0], [1, 0], [0, 1], [-1, 0], [0, -1], [1, 1], [-1, 1], [-1, -1], [1, -1]], np.float64)

    @ti.kernel
    def macro():
        for i, j in ti.ndrange((1, nx - 1), (1, ny - 1)):
            rho[i, j] = 0
            vel[i, j] = 0, 0
            for k in ti.static(range(q)):
                rho[i, j] += f[i, j][k]
                vel[i, j] += ti.Vector([e[k, 0], e[k, 1]]) * f[i, j][k]
            vel[i, j] /= rho[i, j]

    macro()
    want_rho = np.full((nx, ny), -3.0)
    want_vel = np.full((nx, ny, 2), 5.0)
    inner = fs[1:-1, 1:-1]
    want_rho[1:-1, 1:-1] = inner.sum(-1)
    want_vel[1:-1, 1:-1] = inner @ e / want_rho[1:-1, 1:-1, None]
    np.testing.assert_allclose(rho.to_numpy(), want_rho, rtol=1e-13)
    np.testing.assert_allclose(vel.to_numpy(), want_vel, rtol=1e-12)
    forms = {s.attrs["strategy"] for s in walk(macro.instance(()).ir.body) if s.op is Op.ATOMIC}
    assert forms == {"plain"}
    assert "_serial" not in macro._instance_for((), "").llvm_text  # no atomic task, so no plain variant of one


def test_two_shifts_of_one_field_stay_atomic_and_exact():
    """w[i] += 1 and w[i + 1] += 1: iteration i + 1 writes what iteration i writes second; every element gets
    both of its updates (atomics or per-thread copies, never plain read-modify-writes across threads)."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=4)
    n = 200_000
    w = ti.field(ti.i32, shape=n + 1)

    @ti.kernel
    def both():
        for i in range(n):
            w[i] += 1
            w[i + 1] += 1

    both()
    want = np.full(n + 1, 2, np.int32)
    want[0] = want[n] = 1
    np.testing.assert_array_equal(w.to_numpy(), want)
    assert all(s.attrs["strategy"] != "plain" for s in walk(both.instance(()).ir.body) if s.op is Op.ATOMIC)


@pytest.mark.parametrize("shape", [(7, 9), (3, 4, 5)])
def test_struct_for_over_an_ndarray_owns_its_elements_through_run_time_extents(shape):
    """`for I in ti.grouped(a)` splits the flat index by the array's run-time extents (`L % n`, `L // n`):
    a[I] += ... is owned (plain; before, an atomic or a per-thread copy of the whole array), the transposed
    element too; rows[I[0]] (many iterations per row) and a digit without the rest of its chain are not."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=4)
    rng = np.random.default_rng(len(shape))
    start = rng.standard_normal(shape)
    a = start.copy()
    t = np.zeros(shape[::-1])
    rows = np.zeros(shape[0])
    last = np.zeros(shape[-1])

    @ti.kernel
    def bump(a: ti.types.ndarray(ndim=len(shape)), t: ti.types.ndarray(ndim=len(shape)),
             rows: ti.types.ndarray(ndim=1), last: ti.types.ndarray(ndim=1)):
        for I in ti.grouped(a):
            a[I] += 2.0 * a[I] + 1.0
            if ti.static(len(shape) == 2):
                t[I[1], I[0]] += 1.0
            else:
                t[I[2], I[1], I[0]] += 1.0
            rows[I[0]] += 1.0
            last[I[len(shape) - 1]] += 1.0

    bump(a, t, rows, last)
    np.testing.assert_allclose(a, 3 * start + 1, rtol=1e-15)
    np.testing.assert_array_equal(t, np.ones(shape[::-1]))
    np.testing.assert_array_equal(rows, np.full(shape[0], np.prod(shape[1:])))
    np.testing.assert_array_equal(last, np.full(shape[-1], np.prod(shape[:-1])))
    forms = {}
    for s in walk(bump.instance((a, t, rows, last)).ir.body):
        if s.op is Op.ATOMIC:
            forms.setdefault(s.operands[0].attrs["target"].name, set()).add(s.attrs["strategy"])
    assert forms["a"] == {"plain"} and forms["t"] == {"plain"}
    assert "plain" not in forms["rows"] and "plain" not in forms["last"]
