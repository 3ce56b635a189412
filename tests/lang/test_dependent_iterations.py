"""A top-level loop whose iterations depend on each other through a field (a race by Taichi's rule) still runs
in order at one thread, as taichi 1.7.4 runs it (values checked against that order, computed in numpy): the
compiler may tell LLVM that a loop's iterations are independent only when they are (passes/parallel_strategy.py
`independent`)."""

from __future__ import annotations

import numpy as np
import pytest

import simgrad as ti


@pytest.mark.parametrize("dtype", [ti.f32, ti.f64])
def test_loops_reading_what_an_earlier_iteration_wrote_run_in_order_at_one_thread(dtype):
    ti.init(arch=ti.cpu, cpu_max_num_threads=1)
    if ti.lang.impl.current_cfg().arch != ti.cpu:  # TI_ARCH=cuda: a GPU runs such a loop's iterations at once
        pytest.skip("in-order iterations are the one-thread CPU's behaviour (a GPU races, as taichi's does)")
    n = 200
    x = ti.field(dtype, shape=n)
    y = ti.field(dtype, shape=n)
    a = ti.ndarray(dtype, shape=n)

    @ti.kernel
    def count_up():
        for i in range(1, n):
            x[i] = x[i - 1] + 1.0

    @ti.kernel
    def relax():
        for i in range(1, n - 1):
            y[i] = (y[i - 1] + y[i + 1]) * 0.5

    @ti.kernel
    def shift_in(src: ti.types.ndarray(), dst: ti.types.ndarray()):
        for i in range(1, n):
            dst[i] = src[i - 1] * 2.0

    count_up()
    np.testing.assert_array_equal(x.to_numpy(), np.arange(n))
    y0 = (np.arange(n) ** 2 % 7).astype(dtype.np)
    y.from_numpy(y0)
    relax()
    want = y0.copy()
    for i in range(1, n - 1):
        want[i] = (want[i - 1] + want[i + 1]) * dtype.np.type(0.5)
    np.testing.assert_array_equal(y.to_numpy(), want)
    a.from_numpy(np.ones(n, dtype.np))
    shift_in(a, a)  # the same array twice: iteration i reads what iteration i - 1 wrote
    with np.errstate(over="ignore"):
        np.testing.assert_array_equal(a.to_numpy(), (2.0 ** np.arange(n)).astype(dtype.np))
