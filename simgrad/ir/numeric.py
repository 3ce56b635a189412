"""The value of a constant at a type, exactly as the compiled code would compute it.

Constant folding (ir/builder.py, passes/simplify.py) goes through here, so a folded result never
differs from the instruction it replaces: floats are rounded to their width, integers wrap in two's
complement, and conversions whose machine result is undefined (NaN or out-of-range float -> int) are
not folded at all."""

from __future__ import annotations

import math
import warnings

import numpy as np

from simgrad import dtypes as dt
from simgrad.dtypes import DataType

_MANTISSA = {16: 11, 32: 24, 64: 53}  # significand bits, the implicit one included


def wrap_int(v: int, t: DataType) -> int:
    """Two's-complement wrap-around of a Python int into `t`'s range."""
    mask = (1 << t.bits) - 1
    v &= mask
    if t.is_signed and v >> (t.bits - 1):
        v -= 1 << t.bits
    return v


def round_float(v: float, t: DataType) -> float:
    """A Python float rounded (to nearest, ties to even) to the float type `t`."""
    v = float(v)
    if t.bits == 64 or math.isnan(v) or math.isinf(v):
        return v
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # overflow to inf is the IEEE result, not a problem
        return float(np.float32(v) if t.bits == 32 else np.float16(v))


def int_to_float(v: int, t: DataType) -> float:
    """sitofp/uitofp of the integer `v`: rounded once to `t`'s significand (not through f64, which
    would round twice for |v| >= 2**53)."""
    bits = _MANTISSA[t.bits]
    a = abs(v)
    if a.bit_length() > bits:
        shift = a.bit_length() - bits
        q, r = divmod(a, 1 << shift)
        half = 1 << (shift - 1)
        if r > half or (r == half and q & 1):
            q += 1
        a = q << shift
    try:
        f = float(a)
    except OverflowError:
        f = math.inf
    return round_float(-f if v < 0 else f, t)


def float_to_int(v: float, t: DataType) -> int | None:
    """fptosi/fptoui: truncation toward zero; None when the result is undefined (NaN, out of range)."""
    if math.isnan(v) or math.isinf(v):
        return None
    i = math.trunc(v)
    lo, hi = (-(1 << (t.bits - 1)), (1 << (t.bits - 1)) - 1) if t.is_signed else (0, (1 << t.bits) - 1)
    return i if lo <= i <= hi else None


def convert(v, src: DataType, dst: DataType):
    """The value of `cast(v: src, dst)`, or None when the machine result is not defined."""
    if dst is dt.u1:
        return int(v != 0)  # as the codegen does: icmp ne / fcmp une 0
    if dst.is_float:
        if src.is_float:
            return round_float(v, dst)
        return int_to_float(int(v), dst)
    if src.is_float:
        return float_to_int(float(v), dst)
    return wrap_int(int(v), dst)


def const_value(v, t: DataType):
    """A literal's value at type `t` (ints wrap, floats round)."""
    if t.is_float:
        if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
            return int_to_float(int(v), t)
        return round_float(v, t)
    if t is dt.u1:
        return int(bool(v))
    return wrap_int(int(v), t)


def minmax(pick, a, b):
    """min/max as llvm.minnum/maxnum compute it: a NaN operand yields the other one (Python's min and
    max would depend on the operand order)."""
    if a != a:
        return b
    if b != b:
        return a
    return pick(a, b)

