"""A parallel loop whose body takes its flat index apart by a constant (ti.ndrange, a struct-for over several
axes) runs each chunk as rows: an outer loop over i / n, an inner counted loop over i % n (codegen/cpu.py
_row_loops). No division per index, consecutive last-axis accesses, and LLVM vectorises the inner loop. Every
index must still be visited exactly once, from chunks that start and end in the middle of rows."""

import numpy as np
import pytest

import simgrad as ti
from simgrad.runtime.jit import get_jit


def _task_ir(kernel, *args):
    text = kernel._instance_for(args, "").llvm_text
    opt = str(get_jit()._optimized(text, 0))
    return opt.split("define internal void @sg_kernel_task1")[1].split("\n}")[0]


@pytest.mark.parametrize("threads", [1, 2])
def test_every_index_once_from_chunks_that_cut_rows(threads):
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads)
    hits = ti.field(ti.i32, shape=(1003, 997))
    val = ti.field(ti.i32, shape=(1003, 997))

    @ti.kernel
    def k():
        for i, j in ti.ndrange((2, 1001), (3, 996)):
            hits[i, j] += 1
            val[i, j] = i * 1000 + j

    k()
    want = np.zeros((1003, 997), np.int32)
    want[2:1001, 3:996] = 1
    np.testing.assert_array_equal(hits.to_numpy(), want)
    i, j = np.meshgrid(np.arange(1003), np.arange(997), indexing="ij")
    np.testing.assert_array_equal(val.to_numpy(), np.where(want == 1, i * 1000 + j, 0))


def test_stencil_vectorises_and_matches_numpy():
    ti.init(arch=ti.cpu)
    n = 301
    a = ti.field(ti.f32, shape=(n, n))
    b = ti.field(ti.f32, shape=(n, n))

    @ti.kernel
    def lap():
        for i, j in ti.ndrange((1, n - 1), (1, n - 1)):
            b[i, j] = a[i + 1, j] + a[i - 1, j] + a[i, j + 1] + a[i, j - 1] - 4 * a[i, j]

    x = np.random.default_rng(0).random((n, n), dtype=np.float32)
    a.from_numpy(x)
    lap()
    want = np.zeros((n, n), np.float32)
    want[1:-1, 1:-1] = x[2:, 1:-1] + x[:-2, 1:-1] + x[1:-1, 2:] + x[1:-1, :-2] - np.float32(4) * x[1:-1, 1:-1]
    np.testing.assert_array_equal(b.to_numpy(), want)  # same operations in the same order
    task = _task_ir(lap)
    assert " x float>" in task  # the inner loop over j is vectorised
    assert "urem" not in task.split("vector.body")[1].split("middle.block")[0]  # no division per index


def test_three_axes_a_continue_and_a_struct_for():
    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    f = ti.field(ti.i32, shape=(5, 7, 9))
    g = ti.field(ti.f64, shape=(33, 35))

    @ti.kernel
    def k():
        for i, j, l in ti.ndrange(5, 7, 9):
            if (i + j + l) % 4 == 0:
                continue
            f[i, j, l] = i * 100 + j * 10 + l
        for i, j in g:
            g[i, j] = ti.sqrt(ti.cast(i * 35 + j, ti.f64))

    k()
    i, j, l = np.meshgrid(np.arange(5), np.arange(7), np.arange(9), indexing="ij")
    np.testing.assert_array_equal(f.to_numpy(), np.where((i + j + l) % 4 == 0, 0, i * 100 + j * 10 + l))
    np.testing.assert_array_equal(g.to_numpy(), np.sqrt(np.arange(33 * 35, dtype=np.float64)).reshape(33, 35))


def test_run_time_extents_of_ndarrays():
    """The extent is a run-time value (an ndarray's shape): the same instantiation serves every shape, an empty
    axis included (no division by a zero extent)."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=2)

    @ti.kernel
    def k(a: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for i, j in ti.ndrange(a.shape[0], a.shape[1]):
            a[i, j] += i * 1000 + j

    @ti.kernel
    def g(a: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        for i, j in a:
            a[i, j] += 1

    for shape in [(7, 333), (1000, 13), (5, 0), (0, 9), (1, 1)]:
        a = np.zeros(shape, np.int32)
        k(a)
        g(a)
        i, j = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
        np.testing.assert_array_equal(a, i * 1000 + j + 1)
    assert "rowhead" in k._instance_for((np.zeros((2, 2), np.int32),), "").llvm_text
