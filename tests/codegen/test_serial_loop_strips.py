"""Serial loops whose trip count is unknown or long run in strips of CANCEL_STRIDE iterations with a
Ctrl-C check before each (codegen/llvm.py serial_loop; the interrupt itself: tests/runtime/test_ctrl_c.py).
The strips must not change what the loop computes (break, bounds near the type's limits, empty ranges) nor
keep LLVM from vectorising the inner loop."""

from __future__ import annotations

import numpy as np

import simgrad as ti
from simgrad.codegen.llvm import CANCEL_STRIDE
from simgrad.runtime.jit import get_jit


def test_strips_keep_bounds_and_break():
    @ti.kernel
    def count(a: ti.i32, b: ti.i32, stop: ti.i32) -> ti.i64:
        s = ti.i64(0)
        for _ in range(1):
            for j in range(a, b):
                if j == stop:
                    break
                s += 1
        return s

    big = 2**31 - 1
    assert count(0, 3 * CANCEL_STRIDE + 5, -1) == 3 * CANCEL_STRIDE + 5
    assert count(0, 10**6, CANCEL_STRIDE + 7) == CANCEL_STRIDE + 7  # a break leaves every strip
    assert count(big - CANCEL_STRIDE - 3, big, 0) == CANCEL_STRIDE + 3  # no overflow at the top
    assert count(-2**31, -2**31 + 2 * CANCEL_STRIDE + 1, 0) == 2 * CANCEL_STRIDE + 1
    assert count(5, 3, -1) == 0 and count(4, 4, -1) == 0


def test_inner_loop_of_unknown_length_still_vectorises():
    z = ti.field(ti.i32, 4096)

    @ti.kernel
    def scale(n: ti.i32):
        for _ in range(1):
            for j in range(n):
                z[j] = z[j] * 3 + 1

    scale(4096)
    np.testing.assert_array_equal(z.to_numpy(), np.ones(4096, np.int32))
    text = scale._instance_for((4096,), "").llvm_text
    assert "stripbody" in text  # the loop watches Ctrl-C ...
    optimised = str(get_jit()._optimized(text, 0))
    assert "x i32>" in optimised  # ... and its inner loop is still vectorised
