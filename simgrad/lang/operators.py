"""Scalar operations shared by both scopes: Python numbers fold in Python, kernel values emit IR.

Matrices dispatch element-wise to these. Typing follows Taichi: Python literals adopt the type of the
kernel value they meet (an int literal with a float value becomes that float type), otherwise
`default_ip`/`default_fp`; mixed kernel values promote (dtypes.promote)."""

from __future__ import annotations

import builtins
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from simgrad import dtypes as dt
from simgrad.errors import SimgradSyntaxError, SimgradTypeError
from simgrad.ir import context, numeric
from simgrad.ir.opdefs import OpDef
from simgrad.ir.ops import OPS, Op
from simgrad.lang.expr import Expr

_PY_NUM = (int, float, bool)


def _np_scalar(x):
    """A numpy scalar, or a 0-d numpy array (a compile-time constant either way)."""
    import numpy as np

    return isinstance(x, np.generic) or (isinstance(x, np.ndarray) and x.ndim == 0)


def is_matrix(x) -> bool:
    """(Matrix's class flag: no import per call, every scalar operation in both scopes asks.)"""
    return getattr(type(x), "_is_matrix", False)


def _literal_type(v, like: dt.DataType | None) -> dt.DataType:
    """A float literal adopts a float `like` (x_f64 * 0.1 stays exact); an int literal adopts a float
    `like`, and with an int `like` is default_ip promoted with it, as in Taichi: u8 * 10000 is an i32,
    not a u8 that wraps (and an i64 value keeps i64 literals)."""
    if _np_scalar(v):
        return dt.from_numpy(v.dtype)
    if isinstance(v, float):
        return like if like is not None and like.is_float else dt.Defaults.fp
    if like is None:
        return dt.Defaults.ip
    return like if like.is_float else dt.promote(like, dt.Defaults.ip)


def to_expr(v, like: dt.DataType | None = None) -> Expr:
    if isinstance(v, Expr):
        return v
    if isinstance(v, _PY_NUM) or _np_scalar(v):
        t = _literal_type(v, like)
        value = v.item() if _np_scalar(v) else v
        if isinstance(value, int) and not isinstance(value, bool) and not t.is_float:
            _check_literal(value, t)
        return Expr(context.builder().const(value, t))
    raise SimgradTypeError(f"unsupported operand type: cannot use a {type(v).__name__} value in a kernel "
                           "expression", context.current_loc())


def _check_literal(v: int, t: dt.DataType) -> None:
    """An integer literal must fit its type (Taichi refuses too) rather than wrap silently; a negative
    literal meeting an unsigned value is its two's complement (`u - (-1)`), as in Taichi."""
    lo = -(1 << (t.bits - 1))
    hi = (1 << (t.bits - 1 if t.is_signed else t.bits)) - 1
    if not lo <= v <= hi:
        hint = "default_ip" if t is dt.Defaults.ip else "its type"
        raise SimgradTypeError(f"integer literal {v} exceeded the range of {hint} {t} ([{lo}, {hi}]); give it a "
                               f"wider type, e.g. ti.i64({v}) or ti.u64({v}), or set default_ip in ti.init()",
                               context.current_loc())


def _int_literal(v: int) -> Expr:
    """An explicitly cast Python int: the narrowest of default_ip, i64, u64 that holds it."""
    for t in (dt.Defaults.ip, dt.i64, dt.u64):
        if -(1 << (t.bits - 1)) <= v < (1 << (t.bits - 1 if t.is_signed else t.bits)):
            return Expr(context.builder().const(v, t))
    return to_expr(v, dt.u64)  # raises: no 64-bit type holds it


def cast_expr(e: Expr, t: dt.DataType) -> Expr:
    s = e.stmt
    if s.op is Op.CONST and s.type.is_float and not t.is_float and t is not dt.u1 \
            and numeric.convert(s.attrs["value"], s.type, t) is None:
        raise SimgradTypeError(f"converting the constant {s.attrs['value']!r} to {t} is undefined (NaN, infinite "
                               f"or out of {t}'s range); the machine result would be arbitrary",
                               context.current_loc())
    return Expr(context.builder().cast(s, t))


