"""print() inside kernels and formatted assert messages.

A formatted string whose values are kernel values (an f-string, `str.format`, `%`) is kept as a
FormattedString: literal text and (value, conversion) pieces. print turns it into one printf format
string for a PRINT statement; assert keeps its values as operands of the ASSERT statement and the
launcher formats the message on the host when the assertion fails (runtime/launch.py).

Format specs follow Taichi: a spec on a kernel value is a printf specification (`{x:.2f}`,
`{n:.10d}` is zero-padded to 10 digits, `{m:e}` applies to every entry of a matrix), its conversion must
match the value's type (d/i: signed, u/x/X/o: unsigned, e/E/f/F/g/G/a/A: float, else a located
"'<spec>' doesn't match '<type>'." error), a spec without a conversion keeps the type's own one
(`{x:.1}` of an f32 is `%.1f`), length modifiers are accepted and replaced by the right one. Python's
`<`/`>` alignment is accepted as printf's `-` flag / the default.
"""

from __future__ import annotations

import ast
import re
import string

from simgrad import dtypes as dt
from simgrad.errors import SimgradSyntaxError, SimgradTypeError
from simgrad.ir import context
from simgrad.ir.ops import Op
from simgrad.lang.expr import Expr
from simgrad.lang.matrix import Matrix

# a printf specification: flags, width, precision, length modifier, conversion
_PRINTF = re.compile(r"^%?([-+ #0]*)(\d*)(?:\.(\d*))?(hh|h|ll|l|j|z|t|L)?([a-zA-Z]?)$")
_SIGNED, _UNSIGNED, _FLOAT = "di", "uxXo", "eEfFgGaA"

Piece = str | tuple  # literal text, or (Expr, printf conversion such as "%.2f" / None: the type's own)


def _default(t: dt.DataType) -> str:
    if t.is_float:
        return "%.12f" if t.bits == 64 else "%f"
    if t.bits == 64:
        return "%lld" if t.is_signed else "%llu"
    return "%d" if t.is_signed else "%u"


def _length(t: dt.DataType) -> str:
    return "ll" if not t.is_float and t.bits == 64 else ""


def printf_spec(t: dt.DataType, spec: str) -> str:
    """The printf conversion for a value of type t formatted with `spec` (Taichi's rules, see above)."""
    conv = spec[-1:] if spec[-1:].isalpha() else ""
    if conv in ("c", "s", "p", "n"):
        raise SimgradTypeError(f"conversion '{conv}' is not supported.")
    if conv and not (t.is_float and conv in _FLOAT or not t.is_float and conv in (_SIGNED if t.is_signed
                                                                                     else _UNSIGNED)):
        raise SimgradTypeError(f"'{spec}' doesn't match '{t}'.")
    body = spec[1:] if spec[:1] in "<>" and len(spec) > 1 else spec  # Python alignment: < is printf's -
    m = _PRINTF.match(body)
    if m is None or (conv and conv not in _SIGNED + _UNSIGNED + _FLOAT):
        raise SimgradSyntaxError(f"'{spec}' is not a valid printf specifier (use e.g. '.2f', '8d', '-8.3e', "
                                 "'.10d')")
    flags, width, prec, _, _ = m.groups()
    default = _default(t)
    if spec[:1] == "<":
        flags = "-" + flags.replace("-", "")
    if prec is None and t.is_float and t.bits == 64:
        prec = "12"  # f64 keeps its default precision under a spec without one (as Taichi)
    return ("%" + flags + width + ("." + prec if prec is not None else "") + _length(t)
            + (conv or default[-1]))


