"""The value of a constant at a type, exactly as the compiled code would compute it.

Constant folding (ir/builder.py, passes/simplify.py) goes through here, so a folded result never
differs from the instruction it replaces: floats are rounded to their width, integers wrap in two's
complement, and conversions whose machine result is undefined (NaN or out-of-range float -> int) are
not folded at all. While a kernel compiles in flush-to-zero mode (runtime/fpenv.py) every float constant made
goes through `flush` (ir/builder.py `constant`): a subnormal result is the zero the machine computes."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import math
import sys
import warnings

import numpy as np

from simgrad import dtypes as dt
from simgrad.dtypes import DataType

_MANTISSA = {16: 11, 32: 24, 64: 53}  # significand bits, the implicit one included
_SMALLEST_NORMAL = {32: float(np.finfo(np.float32).tiny), 64: sys.float_info.min}
_flush_bits: frozenset[int] = frozenset()  # float widths whose subnormal results flush to zero now


@contextlib.contextmanager
def flushing(bits: frozenset[int]):
    """Fold with results of these float widths flushed (the compile of one kernel; compiles hold a lock)."""
    global _flush_bits
    saved, _flush_bits = _flush_bits, bits
    try:
        yield
    finally:
        _flush_bits = saved


def flush(v, t: DataType):
    """`v` at float type `t` as the flush-to-zero machine leaves a result: a subnormal becomes a signed zero
    (f16 keeps its subnormals: the conversion to half does not flush)."""
    if t.bits in _flush_bits and _subnormal(v, t):
        return math.copysign(0.0, v)
    return v


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



# -- the exact value of an elementwise op (ir/opdefs.py evaluators) ----------------------------------------
def _load_libm() -> ctypes.CDLL:
    name = ctypes.util.find_library("m")
    return ctypes.CDLL(name) if name else ctypes.CDLL(None)


_LIBM = _load_libm()
_C_TYPES = {64: ctypes.c_double, 32: ctypes.c_float}


def libm(name: str, t: DataType, *vals: float) -> float | None:
    """The C library's `name` (double) or `name`f (float) called on `vals`: the very function a compiled
    kernel calls for this op (llvm.sin.f32 becomes a call of sinf), so the value is the machine's on this
    machine, bit for bit, whatever libm's accuracy. f16 goes through f32, as codegen and LLVM promote it."""
    if t.bits == 16:
        r = libm(name, dt.f32, *vals)
        return None if r is None else round_float(r, t)
    c = _C_TYPES[t.bits]
    fn = getattr(_LIBM, name if t.bits == 64 else name + "f")
    fn.restype, fn.argtypes = c, [c] * len(vals)
    r = float(fn(*vals))
    if t.bits in _flush_bits and any(_subnormal(v, t) for v in (*vals, r)):
        return None  # libm's code under flush-to-zero may give another value than here: not folded
    return r


def _subnormal(v: float, t: DataType) -> bool:
    return 0 < abs(v) < _SMALLEST_NORMAL[t.bits]


def ieee(fn, t: DataType, *vals: float) -> float:
    """A correctly rounded IEEE operation (+ - * / sqrt) at `t` through numpy's scalars of that width; f16
    computes at f32 and rounds once (what LLVM's promotion of half arithmetic does; exact, as f32 carries
    more than 2 * 11 + 2 significand bits)."""
    w = dt.f32 if t.bits == 16 else t
    with np.errstate(all="ignore"):
        r = float(fn(*(w.np.type(v) for v in vals)))
    return round_float(r, t) if t.bits == 16 else r


def c_div(a: int, b: int) -> int:
    """C division (toward zero), exact for any Python ints (int(a / b) rounds through a float)."""
    q = abs(a) // abs(b)
    return q if (a < 0) == (b < 0) else -q


def shift_amount(b: int, t: DataType) -> int:
    """The amount a shift uses: taken modulo the width (codegen masks it; LLVM makes a larger one poison)."""
    return b & (t.bits - 1)
