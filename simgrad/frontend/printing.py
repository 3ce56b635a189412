"""print() inside kernels: one PRINT statement with a printf format string built at compile time."""

from __future__ import annotations

import ast
import re

from simgrad import dtypes as dt
from simgrad.errors import SimgradSyntaxError, SimgradTypeError
from simgrad.ir.ops import Op
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix


def _spec(e: Expr) -> str:
    t = e.dtype
    if t.is_float:
        return "%.12f" if t.bits == 64 else "%f"
    if t.bits == 64:
        return "%lld" if t.is_signed else "%llu"
    return "%d" if t.is_signed else "%u"


_PY_SPEC = re.compile(r"^(?:.?[<>^=])?([+\- ]?)(#?)(0?)(\d*)(?:\.(\d+))?([dxXoeEfFgG]?)$")


def _printf_spec(e: Expr, spec: str) -> tuple[str, Expr]:
    """A Python format spec (`{x:8.3f}`) as a printf conversion for one kernel value: printf needs the
    `ll` length for 64-bit ints and a double for float conversions of ints."""
    from simgrad.lang import ops

    m = _PY_SPEC.match(spec)
    if m is None:
        raise SimgradSyntaxError(f"format spec ':{spec}' is not supported in kernel print (use e.g. "
                                 "':8.3f', ':d', ':x')")
    sign, alt, zero, width, prec, kind = m.groups()
    flags = ("-" if re.match(r"^.?<", spec) else "") + sign.replace("-", "") + alt + zero
    t = e.dtype
    if t.is_float and kind in "dxXo" and kind:
        raise SimgradTypeError(f"format code '{kind}' needs an integer value, got {t}")
    if kind in ("", "d") and not t.is_float:
        kind = "d" if t.is_signed else "u"
    elif kind == "":
        kind = "g"
    if kind in "eEfFgG" and not t.is_float:
        e = ops.cast(e, dt.f64)
    length = "ll" if not e.dtype.is_float and e.dtype.bits == 64 else ""
    return "%" + flags + width + ("." + prec if prec else "") + length + kind, e


class FormattedString:
    """An f-string with kernel values in it, kept as (format, values) until printed."""

    def __init__(self, fmt: str, values: list):
        self.fmt, self.values = fmt, values

    @staticmethod
    def from_ast(comp, node: ast.JoinedStr) -> FormattedString:
        fmt, values = "", []
        for part in node.values:
            if isinstance(part, ast.Constant):
                fmt += str(part.value).replace("%", "%%")
            else:
                assert isinstance(part, ast.FormattedValue)  # the only other part of an f-string
                v = comp.eval(part.value)
                spec = comp.eval(part.format_spec).fmt if part.format_spec is not None else ""
                f, vals = _format(v, spec)
                fmt += f
                values += vals
        return FormattedString(fmt, values)

    def __str__(self):
        return self.fmt


def _format(v, spec: str = "") -> tuple[str, list]:
    if isinstance(v, FormattedString):
        return v.fmt, v.values
    if isinstance(v, Expr):
        if spec:
            f, v = _printf_spec(v, spec.lstrip(":"))
            return f, [v]
        return _spec(v), [v]
    if isinstance(v, Matrix):
        if v.m == 0:
            parts = [_format(e, spec) for e in v.entries]
        else:
            parts = [_format(v._row(r), spec) for r in range(v.n)]
        return "[" + ", ".join(p[0] for p in parts) + "]", [x for p in parts for x in p[1]]
    text = format(v, spec) if spec else str(v)
    return text.replace("%", "%%"), []


def emit_print(comp, args, kwargs) -> None:
    sep = kwargs.get("sep", " ")
    end = kwargs.get("end", "\n")
    pieces = [_format(a) for a in args]
    fmt = sep.replace("%", "%%").join(p[0] for p in pieces) + end.replace("%", "%%")
    values = [v for p in pieces for v in p[1]]
    comp.builder.emit(Op.PRINT, None, tuple(v.stmt for v in values), {"format": fmt})
