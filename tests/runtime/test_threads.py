"""Two Python threads launching and compiling kernels at once: ctypes releases the GIL during a launch, so
the context buffer, the error buffer and the thread pool are shared between the threads' launches. Every
launch must see its own arguments and return its own result; the first compile may race."""

from __future__ import annotations

import threading

import numpy as np

import simgrad as ti

LAUNCHES = 3000


def _race(work, threads: int = 2) -> list:
    errors: list = []
    start = threading.Barrier(threads)

    def run(tid):
        try:
            start.wait()
            work(tid)
        except BaseException as e:  # noqa: BLE001 - reported to the main thread
            errors.append(e)

    ts = [threading.Thread(target=run, args=(t,)) for t in range(threads)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    return errors


def test_scalar_args_and_return_values_stay_per_launch():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def affine(a: ti.i32, b: ti.i32) -> ti.i32:
        s = 0
        for _i in range(64):  # a parallel loop, so the launch goes through the pool
            s += 1
        return a * 1000 + b + s - 64

    bad: list = []

    def work(tid):
        for k in range(LAUNCHES):
            got = affine(tid, k)  # the first calls of both threads race on the compile
            if got != tid * 1000 + k:
                bad.append((tid, k, got))

    assert _race(work) == []
    assert bad == []


def test_ndarray_args_stay_per_launch():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def fill(a: ti.types.ndarray(dtype=ti.f32, ndim=1), v: ti.f32):
        for i in a:
            a[i] = v

    arrays = [np.zeros(257, np.float32), np.zeros(1000, np.float32)]
    bad: list = []

    def work(tid):
        a = arrays[tid]
        for k in range(LAUNCHES // 3):
            fill(a, float(tid * 10000 + k))
            if not np.all(a == tid * 10000 + k):
                bad.append((tid, k))

    assert _race(work) == []
    assert bad == []


def test_different_kernels_share_the_pool_safely():
    ti.init(arch=ti.cpu)
    x = ti.field(ti.i64, 4096)
    y = ti.field(ti.i64, 4096)

    @ti.kernel
    def inc_x():
        for i in x:
            x[i] += 1

    @ti.kernel
    def inc_y():
        for i in y:
            y[i] += 2

    def work(tid):
        for _ in range(500):
            (inc_x if tid == 0 else inc_y)()

    assert _race(work) == []
    assert np.all(x.to_numpy() == 500) and np.all(y.to_numpy() == 1000)


def test_first_compile_races_across_many_threads():
    ti.init(arch=ti.cpu)
    z = ti.field(ti.f32, 8)

    @ti.kernel
    def g(t: ti.i32) -> ti.f32:
        acc = 0.0
        for i in range(8):
            acc += z[i] + t
        return acc

    out = {}

    def work(tid):
        out[tid] = g(tid)

    assert _race(work, threads=4) == []
    assert out == {t: 8.0 * t for t in range(4)}