def _pair(a, b) -> tuple[Expr, Expr]:
    if isinstance(a, Expr) and isinstance(b, Expr):
        t = dt.promote(a.dtype, b.dtype)
        return cast_expr(a, t), cast_expr(b, t)
    if isinstance(a, Expr):
        b = to_expr(b, a.dtype)
    else:
        a = to_expr(a, b.dtype)
    t = dt.promote(a.dtype, b.dtype)
    return cast_expr(a, t), cast_expr(b, t)


def _emit2(op: Op, a: Expr, b: Expr) -> Expr:
    return Expr(context.builder().binary(op, a.stmt, b.stmt))


def _emit1(op: Op, a: Expr) -> Expr:
    return Expr(context.builder().unary(op, a.stmt))


def _elementwise(fn, *args):
    from simgrad.lang.matrix import Matrix

    return Matrix._map(fn, *args)


_PY_NUM_TYPES = frozenset(_PY_NUM)


def _binary(pyfn, irfn):
    def op(a, b):
        if type(a) in _PY_NUM_TYPES and type(b) in _PY_NUM_TYPES:  # Python scope's numbers, first
            return pyfn(a, b)
        if is_matrix(a) or is_matrix(b):
            return _elementwise(op, a, b)
        if not isinstance(a, Expr) and not isinstance(b, Expr):
            return pyfn(a, b)
        return irfn(*_pair(a, b))

    return op


def _py_div(a, b):
    return a / b


def _ir_truediv(a: Expr, b: Expr) -> Expr:
    if not a.dtype.is_float:
        a, b = cast_expr(a, dt.Defaults.fp), cast_expr(b, dt.Defaults.fp)
    return _emit2(Op.DIV, a, b)


def _ir_floordiv(a: Expr, b: Expr) -> Expr:
    if a.dtype.is_float:
        return _emit1(Op.FLOOR, _emit2(Op.DIV, a, b))
    return _emit2(Op.FLOORDIV, a, b)


def _ir_mod(a: Expr, b: Expr) -> Expr:
    if a.dtype.is_float:
        return sub(a, mul(_emit1(Op.FLOOR, _emit2(Op.DIV, a, b)), b))
    return _emit2(Op.MOD, a, b)


def _ir_pow(a: Expr, b: Expr) -> Expr:
    if a.dtype.is_float:
        return _emit2(Op.POW, a, b)
    return _int_pow(a, b)


def _int_pow(base: Expr, e: Expr) -> Expr:
    """Integer power with a run-time exponent, as Taichi computes it: squaring over every bit of the
    exponent, wrapping in the type (through f64 it was inexact beyond 2**53 and undefined beyond the
    type); a negative exponent gives 1, as Taichi does outside debug mode. Branch-free: selects only."""
    t = base.dtype
    one = to_expr(1, t)
    result, p = one, base
    for k in range(t.bits - 1 if t.is_signed else t.bits):
        bit = ne(bit_and(shr(e, k), 1), 0)
        result = select(bit, mul(result, p), result)
        if k < t.bits - 2:
            p = mul(p, p)
    return select(lt(e, 0), one, result) if t.is_signed else result


def _ipow(base: Expr, n: int) -> Expr:
    """x ** n for a compile-time integer n: repeated squaring, as exact as multiplication."""
    if n == 0:
        return cast_expr(to_expr(1, base.dtype), base.dtype)
    if n < 0:
        if not base.dtype.is_float:  # Taichi refuses it when compiling (alg_simp), in every mode
            from simgrad.errors import SimgradRuntimeError

            raise SimgradRuntimeError(f"Negative exponent in pow(int, int) is not allowed: {base.dtype} ** {n} "
                                      "(make the base a float for 1 / x ** n)", context.current_loc())
        return truediv(1.0, _ipow(base, -n))
    result: Expr | None = None
    p = base
    while n:
        if n & 1:
            result = p if result is None else mul(result, p)
        n >>= 1
        if n:
            p = mul(p, p)
    assert result is not None  # n > 0 here: some bit was set
    return result


