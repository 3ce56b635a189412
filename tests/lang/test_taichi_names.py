"""Taichi's exception names catch simgrad's errors (`except ti.TaichiCompilationError` in existing programs),
and ti.set_logging_level takes Taichi's level names."""

from __future__ import annotations

import pytest

import simgrad as ti


def test_compile_errors_are_taichi_compilation_errors():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def bad():
        undefined_name_here += 1  # noqa: F821

    with pytest.raises(ti.TaichiCompilationError):
        bad()
    assert issubclass(ti.TaichiSyntaxError, ti.TaichiCompilationError) and issubclass(ti.TaichiSyntaxError,
                                                                                       SyntaxError)
    assert issubclass(ti.TaichiTypeError, TypeError) and issubclass(ti.TaichiIndexError, IndexError)
    assert issubclass(ti.TaichiNameError, NameError)


def test_runtime_errors_are_taichi_runtime_errors():
    ti.init(arch=ti.cpu, debug=True)
    x = ti.field(ti.f32, 4)

    @ti.kernel
    def check(v: ti.f32):
        assert v > 0, "v must be positive"
        x[0] = v

    with pytest.raises(ti.TaichiAssertionError):
        check(-1.0)
    with pytest.raises(ti.TaichiRuntimeError):
        check(-1.0)
    assert issubclass(ti.GradientError, ti.TaichiRuntimeError)


def test_set_logging_level():
    from simgrad.lang import logging as lg

    for name in (ti.TRACE, ti.DEBUG, ti.INFO, ti.WARN, ti.ERROR, "warning"):
        ti.set_logging_level(name)
    assert lg.level == ti.WARN
    with pytest.raises(ValueError, match="unknown logging level"):
        ti.set_logging_level("loud")
    ti.set_logging_level(ti.INFO)


def test_gpu_scheduling_hints_run_and_change_nothing():
    ti.init(arch=ti.cpu)
    n = 16
    a = ti.field(ti.f32, n + 2)
    b = ti.field(ti.f32, n)

    @ti.kernel
    def blur():
        ti.block_local(a)
        ti.cache_read_only(a)
        for i in range(n):
            j = ti.assume_in_range(i + 1, i, 0, 2)
            b[i] = (a[j - 1] + a[j] + a[j + 1]) / 3

    import numpy as np

    av = np.arange(n + 2, dtype=np.float32) ** 2
    a.from_numpy(av)
    blur()
    np.testing.assert_allclose(b.to_numpy(), (av[:-2] + av[1:-1] + av[2:]) / 3, rtol=1e-6)
