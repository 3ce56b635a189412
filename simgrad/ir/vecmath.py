"""Vector math functions (fast_math on the CPU): f32 sin cos tan atan2 exp log tanh pow, f64 sin cos atan2 exp.

Why: a loop calling libm's `cosf` cannot be vectorised (llvmlite gives LLVM no vector math library), and such
calls were most of some examples' time. Each function is written once against a small set of operations (`V`)
with two backends: codegen/vecmath.py emits its vector versions (plain arithmetic, selects and table gathers),
which a vectorised loop calls in place of libm; `evaluate` runs the same operations in numpy (IEEE float64, fma
only where its result is exact, emulated exactly), bit for bit what the vector code computes, for the tests.
f32: the argument is widened to f64 (exact), the result computed there with range reduction and Taylor
polynomials (error < 1e-12 relative) and rounded once: within 1 ulp of the exact value; sin/cos/tan reduce any
f32 exactly by 2/pi (a table of 2/pi's bits per exponent, three 29-bit pieces whose products with the 24-bit
significand are exact). f64: Cody-Waite reduction exact by fma for |x| < 2**30 and an atan(k/16) table with
double-double corrections, exp by k ln2 + r; other lanes (huge, inf, NaN, atan2's subnormal ratios) call libm
(`fallback`).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from decimal import Decimal, localcontext

import numpy as np

from simgrad import dtypes as dt
from simgrad.ir import numeric
from simgrad.ir.ops import Op

# -- constants ------------------------------------------------------------------------------------------------

_BITS = 520  # 2/pi to this many fractional bits: f32's exponents reach bit 127 + 24 + 87


def _pi_scaled(bits: int) -> int:
    """floor(pi * 2**bits), from Machin's formula in integers (16 guard bits)."""
    one = 1 << (bits + 16)

    def arctan_inv(n: int) -> int:
        total, term, k, sign = 0, one // n, 1, 1
        while term:
            total += sign * (term // k)
            term //= n * n
            k += 2
            sign = -sign
        return total

    return (16 * arctan_inv(5) - 4 * arctan_inv(239)) >> 16


_TWO_OVER_PI = (1 << (2 * _BITS + 1)) // _pi_scaled(_BITS)  # floor(2/pi * 2**_BITS), bit j at _BITS - j


def _two_over_pi_table() -> np.ndarray:
    """Per f32 biased exponent E (x = m * 2**s, m < 2**24 an integer): three doubles of 29 bits each, 2/pi's
    bits j0 .. j0 + 86 with j0 = max(1, s - 1). Bits above j0 only add multiples of 4 to x * 2/pi (whole
    turns), so x * T0 + x * T1 + x * T2 is x * 2/pi modulo 4 to 2**-61, each product exact."""
    out = np.zeros((256, 3))
    for e in range(255):
        s = -149 if e == 0 else e - 150
        j0 = max(1, s - 1)
        for c in range(3):
            last = j0 + 29 * c + 28
            piece = (_TWO_OVER_PI >> (_BITS - last)) & ((1 << 29) - 1)
            out[e, c] = math.ldexp(piece, -last)
    return out.reshape(-1)


TABLE = _two_over_pi_table()  # E = 255 (inf, NaN) is zero: inf * 0 is NaN, which is sin(inf)


def _split3(num: int, shift: int) -> tuple[float, float, float]:
    """num / 2**shift as three doubles, each the nearest to what the previous ones leave."""
    out: list[float] = []
    with localcontext() as ctx:
        ctx.prec = 80
        for _ in range(3):
            d = Decimal(num) / (Decimal(2) ** shift) - sum((Decimal(v) for v in out), Decimal(0))
            out.append(float(d))
    return out[0], out[1], out[2]


def _atan_table() -> np.ndarray:
    """atan(k/16), k = 0..16, as (hi, lo) pairs: argument halving (atan x = 2 atan(x / (1 + sqrt(1 + x*x))))
    three times, then the series, in 60-digit decimals."""
    out = []
    with localcontext() as ctx:
        ctx.prec = 60
        for k in range(17):
            x = Decimal(k) / 16
            for _ in range(3):
                x = x / (1 + (1 + x * x).sqrt())
            total, term, n = Decimal(0), x, 0
            while abs(term) > Decimal(10) ** -58:
                total += term / (2 * n + 1)
                term = -term * x * x
                n += 1
            v = 8 * total
            hi = float(v)
            out += [hi, float(v - Decimal(hi))]
    return np.array(out + [0.0] * (64 - len(out)))  # 32 pairs: an index masked with 31 stays inside


ATAN16 = _atan_table()
TABLES = {"two_over_pi": TABLE, "atan16": ATAN16}

with localcontext() as _ctx:
    _ctx.prec = 40
    _LN2 = Decimal(2).ln()
    LN2 = float(_LN2)
    _bits = struct.unpack("<Q", struct.pack("<d", LN2))[0] & ~((1 << 21) - 1)  # 32 significant bits: k ln2_hi exact
    LN2_HI = struct.unpack("<d", struct.pack("<Q", _bits))[0]
    LN2_LO = float(_LN2 - Decimal(LN2_HI))
PI = math.pi
PIO2_1, PIO2_2, PIO2_3 = _split3(_pi_scaled(_BITS), _BITS + 1)  # pi/2 to ~160 bits
MAGIC = 6755399441055744.0  # 1.5 * 2**52: t + MAGIC - MAGIC is t rounded to an integer (|t| < 2**51)
MAGIC_BITS = 0x4338000000000000

# Taylor coefficients (exact enough as doubles; the truncation error is what the comments bound)
_EXP = [1.0 / math.factorial(n) for n in range(12)]  # e**r, |r| <= ln2/2: r**12/12! < 1e-14
_SIN = [(-1.0) ** k / math.factorial(2 * k + 1) for k in range(7)]  # |r| <= pi/4: r**14/15! < 3e-14
_COS = [(-1.0) ** k / math.factorial(2 * k) for k in range(8)]  # r**16/16! < 1e-15
_ATAN = [(-1.0) ** k / (2 * k + 1) for k in range(8)]  # |u| <= tan(pi/16): u**16/17 < 4e-24
_LOG = [2.0 / (2 * k + 1) for k in range(9)]  # 2 atanh(s), |s| <= 0.172: s**18/19 < 1e-15
_TAN_PI_16 = math.tan(math.pi / 16)
_TAN_3PI_16 = math.tan(3 * math.pi / 16)
_TAN_PI_8 = math.tan(math.pi / 8)


# -- the operations the functions are written in ---------------------------------------------------------------

class V:
    """A value of one backend: `h` is its handle (an LLVM name or a numpy array), `ty` its LLVM type."""

    def __init__(self, be, h, ty: str):
        self.be, self.h, self.ty = be, h, ty

    def _c(self, other) -> V:
        return other if isinstance(other, V) else self.be.const(other, self.ty)

    def _bin(self, fop: str, iop: str, other, rev: bool = False) -> V:
        o = self._c(other)
        a, b = (o, self) if rev else (self, o)
        return self.be.bin(fop if self.ty in ("double", "float") else iop, a, b)

    def __add__(self, o): return self._bin("fadd", "add", o)
    def __radd__(self, o): return self._bin("fadd", "add", o, True)
    def __sub__(self, o): return self._bin("fsub", "sub", o)
    def __rsub__(self, o): return self._bin("fsub", "sub", o, True)
    def __mul__(self, o): return self._bin("fmul", "mul", o)
    def __rmul__(self, o): return self._bin("fmul", "mul", o, True)
    def __truediv__(self, o): return self._bin("fdiv", "", o)
    def __rtruediv__(self, o): return self._bin("fdiv", "", o, True)
    def __and__(self, o): return self._bin("", "and", o)
    def __or__(self, o): return self._bin("", "or", o)
    def __xor__(self, o): return self._bin("", "xor", o)
    def __lshift__(self, o): return self._bin("", "shl", o)
    def __rshift__(self, o): return self._bin("", "lshr", o)

    def cmp(self, pred: str, o) -> V:
        """fcmp (olt, ogt, oeq, uno, ...) for floats, icmp (slt, eq, ...) for integers."""
        return self.be.cmp(pred, self, self._c(o))

    def to(self, how: str, ty: str) -> V:
        """fpext, fptrunc, bitcast, trunc, zext, sext, sitofp."""
        return self.be.cast(how, self, ty)

    def abs(self) -> V:
        return self.be.call("fabs", self)

    def copysign(self, sign: V) -> V:
        return self.be.call("copysign", self, sign)


def select(c: V, a, b) -> V:
    """c ? a : b; numbers are constants of the other operand's type (double when both are numbers)."""
    x = a if isinstance(a, V) else b if isinstance(b, V) else c.be.const(a, "double")
    return c.be.select(c, x._c(a), x._c(b))


def _poly(x: V, coeffs: list[float]) -> V:
    """c0 + c1 x + c2 x**2 + ... by Horner's rule."""
    p = x * coeffs[-1] + coeffs[-2]
    for c in reversed(coeffs[:-2]):
        p = p * x + c
    return p


def _round(t: V) -> tuple[V, V]:
    """t (|t| < 2**51) rounded to the nearest integer, as a double and as an i64 (no fptosi: NaN is no poison)."""
    s = t + MAGIC
    return s - MAGIC, s.to("bitcast", "i64") - MAGIC_BITS


def _pow2(k: V) -> V:
    """2**k for an i64 k in [-1022, 1023]."""
    return ((k + 1023) << 52).to("bitcast", "double")


def _exp_core(t: V) -> V:
    """e**t for a double t in [-700, 700] (or NaN): t = k ln2 + r, e**r by its Taylor series."""
    kd, k = _round(t * (1.0 / LN2))
    r = (t - kd * LN2_HI) - kd * LN2_LO
    return _poly(r, _EXP) * _pow2(k)


def _log_core(d: V) -> V:
    """log(d) for a positive finite double: d = 2**e m with m in [sqrt(1/2), sqrt(2)), log m = 2 atanh(s)."""
    b = d.to("bitcast", "i64")
    e = (b >> 52) - 1023
    m = ((b & ((1 << 52) - 1)) | 0x3FF0000000000000).to("bitcast", "double")
    big = m.cmp("ogt", math.sqrt(2.0))
    m = select(big, m * 0.5, m)
    e = e + big.to("zext", "i64")
    s = (m - 1.0) / (m + 1.0)
    return e.to("sitofp", "double") * LN2 + s * _poly(s * s, _LOG)


def _reduce(x: V) -> tuple[V, V]:
    """An f32 x as r + q pi/2 (q modulo 4 as an i64), |r| <= pi/4 (a hair more), exact to 2**-61 absolute."""
    e = (x.to("bitcast", "i32") >> 23) & 255
    idx = e.to("zext", "i64") * 3
    xd = x.to("fpext", "double")
    t0, t1, t2 = (x.be.load("two_over_pi", idx + c) for c in range(3))
    p0, p1, p2 = xd * t0, xd * t1, xd * t2  # exact
    nd, n = _round(p0 + p1)
    f = ((p0 - nd) + p1) + p2  # p0 - nd exact
    return f * (PI / 2), n & 3


def _sin_cos(r: V) -> tuple[V, V]:
    z = r * r
    return r + r * z * _poly(z, _SIN[1:]), _poly(z, _COS)


def _sin(x: V) -> V:
    r, q = _reduce(x)
    s, c = _sin_cos(r)
    v = select((q & 1).cmp("ne", 0), c, s)
    v = select((q & 2).cmp("ne", 0), v * -1.0, v)
    return select(x.cmp("oeq", 0.0), x, v.to("fptrunc", "float"))  # sin(-0) = -0


def _cos(x: V) -> V:
    r, q = _reduce(x)
    s, c = _sin_cos(r)
    v = select((q & 1).cmp("ne", 0), s * -1.0, c)
    return select((q & 2).cmp("ne", 0), v * -1.0, v).to("fptrunc", "float")


def _tan(x: V) -> V:
    r, q = _reduce(x)
    s, c = _sin_cos(r)
    v = select((q & 1).cmp("ne", 0), (c * -1.0) / s, s / c)
    return select(x.cmp("oeq", 0.0), x, v.to("fptrunc", "float"))


def _atan01(t: V) -> V:
    """atan(t) for t in [0, 1] (or NaN): atan t = atan c + atan((t - c) / (1 + t c)) with c = tan(0, pi/8,
    pi/4), whichever leaves |u| <= tan(pi/16), then atan u by its Taylor series."""
    c1, c2 = t.cmp("ogt", _TAN_PI_16), t.cmp("ogt", _TAN_3PI_16)
    cen = select(c2, 1.0, select(c1, _TAN_PI_8, 0.0))
    base = select(c2, PI / 4, select(c1, PI / 8, 0.0))
    u = (t - cen) / (t * cen + 1.0)
    z = u * u
    return base + (u + u * z * _poly(z, _ATAN[1:]))


def _atan(x: V) -> V:
    d = x.to("fpext", "double").abs()
    inv = d.cmp("ogt", 1.0)
    a = _atan01(select(inv, 1.0 / d, d))
    a = select(inv, PI / 2 - a, a)
    return a.copysign(x.to("fpext", "double")).to("fptrunc", "float")


def _atan2(y: V, x: V) -> V:
    yd, xd = y.to("fpext", "double"), x.to("fpext", "double")
    ay, ax = yd.abs(), xd.abs()
    swap = ay.cmp("ogt", ax)
    num, den = select(swap, ax, ay), select(swap, ay, ax)
    t = num / den
    t = select(den.cmp("oeq", 0.0), 0.0, t)  # atan2(+-0, +-0)
    t = select(num.cmp("oeq", math.inf), 1.0, t)  # atan2(+-inf, +-inf)
    a = _atan01(t)
    a = select(swap, PI / 2 - a, a)
    a = select(x.to("bitcast", "i32").cmp("slt", 0), PI - a, a)  # x < 0 or x = -0
    a = select(yd.cmp("uno", xd), yd + xd, a.copysign(yd))
    return a.to("fptrunc", "float")


def _exp(x: V) -> V:
    t = x.to("fpext", "double")
    t = select(t.cmp("ogt", 100.0), 100.0, t)  # e**100 overflows f32, e**-160 rounds to 0; NaN stays
    t = select(t.cmp("olt", -160.0), -160.0, t)
    return _exp_core(t).to("fptrunc", "float")


def _log(x: V) -> V:
    d = x.to("fpext", "double")
    v = _log_core(d)
    v = select(d.cmp("oeq", 0.0), -math.inf, v)
    v = select(d.cmp("olt", 0.0), math.nan, v)
    v = select(d.cmp("oeq", math.inf), math.inf, v)
    v = select(d.cmp("uno", d), d, v)
    return v.to("fptrunc", "float")


def _tanh(x: V) -> V:
    """tanh|x| = m / (m + 2) with m = e**(2|x|) - 1 = 2**k (e**r - 1) + (2**k - 1): no cancellation."""
    xd = x.to("fpext", "double")
    u = xd.abs() * 2.0
    u = select(u.cmp("ogt", 40.0), 40.0, u)
    kd, k = _round(u * (1.0 / LN2))
    r = (u - kd * LN2_HI) - kd * LN2_LO
    scale = _pow2(k)
    m = r * _poly(r, _EXP[1:]) * scale + (scale - 1.0)
    return (m / (m + 2.0)).copysign(xd).to("fptrunc", "float")


def _pow(x: V, y: V) -> V:
    """|x|**y = e**(y log|x|) in f64, then C99's special cases (Annex F.9.4.4) as selects."""
    xd, yd = x.to("fpext", "double"), y.to("fpext", "double")
    ax, ay = xd.abs(), yd.abs()
    t = yd * _log_core(ax)
    t = select(t.cmp("ogt", 200.0), 200.0, t)
    t = select(t.cmp("olt", -200.0), -200.0, t)
    v = _exp_core(t)
    ypos = yd.cmp("ogt", 0.0)
    v = select(ax.cmp("oeq", 0.0), select(ypos, 0.0, math.inf), v)
    v = select(ax.cmp("oeq", math.inf), select(ypos, math.inf, 0.0), v)
    v = select(ax.cmp("oeq", 1.0), 1.0, v)  # (-1)**+-inf; 1 for |x| = 1 otherwise too (the sign below)
    small = ay.cmp("olt", 16777216.0)  # |y| >= 2**24 (or inf) is an even integer
    yr, yi = _round(select(small, yd, 0.0))
    integer = select(small, yr.cmp("oeq", yd), ay.cmp("oeq", ay))
    odd = small & integer & (yi & 1).cmp("ne", 0)
    v = select(x.to("bitcast", "i32").cmp("slt", 0) & odd, v * -1.0, v)
    bad = xd.cmp("olt", 0.0) & ax.cmp("one", math.inf) & (integer ^ yd.cmp("oeq", yd))  # x < 0, y finite non-int
    v = select(bad, math.nan, v)
    v = select(xd.cmp("uno", yd), xd + yd, v)
    v = select(yd.cmp("oeq", 0.0) | xd.cmp("oeq", 1.0), 1.0, v)
    return v.to("fptrunc", "float")


# -- f64: double arithmetic with exact error terms (fma), libm for the lanes outside the fast path ----------------

_SIN64 = [(-1.0) ** k / math.factorial(2 * k + 1) for k in range(9)]  # |r| <= pi/4: r**19/19! < 1e-19
_COS64 = [(-1.0) ** k / math.factorial(2 * k) for k in range(10)]
_ATAN64 = [(-1.0) ** k / (2 * k + 1) for k in range(7)]  # |q| <= 1/32: q**14/15 < 2**-74


def _two_prod(a: V, b: V) -> tuple[V, V]:
    p = a * b
    return p, a.be.call("fma", a, b, p * -1.0)


def _two_sum(a: V, b) -> tuple[V, V]:
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (bb * -1.0 + b)


def _fast_two_sum(a, b: V) -> tuple[V, V]:
    """|a| >= |b| (or a = 0)."""
    s = b + a
    return s, b - (s - a)


def _sin_cos64(x: V) -> tuple[V, V, V]:
    """sin and cos of r, and q, for x = r + q pi/2 (|x| < 2**30): Cody-Waite with pi/2 in three doubles, the
    first step exact by fma, the second exact by two_prod/two_sum, so r = rh + rl to ~2**-100 relative."""
    nd, n = _round(x * (2.0 / PI))
    a = x.be.call("fma", nd * -1.0, x.be.const(PIO2_1, "double"), x)  # x - n P1: exact
    bh, bl = _two_prod(nd, x.be.const(PIO2_2, "double"))
    s, e = _two_sum(a, bh * -1.0)
    rh, rl = _two_sum(s, (e - bl) - nd * PIO2_3)
    z = rh * rh
    sin = rh + (rh * z * _poly(z, _SIN64[1:]) + rl * (1.0 - z * 0.5))
    hz = z * 0.5
    w = 1.0 - hz
    cos = w + (((1.0 - w) - hz) + (z * z * _poly(z, _COS64[2:]) - rh * rl))
    return sin, cos, n & 3


_HUGE64 = 2.0 ** 30


def _sin64(x: V) -> V:
    s, c, q = _sin_cos64(x)
    v = select((q & 1).cmp("ne", 0), c, s)
    v = select((q & 2).cmp("ne", 0), v * -1.0, v)
    v = select(x.cmp("oeq", 0.0), x, v)
    return x.be.fallback(x.abs().cmp("olt", _HUGE64) ^ True, "sin", [x], v)


def _cos64(x: V) -> V:
    s, c, q = _sin_cos64(x)
    v = select((q & 1).cmp("ne", 0), s * -1.0, c)
    v = select((q & 2).cmp("ne", 0), v * -1.0, v)
    return x.be.fallback(x.abs().cmp("olt", _HUGE64) ^ True, "cos", [x], v)


def _atan2_64(y: V, x: V) -> V:
    """t = min/max of |x|, |y| (with its rounding error tl); atan t = atan(k/16) + atan u, u = (t - c)/(1 + t c)
    with c = k/16 nearest t (|u| <= 1/32), u and the sums kept as double-doubles; then pi/2 - a, pi - a.
    libm for inf, NaN and extreme magnitudes (subnormal ratios)."""
    ax, ay = x.abs(), y.abs()
    swap = ay.cmp("ogt", ax)
    num, den = select(swap, ax, ay), select(swap, ay, ax)
    t = num / den
    tl = x.be.call("fma", t * -1.0, den, num) / den  # num/den = t + tl
    kd, k = _round(t * 16.0)
    c = kd * 0.0625
    d = t - c  # exact
    ph, pe = _two_prod(t, c)
    dh, de = _fast_two_sum(x.be.const(1.0, "double"), ph)
    dl = de + pe + tl * c  # 1 + (t + tl) c = dh + dl
    q = d / dh
    ql = ((x.be.call("fma", q * -1.0, dh, d) + tl) - q * dl) / dh  # u = q + ql
    z = q * q
    idx = (k & 31) * 2  # in the table whatever t is (NaN lanes go to libm)
    h, lo = _fast_two_sum(x.be.load("atan16", idx), q)
    lo = lo + (x.be.load("atan16", idx + 1) + (ql + q * z * _poly(z, _ATAN64[1:])))
    for cond, ch, cl in ((swap, PIO2_1, PIO2_2), (x.to("bitcast", "i64").cmp("slt", 0), 2 * PIO2_1, 2 * PIO2_2)):
        s, e = _two_sum(x.be.const(ch, "double"), h * -1.0)
        h2, lo2 = _fast_two_sum(s, e + (lo * -1.0 + cl))
        h, lo = select(cond, h2, h), select(cond, lo2, lo)
    v = (h + lo).copysign(y)
    # two zeros: +-0 for x = +0, +-pi for x = -0 (C's values; a zero gradient's angle, where snow_phaseField's
    # field is flat, is the common case: each such lane calling libm made its vector loop 2x slower)
    zeros = den.cmp("oeq", 0.0)
    v = select(zeros, select(x.to("bitcast", "i64").cmp("slt", 0), PI, 0.0).copysign(y), v)
    ok = ax.cmp("olt", 2.0 ** 990) & ay.cmp("olt", 2.0 ** 990) & (zeros | den.cmp("ogt", 2.0 ** -900)
                                                                 & (t.cmp("ogt", 2.0 ** -900) | num.cmp("oeq", 0.0)))
    return x.be.fallback(ok ^ True, "atan2", [y, x], v)


_EXP64 = [1.0 / math.factorial(n) for n in range(2, 15)]  # |r| <= ln2/2: r**15/15! < 2**-70


def _exp64(x: V) -> V:
    """x = k ln2 + r with r = hi - lo (hi exact: k ln2_hi has 43 bits), e**r = 1 + hi + (r**2 P(r) - lo), times
    2**k. libm for |x| >= 708 (overflow, subnormal results), inf and NaN."""
    kd, k = _round(x * (1.0 / LN2))
    hi = x - kd * LN2_HI
    lo = kd * LN2_LO
    r = hi - lo
    p = (hi + (r * r * _poly(r, _EXP64) - lo)) + 1.0
    return x.be.fallback(x.abs().cmp("olt", 708.0) ^ True, "exp", [x], p * _pow2(k))


#: Op -> (function name, algorithm on f64 values)
FUNCTIONS64: dict[Op, tuple[str, Callable[..., V]]] = {
    Op.SIN: ("sin", _sin64), Op.COS: ("cos", _cos64), Op.ATAN2: ("atan2", _atan2_64), Op.EXP: ("exp", _exp64),
}


#: Op -> (function name, algorithm on f32 values)
FUNCTIONS: dict[Op, tuple[str, Callable[..., V]]] = {
    Op.SIN: ("sin", _sin), Op.COS: ("cos", _cos), Op.TAN: ("tan", _tan), Op.ATAN2: ("atan2", _atan2),
    Op.EXP: ("exp", _exp), Op.LOG: ("log", _log), Op.TANH: ("tanh", _tanh), Op.POW: ("pow", _pow),
}
ATAN = ("atan", _atan)  # not a registry op (ti.atan2 is); kept for completeness and tested


# -- the numpy backend ------------------------------------------------------------------------------------------

_NP = {"double": np.float64, "float": np.float32, "i64": np.int64, "i32": np.int32, "i1": np.bool_}
_UNSIGNED = {"i64": np.uint64, "i32": np.uint32}


class _Numpy:
    """Each operation on numpy arrays, as LLVM defines it on the emitted types (IEEE, round to nearest)."""

    def const(self, v, ty: str) -> V:
        return V(self, np.array(v).astype(_NP[ty]), ty)

    def bin(self, op: str, a: V, b: V) -> V:
        x, y = a.h, b.h
        if op in ("fadd", "add"):
            r = x + y
        elif op in ("fsub", "sub"):
            r = x - y
        elif op in ("fmul", "mul"):
            r = x * y
        elif op == "fdiv":
            r = x / y
        elif op == "and":
            r = x & y
        elif op == "or":
            r = x | y
        elif op == "xor":
            r = x ^ y
        elif op == "shl":
            r = np.asarray(x).view(_UNSIGNED[a.ty]) << np.asarray(y).astype(_UNSIGNED[a.ty])
        else:  # lshr
            r = np.asarray(x).view(_UNSIGNED[a.ty]) >> np.asarray(y).astype(_UNSIGNED[a.ty])
        return V(self, np.asarray(r).view(_NP[a.ty]) if a.ty in _UNSIGNED else np.asarray(r), a.ty)

    def cmp(self, pred: str, a: V, b: V) -> V:
        x, y = a.h, b.h
        r = {"olt": lambda: x < y, "ogt": lambda: x > y, "oeq": lambda: x == y, "ole": lambda: x <= y,
             "oge": lambda: x >= y, "uno": lambda: np.isnan(x) | np.isnan(y),
             "one": lambda: (x != y) & ~np.isnan(x) & ~np.isnan(y),
             "slt": lambda: x < y, "eq": lambda: x == y, "ne": lambda: x != y}[pred]()
        return V(self, np.asarray(r), "i1")

    def select(self, c: V, a: V, b: V) -> V:
        return V(self, np.where(c.h, a.h, b.h).astype(_NP[a.ty]), a.ty)

    def cast(self, how: str, a: V, ty: str) -> V:
        x = np.asarray(a.h)
        r: np.ndarray
        if how == "bitcast":
            r = x.view(_NP[ty])
        elif how == "zext" and a.ty != "i1":
            r = x.view(_UNSIGNED[a.ty]).astype(_NP[ty])
        else:  # fpext, fptrunc, trunc (wraps), sext, sitofp, zext of i1
            r = x.astype(_NP[ty])
        return V(self, r, ty)

    def call(self, name: str, *args: V) -> V:
        a = args[0].h
        if name == "fabs":
            r = np.abs(a)
        elif name == "copysign":
            r = np.copysign(a, args[1].h)
        else:  # fma, only where its result is exact: a * b = p + e exactly (Dekker), then (p + c) + e
            p, e = _dekker(a, args[1].h)
            r = (p + args[2].h) + e
        return V(self, np.asarray(r), args[0].ty)

    def load(self, table: str, idx: V) -> V:
        return V(self, TABLES[table][idx.h], "double")

    def fallback(self, cond: V, name: str, args: list[V], fast: V) -> V:
        out = np.array(fast.h, dtype=np.float64, copy=True).reshape(-1)
        c = np.broadcast_to(cond.h, out.shape)
        vals = [np.broadcast_to(a.h, out.shape) for a in args]
        with numeric.flushing(frozenset()):
            for i in np.flatnonzero(c):
                out[i] = numeric.libm(name, dt.f64, *(float(v[i]) for v in vals))
        return V(self, out.reshape(np.shape(fast.h)), "double")


def _dekker(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a * b = p + e exactly (Veltkamp splitting; |a|, |b| < 2**995)."""
    def split(v):
        c = v * 134217729.0
        hi = c - (c - v)
        return hi, v - hi

    p = a * b
    ah, al = split(a)
    bh, bl = split(b)
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


def evaluate(fn: Callable[..., V], *args, f64: bool = False) -> np.ndarray:
    """What the compiled function computes, on float32 (f64: float64) arrays, elementwise."""
    be = _Numpy()
    ty, npt = ("double", np.float64) if f64 else ("float", np.float32)
    with np.errstate(all="ignore"):
        vs = [V(be, np.asarray(a, dtype=npt), ty) for a in args]
        return np.asarray(fn(*vs).h, dtype=npt)
