"""Gradients need a floating-point field: asking for one on an integer field is a clear error, as in Taichi
(it was an AttributeError on the missing gradient field)."""

import pytest

import simgrad as ti


@pytest.mark.parametrize("make", [
    lambda: ti.field(ti.i32, shape=4, needs_grad=True),
    lambda: ti.Vector.field(2, ti.i32, shape=4, needs_grad=True),
    lambda: ti.field(ti.i64, shape=(), needs_dual=True),
])
def test_integer_field_with_gradient_is_refused(make):
    with pytest.raises(ti.SimgradRuntimeError,
                       match="not supported for field with `needs_grad=True` or `needs_dual=True`"):
        make()


def test_integer_field_without_gradient_and_float_field_with_one():
    assert ti.field(ti.i32, shape=4).grad is None
    f = ti.Vector.field(2, ti.f32, shape=4, needs_grad=True)
    f.grad.fill(1.0)
    assert f.grad.to_numpy().sum() == 8.0
