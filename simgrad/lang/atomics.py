"""ti.atomic_*: atomic read-modify-write on fields, ndarrays and locals, returning the old value."""

from __future__ import annotations

from simgrad.errors import SimgradSyntaxError


def _atomic(kind: str):
    def fn(dest, value):
        raise SimgradSyntaxError(f"ti.atomic_{kind} must be called inside a kernel with a field element, "
                                 "ndarray element or local variable as its first argument")

    fn.__name__ = f"atomic_{kind}"
    fn.atomic_kind = kind  # type: ignore[attr-defined]  # read back by frontend/calls.py
    return fn


atomic_add = _atomic("add")
atomic_sub = _atomic("sub")
atomic_mul = _atomic("mul")
atomic_min = _atomic("min")
atomic_max = _atomic("max")
atomic_and = _atomic("and")
atomic_or = _atomic("or")
atomic_xor = _atomic("xor")
