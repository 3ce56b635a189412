"""Fields of a program dropped by ti.reset() or a later ti.init() refuse every use with a located error
(they used to return stale values in Python scope and segfault in kernels), and debug mode turns every
out-of-range index into a located error: fields indexed through casts of negative floats to unsigned types,
ndarrays, and run-time indices into local vectors (loads and stores)."""

from __future__ import annotations

import numpy as np
import pytest

import simgrad as ti
from simgrad.errors import SimgradAssertionError, SimgradError, SimgradIndexError


def _program():
    ti.init(arch=ti.cpu)
    x = ti.field(ti.f32, 4)
    v = ti.Vector.field(2, ti.f32, 4, needs_grad=True)

    @ti.kernel
    def k():
        for i in x:
            x[i] = 1
            v[i] = [1, 2]

    k()
    return x, v, k


@pytest.mark.parametrize("drop", ["reset", "init"])
def test_fields_of_a_released_program_refuse_use(drop):
    x, v, k = _program()
    if drop == "reset":
        ti.reset()
    else:
        ti.init(arch=ti.cpu)
    uses = [lambda: x[0], lambda: x.__setitem__(1, 3.0), lambda: x.to_numpy(), lambda: x.fill(2),
            lambda: v[0], lambda: v.grad[1], lambda: v.to_numpy(), lambda: v.from_numpy(np.zeros((4, 2)))]
    for use in uses:
        with pytest.raises(SimgradError, match="released") as info:
            use()
        assert "test_released_and_debug_bounds.py" in str(info.value)
    with pytest.raises(SimgradError, match="field x belongs to a program") as info:
        k()  # recompiles for the new program and meets the old field
    assert "for i in x:" in str(info.value)  # the struct-for over it is the first use


def test_new_fields_after_init_work_and_kernels_recompile():
    x, v, k = _program()
    ti.init(arch=ti.cpu)
    y = ti.field(ti.f32, 4)

    @ti.kernel
    def g():
        for i in y:
            y[i] = i * 2

    g()
    np.testing.assert_array_equal(y.to_numpy(), [0, 2, 4, 6])


def test_debug_cast_of_negative_float_to_unsigned_index():
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.f32, 8)

    @ti.kernel
    def k(f: ti.f32):
        x[ti.cast(f, ti.u8)] = 1.0

    with pytest.raises(SimgradIndexError, match="out of bounds"):
        k(-300.0)


def test_debug_ndarray_index():
    ti.init(arch=ti.cpu, debug=True)

    @ti.kernel
    def k(arr: ti.types.ndarray(), j: ti.i32):
        arr[j] = 1.0

    with pytest.raises(SimgradIndexError, match="out of bounds"):
        k(np.zeros(4, np.float32), 4)


@pytest.mark.parametrize("j", [3, -1, 100])
def test_debug_dynamic_index_into_local_vector(j):
    ti.init(arch=ti.cpu, debug=True)

    @ti.kernel
    def load(j: ti.i32) -> ti.f32:
        v = ti.Vector([1.0, 2.0, 3.0])
        return v[j]

    @ti.kernel
    def store(j: ti.i32) -> ti.f32:
        v = ti.Vector([1.0, 2.0, 3.0])
        v[j] = 7.0
        return v.sum()

    @ti.kernel
    def matrix(j: ti.i32) -> ti.f32:
        m = ti.Matrix([[1.0, 2.0], [3.0, 4.0]])
        return m[1, j]

    assert load(1) == 2.0 and store(0) == 12.0 and matrix(1) == 4.0
    for kern in (load, store):
        with pytest.raises(SimgradAssertionError, match="index out of range for a local vector"):
            kern(j)
    with pytest.raises(SimgradAssertionError, match="index out of range"):
        matrix(j - 1 if j == 3 else j)  # 2 is out of range for the column dimension too