class FormattedString:
    """A string with kernel values in it, kept as pieces until printed or used as an assert message."""

    def __init__(self, pieces: list[Piece]):
        self.pieces = pieces

    @property
    def values(self) -> list[Expr]:
        return [p[0] for p in self.pieces if isinstance(p, tuple)]

    def printf(self) -> str:
        return "".join(p.replace("%", "%%") if isinstance(p, str) else p[1] or _default(p[0].dtype)
                       for p in self.pieces)

    def template(self) -> list:
        """The pieces with each value as (position, conversion, type name): what the launcher needs to
        format an assert message from the values the kernel reported."""
        out: list = []
        k = 0
        for p in self.pieces:
            if isinstance(p, str):
                out.append(p)
            else:
                out.append((k, p[1], p[0].dtype.name))
                k += 1
        return out

    def __str__(self) -> str:
        return self.printf()

    def __add__(self, other):
        return FormattedString(self.pieces + _pieces(other))

    def __radd__(self, other):
        return FormattedString(_pieces(other) + self.pieces)

    @staticmethod
    def from_ast(comp, node: ast.JoinedStr) -> str | FormattedString:
        pieces: list[Piece] = []
        for part in node.values:
            if isinstance(part, ast.Constant):
                pieces.append(str(part.value))
                continue
            assert isinstance(part, ast.FormattedValue)  # the only other part of an f-string
            v = comp.eval(part.value)
            spec = ""
            if part.format_spec is not None:
                s = comp.eval(part.format_spec)
                if isinstance(s, FormattedString):
                    raise SimgradSyntaxError("a format spec in a kernel must be known at compile time",
                                             comp.loc(part))
                spec = s
            if not spec and not isinstance(v, (Expr, Matrix, FormattedString)):
                conv = {ord("r"): repr, ord("a"): ascii}.get(part.conversion, str)
                pieces.append(conv(v))
                continue
            pieces += _format(v, spec)
        return _simplify(pieces)


def _pieces(v) -> list[Piece]:
    return v.pieces if isinstance(v, FormattedString) else [str(v)]


def _simplify(pieces: list[Piece]) -> str | FormattedString:
    """A plain str when no kernel value remains (so compile-time strings stay Python strings)."""
    if all(isinstance(p, str) for p in pieces):
        return "".join(pieces)  # type: ignore[arg-type]
    return FormattedString(pieces)


def _format(v, spec: str = "") -> list[Piece]:
    """The pieces of one value formatted with a (Taichi) format spec, matrices entry by entry."""
    if isinstance(v, FormattedString):
        return list(v.pieces)
    if isinstance(v, Expr):
        return [(v, printf_spec(v.dtype, spec) if spec else None)]
    if isinstance(v, Matrix):
        rows = [_format(e, spec) for e in v.entries] if v.m == 0 else \
            [_format(v._row(r), spec) for r in range(v.n)]
        out: list[Piece] = ["["]
        for i, r in enumerate(rows):
            out += ([", "] if i else []) + r
        return out + ["]"]
    if isinstance(v, (list, tuple)) and not spec:
        out = ["["]
        for i, e in enumerate(v):
            out += ([", "] if i else []) + _format(e)
        return out + ["]"]
    if spec and isinstance(v, (bool, int, float)):  # a number with a spec is a kernel constant (as Taichi)
        b = context.builder()
        from simgrad.lang import operators

        e = Expr(b.const(True if v else False, dt.u1)) if isinstance(v, bool) else operators.to_expr(v)
        return [(e, printf_spec(e.dtype, spec))]
    return [format(v, spec) if spec else str(v)]


