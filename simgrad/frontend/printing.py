"""print() inside kernels: one PRINT statement with a printf format string built at compile time."""

from __future__ import annotations

import ast

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
            return "%" + spec.lstrip(":"), [v]
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