def pow(a, b):  # noqa: A001
    if is_matrix(a) or is_matrix(b):
        return _elementwise(pow, a, b)
    if not isinstance(a, Expr) and not isinstance(b, Expr):
        return a**b
    if isinstance(a, Expr) and isinstance(b, int) and not isinstance(b, bool) and \
            (builtins.abs(b) <= 32 or (not a.dtype.is_float and b > 0)):
        return _ipow(a, b)
    return _ir_pow(*_pair(a, b))


def _cmp(pyop, op: Op):
    return _binary(lambda a, b: int(pyop(a, b)), lambda a, b: _emit2(op, a, b))


add = _binary(lambda a, b: a + b, lambda a, b: _emit2(Op.ADD, a, b))
sub = _binary(lambda a, b: a - b, lambda a, b: _emit2(Op.SUB, a, b))
mul = _binary(lambda a, b: a * b, lambda a, b: _emit2(Op.MUL, a, b))
truediv = _binary(_py_div, _ir_truediv)
floordiv = _binary(lambda a, b: a // b, _ir_floordiv)
mod = _binary(lambda a, b: a % b, _ir_mod)
raw_div = _binary(lambda a, b: numeric.c_div(a, b) if isinstance(a, int) and isinstance(b, int) else a / b,
                  lambda a, b: _emit2(Op.RAW_DIV if not a.dtype.is_float else Op.DIV, a, b))
raw_mod = _binary(lambda a, b: math.fmod(a, b) if isinstance(a, float) or isinstance(b, float)
                  else int(math.fmod(a, b)), lambda a, b: _emit2(Op.RAW_MOD, a, b))
bit_and = _binary(lambda a, b: a & b, lambda a, b: _emit2(Op.BIT_AND, a, b))
bit_or = _binary(lambda a, b: a | b, lambda a, b: _emit2(Op.BIT_OR, a, b))
bit_xor = _binary(lambda a, b: a ^ b, lambda a, b: _emit2(Op.BIT_XOR, a, b))
lt = _cmp(lambda a, b: a < b, Op.LT)
le = _cmp(lambda a, b: a <= b, Op.LE)
gt = _cmp(lambda a, b: a > b, Op.GT)
ge = _cmp(lambda a, b: a >= b, Op.GE)
eq = _cmp(lambda a, b: a == b, Op.EQ)
ne = _cmp(lambda a, b: a != b, Op.NE)


def _shift(pyfn, op: Op):
    def f(a, b):
        if is_matrix(a) or is_matrix(b):
            return _elementwise(f, a, b)
        if not isinstance(a, Expr) and not isinstance(b, Expr):
            return pyfn(a, b)
        a = to_expr(a, b.dtype if isinstance(b, Expr) else None)
        b = cast_expr(to_expr(b, a.dtype), a.dtype)
        return _emit2(op, a, b)

    return f


shl = _shift(lambda a, b: a << b, Op.SHL)
shr = _shift(lambda a, b: a >> b, Op.SHR)


def bit_shr(a, b):
    """Logical right shift (zero fill), Taichi's ti.bit_shr."""
    if not isinstance(a, Expr):
        return a >> b
    u = {dt.i8: dt.u8, dt.i16: dt.u16, dt.i32: dt.u32, dt.i64: dt.u64}.get(a.dtype, a.dtype)
    r = shr(Expr(context.builder().emit(Op.BITCAST, u, (a.stmt,))) if u is not a.dtype else a, b)
    return Expr(context.builder().emit(Op.BITCAST, a.dtype, (r.stmt,))) if u is not a.dtype else r


def _minmax(pyfn, op: Op):
    two = _binary(pyfn, lambda a, b: _emit2(op, a, b))

    def f(*args):
        if len(args) == 1:
            (only,) = args
            if is_matrix(only):
                return only.max() if op is Op.MAX else only.min()
            args = tuple(only)
        result = args[0]
        for a in args[1:]:
            result = two(result, a)
        return result

    f.__name__ = f.__qualname__ = op.name.lower()  # ti.max / ti.min, as Taichi names them
    return f


max = _minmax(lambda a, b: numeric.minmax(builtins.max, a, b), Op.MAX)  # noqa: A001
min = _minmax(lambda a, b: numeric.minmax(builtins.min, a, b), Op.MIN)  # noqa: A001


def neg(a):
    if is_matrix(a):
        return _elementwise(neg, a)
    if not isinstance(a, Expr):
        return -a
    return _emit1(Op.NEG, a)


def abs(a):  # noqa: A001
    if is_matrix(a):
        return _elementwise(abs, a)
    if not isinstance(a, Expr):
        return builtins.abs(a)
    if not a.dtype.is_float and not a.dtype.is_signed:
        return a  # an unsigned value is its own absolute value (llvm.abs would read it as signed)
    return _emit1(Op.ABS, a)


def bit_not(a):
    if is_matrix(a):
        return _elementwise(bit_not, a)
    if not isinstance(a, Expr):
        return ~a
    return _emit1(Op.BIT_NOT, a)


def logical_not(a):
    if is_matrix(a):
        return _elementwise(logical_not, a)
    if not isinstance(a, Expr):
        return int(not a)
    if a.dtype.is_float:  # Taichi's type check: `not x` needs an integer (compare with 0 for a float)
        raise SimgradTypeError(f"'logical_not' takes integral inputs only, got {a.dtype} (write x == 0)",
                               context.current_loc())
    return _emit1(Op.LOGICAL_NOT, a)


def logical_and(a, b):
    return bit_and(ne(a, 0), ne(b, 0))


def logical_or(a, b):
    return bit_or(ne(a, 0), ne(b, 0))


def _math_function(d: OpDef):
    """ti.<name> / ti.math.<name> of a registry math function (ir/opdefs.py): elementwise on matrices, the
    Python value on Python numbers, else the op on the operands promoted together (integers to default_fp)."""

    def f(*args):
        if len(args) != d.arity:
            raise SimgradTypeError(f"{d.name}() takes {d.arity} argument{'s' if d.arity > 1 else ''}, got "
                                   f"{len(args)}", context.current_loc())
        if builtins.any(is_matrix(a) for a in args):
            return _elementwise(f, *args)
        if not builtins.any(isinstance(a, Expr) for a in args):
            assert d.python is not None
            return d.python(*args)
        xs = list(_pair(*args)) if d.arity == 2 else [to_expr(args[0])]
        if not xs[0].dtype.is_float:
            xs = [cast_expr(x, dt.Defaults.fp) for x in xs]
        b = context.builder()
        return Expr(b.binary(d.op, xs[0].stmt, xs[1].stmt) if d.arity == 2 else b.unary(d.op, xs[0].stmt))

    f.__name__ = f.__qualname__ = d.name  # the kernel cache names library functions by qualified name
    return f


# every math function of the registry, by name (simgrad/__init__.py and lang/mathlib.py export them)
MATH = {d.name: _math_function(d) for d in OPS.values() if d.export}
globals().update(MATH)


def math_functions(namespace: str) -> dict[str, Callable[..., Any]]:
    """The registry's math functions that `namespace` ("ti": ti.*, "math": ti.math) exports."""
    return {d.name: MATH[d.name] for d in OPS.values() if namespace in d.export}


if TYPE_CHECKING:
    def __getattr__(name: str) -> Callable[..., Any]:
        """The functions of MATH (ops.sin, ops.atan2, ...) for the type checker."""


def _py_round(x):
    """Half away from zero, as Taichi rounds run-time values (and LLVM's llvm.round)."""
    if not isinstance(x, float):
        return x
    return float(math.copysign(math.floor(abs(x) + 0.5), x))


def _rounding(op: Op, pyfn):
    def f(x, dtype=None):
        if is_matrix(x):
            return _elementwise(lambda e: f(e, dtype), x)
        if not isinstance(x, Expr):
            r = pyfn(x)
            return cast(r, dtype) if dtype is not None else (float(r) if isinstance(x, float) else r)
        if not x.dtype.is_float:  # Taichi refuses them (its floor/ceil/round are float ops)
            raise SimgradTypeError(f"'{op.name.lower()}' takes real inputs only, got {x.dtype}: "
                                   f"ti.{op.name.lower()}(ti.cast(x, float)) for a float", context.current_loc())
        r = _emit1(op, x)
        return cast(r, dtype) if dtype is not None else r

    f.__name__ = op.name.lower()
    return f


floor = _rounding(Op.FLOOR, math.floor)
ceil = _rounding(Op.CEIL, math.ceil)
round = _rounding(Op.ROUND, _py_round)  # noqa: A001


def select(cond, a, b):
    if is_matrix(cond) or is_matrix(a) or is_matrix(b):
        return _elementwise(select, cond, a, b)
    if not isinstance(cond, Expr) and not isinstance(a, Expr) and not isinstance(b, Expr):
        return a if cond else b
    c = to_expr(cond)
    c = Expr(context.builder().binary(Op.NE, c.stmt, context.builder().const(0, c.dtype)))
    if not isinstance(a, Expr) and not isinstance(b, Expr):  # two literals: type them like a + b
        a = to_expr(a, dt.Defaults.fp if isinstance(b, float) else None)
    a, b = _pair(a, b)
    return Expr(context.builder().select(c.stmt, a.stmt, b.stmt))


def cast(x, dtype):
    if is_matrix(x):
        return x.cast(dtype)
    t = dt.from_any(dtype)
    if not isinstance(x, Expr):
        if context.in_kernel() and (isinstance(x, _PY_NUM) or _np_scalar(x)):
            if isinstance(x, int) and not isinstance(x, bool):  # ti.cast(2**40, ti.i32) wraps, explicitly
                return cast_expr(_int_literal(x), t)
            return cast_expr(to_expr(x, t), t)
        return _py_cast(x, t)
    return cast_expr(x, t)


def _py_cast(x, t: dt.DataType):
    """A Python-scope value converted as numpy converts it; a float or exact int to a float type, and an int
    that fits its integer type, skip numpy's array round trip (vec3(1, 2, 3) casts every entry)."""
    import numpy as np

    if (type(x) is float or (type(x) is int and -(1 << 53) <= x <= 1 << 53)) and t.is_float:
        return float(x) if t.bits == 64 else float(t.np.type(x))
    if type(x) is int and not t.is_float and t is not dt.u1 \
            and -(1 << (t.bits - 1)) * t.is_signed <= x < 1 << (t.bits - t.is_signed):
        return x
    return np.array(x).astype(t.np).item()


def bit_cast(x, dtype):
    t = dt.from_any(dtype)
    x = to_expr(x)
    return Expr(context.builder().emit(Op.BITCAST, t, (x.stmt,)))


def random(dtype=float):
    t = dt.from_any(dtype)
    return Expr(context.builder().emit(Op.RANDOM, t))


def randn(dtype=None):
    """A standard normal sample (Box-Muller on two uniforms)."""
    t = dt.from_any(dtype) if dtype is not None else dt.Defaults.fp
    u1 = random(t)
    u2 = random(t)
    r = MATH["sqrt"](mul(-2.0, MATH["log"](sub(1.0, u1))))
    return mul(r, MATH["cos"](mul(2.0 * math.pi, u2)))


def zero(x):
    """A zero of x's type and shape (a scalar or a matrix), as Taichi's ti.zero."""
    return x * 0


def one(x):
    """A one of x's type and shape."""
    return zero(x) + 1


# frexp on the bits: (exponent shift, exponent mask, bias to [0.5, 1), sign+mantissa mask (as a signed
# integer), the exponent bits of 0.5, the scale that makes a subnormal normal, the integer type)
_FREXP = {32: (23, 0xFF, 126, -0x7F800001, 0x3F000000, 2.0**24, dt.i32),
          64: (52, 0x7FF, 1022, -0x7FF0000000000001, 0x3FE0000000000000, 2.0**54, dt.i64)}


def frexp(x):
    """(m, e) with x = m * 2**e and 0.5 <= |m| < 1 (0, inf and nan give (x, 0)), as numpy's frexp: on the
    bits in kernels (a subnormal is first scaled into the normal range), numpy's in Python scope."""
    if is_matrix(x):
        raise SimgradTypeError("ti.frexp takes a scalar")
    if not isinstance(x, Expr):
        import numpy as np

        m, e = np.frexp(x)
        return float(m), int(e)
    t = x.dtype if x.dtype.is_float else dt.Defaults.fp
    t = dt.f32 if t is dt.f16 else t
    x = cast_expr(x, t)
    shift, field_mask, bias, keep, half, up, it = _FREXP[t.bits]
    tiny = abs(x) < (2.0**-126 if t.bits == 32 else 2.0**-1022)
    y = select(tiny, x * up, x)
    bits = bit_cast(y, it)
    e = bit_and(bit_shr(bits, shift), field_mask) - bias
    m = bit_cast(bit_or(bit_and(bits, keep), half), t)
    special = logical_or(x == 0, e == field_mask - bias)  # zero, inf, nan
    e = select(tiny, e - (24 if t.bits == 32 else 54), e)
    return select(special, x, m), cast(select(special, 0, e), dt.i32)


def global_thread_idx():
    """The index of the thread running this iteration (the pool's thread id on the CPU; 0 outside a
    parallel loop)."""
    return Expr(context.builder().emit(Op.THREAD_INDEX, dt.i32))


def type_call(t: dt.DataType, args: tuple, kwargs: dict):
    """`ti.f32(x)`: a cast; in a kernel, as Taichi's primitive-type call, one scalar only, and a Python number is a
    literal of that type (an int must fit it, and only an integer type takes an int and a float type a float)."""
    if not context.in_kernel():
        if len(args) != 1 or kwargs:
            raise TypeError(f"{t}() takes one value")
        return cast(args[0], t)
    loc = context.current_loc()
    if len(args) != 1 or kwargs:
        raise SimgradSyntaxError("A primitive type can only decorate a single expression.", loc)
    import numpy as np

    x = args[0]
    if is_matrix(x):
        raise SimgradSyntaxError("A primitive type cannot decorate an expression with a compound type (use "
                                 "ti.cast or .cast(dtype) on a vector or matrix).", loc)
    if isinstance(x, (float, np.floating)) and not t.is_float:
        raise SimgradTypeError("Floating-point literals must be annotated with a floating-point type. For type "
                               "casting, use `ti.cast`.", loc)
    if isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_)):
        if t.is_float:
            raise SimgradTypeError("Integer literals must be annotated with a integer type. For type casting, "
                                   "use `ti.cast`.", loc)
        lo, hi = (-(1 << (t.bits - 1)), (1 << (t.bits - 1)) - 1) if t.is_signed else (0, (1 << t.bits) - 1)
        if not lo <= int(x) <= hi:
            raise SimgradTypeError(f"Integer literal {int(x)} exceeded the range of specified dtype: {t} ([{lo}, "
                                   f"{hi}]); ti.cast({int(x)}, {t}) wraps it explicitly", loc)
    return cast(x, t)


dt.cast_hook = type_call  # `ti.f32(x)` (dtypes.DataType.__call__) goes through lang
