"""Scalar kernel arguments are converted as taichi 1.7.4 converts them, or refused with a located error: no
None becoming NaN, no string parsed as a number, no float silently truncated into an integer parameter."""

from __future__ import annotations

import numpy as np
import pytest

import simgrad as ti
from simgrad.errors import SimgradTypeError


def _kernels():
    ti.init(arch=ti.cpu)

    @ti.kernel
    def kf(a: ti.f32) -> ti.f32:
        return a

    @ti.kernel
    def ki(a: ti.i32) -> ti.i32:
        return a

    return kf, ki


@pytest.mark.parametrize("value, expected", [(1.5, 1.5), (np.float64(1.5), 1.5), (np.float32(0.25), 0.25),
                                             (3, 3.0), (np.int64(3), 3.0), (True, 1.0)])
def test_float_parameter_accepts_real_numbers(value, expected):
    kf, _ = _kernels()
    assert kf(value) == expected


@pytest.mark.parametrize("value", [None, "1.5", np.array(2.5), 1 + 2j, [1.0]])
def test_float_parameter_refuses_non_numbers(value):
    kf, _ = _kernels()
    with pytest.raises(SimgradTypeError, match="argument 'a' expects a f32") as info:
        kf(value)
    assert "test_arg_conversion.py" in str(info.value)  # located at the user's call


@pytest.mark.parametrize("value, expected", [(7, 7), (np.int64(7), 7), (np.uint8(5), 5), (True, 1)])
def test_int_parameter_accepts_integers(value, expected):
    _, ki = _kernels()
    assert ki(value) == expected


@pytest.mark.parametrize("value", [1.0, np.float64(1.5), np.float64(2.0), "3", None, np.array(4)])
def test_int_parameter_refuses_everything_else(value):
    _, ki = _kernels()
    with pytest.raises(SimgradTypeError, match="argument 'a' expects a i32"):
        ki(value)


def test_int_parameter_out_of_range_is_refused():
    _, ki = _kernels()
    with pytest.raises(SimgradTypeError, match="out of range for i32"):
        ki(2 ** 40)  # taichi 1.7.4 wraps it to 0
