"""Expressions seen while a kernel is being compiled: a typed IR value with Python operators.

User code inside kernels and library helpers (matrix methods, ti.math) compute on `Expr`s with plain
Python operators; every operator emits IR into the kernel under construction."""

from __future__ import annotations

from simgrad.errors import SimgradSyntaxError


class Expr:
    __slots__ = ("stmt",)

    def __init__(self, stmt):
        self.stmt = stmt

    @property
    def dtype(self):
        return self.stmt.type

    def __repr__(self) -> str:
        return f"Expr({self.stmt!r})"

    def __bool__(self):
        from simgrad.ir.context import current_loc

        raise SimgradSyntaxError(
            "a kernel value was used where Python needs a compile-time bool (e.g. in a plain Python "
            "`if`/`and`/`or` inside a helper function); use ti.select(), or ti.static() for compile-time "
            "conditions",
            current_loc(),
        )

    def __hash__(self):
        return id(self)

    # arithmetic: all defined by lang.operators so that Python numbers and matrices mix freely
    def __add__(self, o):
        return _ops().add(self, o)

    def __radd__(self, o):
        return _ops().add(o, self)

    def __sub__(self, o):
        return _ops().sub(self, o)

    def __rsub__(self, o):
        return _ops().sub(o, self)

    def __mul__(self, o):
        return _ops().mul(self, o)

    def __rmul__(self, o):
        return _ops().mul(o, self)

    def __truediv__(self, o):
        return _ops().truediv(self, o)

    def __rtruediv__(self, o):
        return _ops().truediv(o, self)

    def __floordiv__(self, o):
        return _ops().floordiv(self, o)

    def __rfloordiv__(self, o):
        return _ops().floordiv(o, self)

    def __mod__(self, o):
        return _ops().mod(self, o)

    def __rmod__(self, o):
        return _ops().mod(o, self)

    def __pow__(self, o):
        return _ops().pow(self, o)

    def __rpow__(self, o):
        return _ops().pow(o, self)

    def __neg__(self):
        return _ops().neg(self)

    def __pos__(self):
        return self

    def __abs__(self):
        return _ops().abs(self)

    def __invert__(self):
        return _ops().bit_not(self)

    def __and__(self, o):
        return _ops().bit_and(self, o)

    def __rand__(self, o):
        return _ops().bit_and(o, self)

    def __or__(self, o):
        return _ops().bit_or(self, o)

    def __ror__(self, o):
        return _ops().bit_or(o, self)

    def __xor__(self, o):
        return _ops().bit_xor(self, o)

    def __rxor__(self, o):
        return _ops().bit_xor(o, self)

    def __lshift__(self, o):
        return _ops().shl(self, o)

    def __rlshift__(self, o):
        return _ops().shl(o, self)

    def __rshift__(self, o):
        return _ops().shr(self, o)

    def __rrshift__(self, o):
        return _ops().shr(o, self)

    def __lt__(self, o):
        return _ops().lt(self, o)

    def __le__(self, o):
        return _ops().le(self, o)

    def __gt__(self, o):
        return _ops().gt(self, o)

    def __ge__(self, o):
        return _ops().ge(self, o)

    def __eq__(self, o):  # type: ignore[override]
        return _ops().eq(self, o)

    def __ne__(self, o):  # type: ignore[override]
        return _ops().ne(self, o)


def _ops():
    from simgrad.lang import operators

    return operators
