"""Flush to zero (runtime/fpenv.py): Taichi's float mode on every backend, simgrad's default; subnormal
results of kernel arithmetic are zeros of their sign, folded or computed, on the calling thread and on the
pool's workers; inputs are not flushed (FTZ without DAZ, as Taichi's CPU); numpy and Python keep IEEE
subnormals around kernels (Taichi sets the mode for its whole process, so numpy flushes there too: a
deliberate difference); ti.init(flush_denormals=False) keeps IEEE subnormals in kernels."""

import numpy as np
import pytest

import simgrad as ti

TINY32 = float(np.float32(1e-10)) * float(np.float32(1e-35))  # ~1e-45 in f32: a subnormal result


def _products(dtype, x, y):
    """Literal, folded product, run-time product on the caller and in a parallel loop on the workers."""
    n = 4096
    a = ti.field(dtype, shape=3 + n)

    @ti.kernel
    def k(u: dtype, v: dtype):
        a[0] = 1e-45 if ti.static(dtype == ti.f32) else 1e-323
        a[1] = 1e-10 * 1e-35 if ti.static(dtype == ti.f32) else 1e-300 * 1e-23
        a[2] = u * v
        for i in range(n):
            a[3 + i] = u * v * (1.0 + 1e-7 * (i % 2))

    k(x, y)
    return a.to_numpy()


@pytest.mark.parametrize("dtype,x,y", [(ti.f32, 1e-10, 1e-35), (ti.f64, 1e-300, 1e-23)])
def test_subnormal_results_flush_to_zero_by_default(dtype, x, y):
    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    got = _products(dtype, x, y)
    want = dtype.np.type(x) * dtype.np.type(y)
    assert 0 < abs(want) < np.finfo(dtype.np).tiny  # IEEE gives a subnormal ...
    assert not got.any()  # ... the kernel a zero, everywhere (caller, workers, folds)


@pytest.mark.parametrize("dtype,x,y", [(ti.f32, 1e-10, 1e-35), (ti.f64, 1e-300, 1e-23)])
def test_flush_denormals_false_keeps_ieee_subnormals(dtype, x, y):
    ti.init(arch=ti.cpu, cpu_max_num_threads=2, flush_denormals=False)
    got = _products(dtype, x, y)
    want = dtype.np.type(x) * dtype.np.type(y)
    assert got[2] == want and got[3] == want and np.all(got[3:] != 0)
    lit = np.array([1e-45 if dtype == ti.f32 else 1e-323], dtype=dtype.np)[0]
    assert got[0] == lit and got[0] != 0


def test_negative_results_flush_to_negative_zero():
    a = ti.field(ti.f32, shape=2)

    @ti.kernel
    def k(u: ti.f32):
        a[0] = -u * 1e-35
        a[1] = -1e-45

    k(1e-10)
    got = a.to_numpy()
    assert np.all(got == 0) and np.all(np.signbit(got))


def test_subnormal_inputs_are_not_flushed():
    """A subnormal read from a field is itself (no DAZ): copied, compared and min'd as such; arithmetic on it
    with a normal result is exact."""
    a = ti.field(ti.f32, shape=5)
    sub = np.float32(1e-40)
    a.from_numpy(np.array([sub, 0, 0, 0, 0], dtype=np.float32))

    @ti.kernel
    def k():
        a[1] = a[0]
        a[2] = ti.cast(a[0] > 0, ti.f32)
        a[3] = a[0] * 1e30
        a[4] = ti.min(a[0], 1.0)

    k()
    got = a.to_numpy()
    assert got[1] == sub and got[2] == 1.0 and got[4] == sub
    assert got[3] == np.float32(sub * np.float32(1e30))


def test_numpy_keeps_ieee_subnormals_around_kernels():
    """The mode is the kernels': after kernels ran (caller and workers) numpy still produces subnormals (under
    Taichi, whose process-wide FTZ flushes numpy's products too, this is 0.0)."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    _products(ti.f32, 1e-10, 1e-35)
    assert np.float32(1e-10) * np.float32(1e-35) != 0
    assert np.float32(TINY32) != 0


def test_flushed_constant_folds_like_the_run_time_op():
    """A constant expression folded at compile time and the same expression on kernel arguments agree."""
    a = ti.field(ti.f32, shape=4)

    @ti.kernel
    def k(u: ti.f32, v: ti.f32, w: ti.f32):
        a[0] = 1.5e-20 * 2.5e-19
        a[1] = u * v
        a[2] = ti.sqrt(1e-38) * 1e-20
        a[3] = ti.sqrt(w * 1e-18) * 1e-20

    k(1.5e-20, 2.5e-19, 1e-20)
    got = a.to_numpy()
    assert got[0] == got[1] == 0
    assert got[2] == got[3] == 0


def test_pool_workers_run_in_the_launching_threads_mode():
    """Chunks a worker thread ran (ti.global_thread_idx() != 0) flush too: the worker takes the launching thread's
    mode with the job. Launches repeat until workers took part (they do at once on an idle machine)."""
    ti.init(arch=ti.cpu, cpu_max_num_threads=2)
    n = 1 << 20
    out = ti.field(ti.f32, shape=n)
    tid = ti.field(ti.i32, shape=n)

    @ti.kernel
    def k(u: ti.f32, v: ti.f32):
        for i in range(n):
            out[i] = u * v
            tid[i] = ti.global_thread_idx()

    for _ in range(50):
        k(1e-10, 1e-35)
        if (tid.to_numpy() != 0).any():
            break
    by_worker = tid.to_numpy() != 0
    assert by_worker.any(), "no chunk ran on a worker thread"
    assert not out.to_numpy()[by_worker].any()