def str_format(fmt: str, args: tuple, kwargs: dict) -> str | FormattedString:
    """`fmt.format(*args, **kwargs)` in a kernel. As in Taichi, `{}` fields count from 0 whatever manual
    `{n}` fields there are, and every positional and keyword argument must be used."""
    pieces: list[Piece] = []
    auto, top, used = 0, -1, set()
    for literal, field, spec, conversion in string.Formatter().parse(fmt):
        if literal:
            pieces.append(literal)
        if field is None:
            continue
        if spec and "{" in spec:
            raise SimgradSyntaxError("nested fields in a format spec are not supported in kernels")
        if field == "":
            index: int | str = auto
            auto += 1
        elif field.isdigit():
            index = int(field)
        elif field.isidentifier():
            index = field
        else:
            raise SimgradSyntaxError(f"field '{{{field}}}' is not supported in kernel strings: use "
                                     "'{}', '{0}' or '{name}'")
        if isinstance(index, int):
            top = max(top, index)
            v = args[index] if index < len(args) else None
        else:
            if index not in kwargs:
                raise SimgradSyntaxError(f"Keyword '{index}' not found.")
            used.add(index)
            v = kwargs[index]
        if not spec and not isinstance(v, (Expr, Matrix, FormattedString)):
            pieces.append(repr(v) if conversion == "r" else str(v))
        else:
            pieces += _format(v, spec or "")
    expected = max(auto, top + 1)
    if expected != len(args):
        raise SimgradSyntaxError(f"Expected {expected} positional argument(s), but received {len(args)} "
                                 "instead.")
    for k in kwargs:
        if k not in used:
            raise SimgradSyntaxError(f"Keyword '{k}' not used.")
    return _simplify(pieces)


_PERCENT = re.compile(r"%(?:\((\w+)\))?([-+ #0]*)(\d*)(?:\.(\d*))?[hlL]?([diouxXeEfFgGcrsa%])")


def percent_format(fmt: str, args) -> str | FormattedString:
    """`fmt % args` in a kernel with kernel values among args: printf-like conversions of each value
    (Python's leniency kept: %d of a float truncates, %f of an int converts, %s is the default format)."""
    from simgrad.lang import operators

    values = args.values() if isinstance(args, dict) else args if isinstance(args, tuple) else (args,)
    if not any(isinstance(v, (Expr, Matrix, FormattedString)) for v in values):
        return fmt % args
    mapping = args if isinstance(args, dict) else None
    seq = list(args) if isinstance(args, tuple) else [args]
    pieces: list[Piece] = []
    pos, k = 0, 0
    for m in _PERCENT.finditer(fmt):
        pieces.append(fmt[pos:m.start()])
        pos = m.end()
        key, flags, width, prec, conv = m.groups()
        if conv == "%":
            pieces.append("%")
            continue
        if mapping is not None and key is not None:
            v = mapping[key]
        else:
            if k >= len(seq):
                raise SimgradSyntaxError("not enough arguments for format string")
            v, k = seq[k], k + 1
        if not isinstance(v, (Expr, Matrix, FormattedString)):
            pieces.append(m.group(0) % v if conv not in "sr" else (repr(v) if conv == "r" else str(v)))
            continue
        if conv in "sr" or not isinstance(v, Expr):
            pieces += _format(v)
            continue
        if conv == "c":
            raise SimgradTypeError("conversion 'c' is not supported.")
        t = v.dtype
        if conv in "diu":
            if t.is_float:
                v = operators.cast(v, dt.i64)
            conv = "d" if v.dtype.is_signed else "u"
        elif conv in "xXo" and t.is_float:
            raise SimgradTypeError(f"%{conv} format: an integer is required, not {t}")
        elif conv in _FLOAT and not t.is_float:
            v = operators.cast(v, dt.f64)
        spec = flags + width + ("." + prec if prec is not None else "")
        pieces.append((v, "%" + spec + _length(v.dtype) + conv))
    if mapping is None and k < len(seq):
        raise SimgradSyntaxError("not all arguments converted during string formatting")
    pieces.append(fmt[pos:])
    return _simplify([p for p in pieces if p != ""])


def emit_print(comp, args, kwargs) -> None:
    sep = kwargs.get("sep", " ")
    end = kwargs.get("end", "\n")
    pieces: list[Piece] = []
    for i, a in enumerate(args):
        pieces += ([sep] if i else []) + _format(a)
    s = FormattedString(pieces + [end])
    comp.builder.emit(Op.PRINT, None, tuple(v.stmt for v in s.values), {"format": s.printf()})
