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
