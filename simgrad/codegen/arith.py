"""Elementwise ops as their registry entries say (ir/opdefs.py), the named special emitters (Python's //
and %, masked shifts, ...), conversions and random numbers."""

from __future__ import annotations

import linecache
from collections.abc import Callable

from simgrad import dtypes as dt
from simgrad.codegen import vecmath
from simgrad.ir.opdefs import OPS, Compare, Instr, Intrinsic, Libm, Op
from simgrad.ir.vecmath import FUNCTIONS, FUNCTIONS64


def _sfx(t: dt.DataType) -> str:
    return {"float": "f32", "double": "f64", "half": "f16"}.get(t.llvm, t.llvm)


def _intrinsic(f, name: str, t: dt.DataType, args: list[str], flags: str = "") -> str:
    ty = t.llvm
    fn = f"@llvm.{name}.{_sfx(t)}"
    f.gen.module.declare(f"declare {ty} {fn}({', '.join([ty] * len(args))})")
    r = f.tmp(name.split(".")[0])
    f.emit(f"{r} = call {flags}{ty} {fn}({', '.join(f'{ty} {a}' for a in args)})")
    return r


#: a float min/max of a reduction a serial loop carries (passes/accumulate.py marks it `reassoc`, fast_math
#: only): minimumnum/maximumnum give minnum/maxnum's value (the other operand for a NaN; equal zeros either
#: way under nsz), and LLVM 22 vectorises any number of such reductions in one loop, minnum ones only alone
_REDUCTION = {Op.MIN: "minimumnum", Op.MAX: "maximumnum"}


def _libm(f, name: str, t: dt.DataType, args: list[str]) -> str:
    if t is dt.f16:
        wide = [_conv(f, a, dt.f16, dt.f32) for a in args]
        return _conv(f, _libm(f, name, dt.f32, wide), dt.f32, dt.f16)
    fn = name + ("f" if t is dt.f32 else "")
    ty = t.llvm
    f.gen.module.declare(f"declare {ty} @{fn}({', '.join([ty] * len(args))})")
    r = f.tmp(name)
    f.emit(f"{r} = call {ty} @{fn}({', '.join(f'{ty} {a}' for a in args)})")
    return r


def _safe_divisor(f, b: str, ty: str) -> str:
    """Integer division by zero must not trap the process: divide by 1 instead (result unspecified)."""
    z, r = f.tmp("z"), f.tmp("d")
    f.emit(f"{z} = icmp eq {ty} {b}, 0")
    f.emit(f"{r} = select i1 {z}, {ty} 1, {ty} {b}")
    return r


def _safe_signed_divisor(f, b: str, ty: str) -> tuple[str, str]:
    """Signed division also traps on INT_MIN / -1: divide by 1 instead and negate the quotient (wraps,
    as the C result would); the remainder by 1 is the correct 0. Returns (divisor, is_minus_one)."""
    m1, z, bad, r = f.tmp("m1"), f.tmp("z"), f.tmp("bad"), f.tmp("d")
    f.emit(f"{m1} = icmp eq {ty} {b}, -1")
    f.emit(f"{z} = icmp eq {ty} {b}, 0")
    f.emit(f"{bad} = or i1 {m1}, {z}")
    f.emit(f"{r} = select i1 {bad}, {ty} 1, {ty} {b}")
    return r, m1


def _negate_if(f, q: str, cond: str, ty: str) -> str:
    n, r = f.tmp("n"), f.tmp("v")
    f.emit(f"{n} = sub {ty} 0, {q}")
    f.emit(f"{r} = select i1 {cond}, {ty} {n}, {ty} {q}")
    return r


def _nonnegative_digit(x) -> bool:
    """x is the index of a loop starting at a constant >= 0, or a quotient of one by positive constants."""
    while x.op is Op.RAW_DIV and x.operands[1].op is Op.CONST and x.operands[1].attrs["value"] > 0:
        x = x.operands[0]
    start = x.operands[0] if x.op is Op.RANGE_FOR else None
    return start is not None and start.op is Op.CONST and start.attrs["value"] >= 0


def lower_elementwise(f, s) -> str:
    """An elementwise op, as its registry entry says (ir/opdefs.py): an instruction, an intrinsic, a libm
    call, a comparison or one of the named emitters in `SPECIAL`."""
    t = s.operands[0].type
    if "overflow" in s.attrs and t.is_int and s.op in _OVERFLOW:  # (a pass may have rewritten the op)
        return _checked_overflow(f, s, t)
    d = OPS[s.op]
    how = d.lower_float if t.is_float else d.lower_int
    if how is None:
        raise NotImplementedError(f"{s.op.name} on {t}")
    args = [f.v(o) for o in s.operands]
    if f.gen.vector_math and (t in (dt.f32, dt.f16) and s.op in FUNCTIONS or t is dt.f64 and s.op in FUNCTIONS64):
        if t is dt.f16:  # through f32, as libm's
            wide = [_conv(f, a, dt.f16, dt.f32) for a in args]
            return _conv(f, vecmath.emit_call(f, s.op, "float", wide), dt.f32, dt.f16)
        return vecmath.emit_call(f, s.op, t.llvm, args)
    if isinstance(how, Instr):
        r = f.tmp("v")
        if t.is_float:
            f.emit(f"{r} = {how.name} {f.gen.float_flags(s)}{t.llvm} {', '.join(args)}")
        else:
            flags = " nuw nsw" if s.attrs.get("nowrap") else ""  # address arithmetic (passes/lower_access.py)
            f.emit(f"{r} = {how.name}{flags} {t.llvm} {', '.join(args)}")
        return r
    if isinstance(how, Intrinsic):
        if s.op in _REDUCTION and s.attrs.get("reassoc") and t in (dt.f32, dt.f64) and f.gen.minmax_reductions:
            return _intrinsic(f, _REDUCTION[s.op], t, args, f.gen.float_flags(s).replace("reassoc ", ""))
        name = how.unsigned if how.unsigned and not t.is_signed else how.name
        return _intrinsic(f, name, t, args)
    if isinstance(how, Libm):
        return _libm(f, how.name, t, args)
    if isinstance(how, Compare):
        c, r = f.tmp("cmp"), f.tmp("v")
        if t.is_float:
            f.emit(f"{c} = fcmp {how.fcmp} {t.llvm} {args[0]}, {args[1]}")
        else:
            f.emit(f"{c} = icmp {how.signed if t.is_signed else how.unsigned} {t.llvm} {args[0]}, {args[1]}")
        f.emit(f"{r} = zext i1 {c} to i32")
        return r
    return SPECIAL[how.name](f, s, t, *args)


def _shift(f, s, t: dt.DataType, x: str, y: str) -> str:
    """A shift by >= the width is poison in LLVM: take the amount modulo the width, as x86 does at run time,
    so a constant shift and a run-time one agree."""
    amt, r = f.tmp("sh"), f.tmp("v")
    f.emit(f"{amt} = and {t.llvm} {y}, {t.bits - 1}")
    kind = "shl" if s.op is Op.SHL else "ashr" if t.is_signed else "lshr"
    f.emit(f"{r} = {kind} {t.llvm} {x}, {amt}")
    return r


_OVERFLOW = {Op.ADD: ("add", "Addition"), Op.SUB: ("sub", "Subtraction"), Op.MUL: ("mul", "Multiplication"),
             Op.SHL: ("shl", "Shift left")}


def _checked_overflow(f, s, t: dt.DataType) -> str:
    """Debug mode's + - * << the user wrote (frontend/lower.py marks them `overflow`): the wrapped value, and on
    overflow Taichi's report printed with the user's line (its debug_add/sub/mul/shl: the kernel goes on).
    + - * through llvm.[su]{add,sub,mul}.with.overflow; << overflows when shifting back does not give x."""
    x, y = (f.v(o) for o in s.operands)
    ty = t.llvm
    name, what = _OVERFLOW[s.op]
    if s.op is Op.SHL:
        r = _shift(f, s, t, x, y)
        amt, back, bad = f.tmp("sh"), f.tmp("back"), f.tmp("ovf")
        f.emit(f"{amt} = and {ty} {y}, {t.bits - 1}")
        f.emit(f"{back} = {'ashr' if t.is_signed else 'lshr'} {ty} {r}, {amt}")
        f.emit(f"{bad} = icmp ne {ty} {back}, {x}")
    else:
        fn = f"@llvm.{'s' if t.is_signed else 'u'}{name}.with.overflow.{ty}"
        f.gen.module.declare(f"declare {{ {ty}, i1 }} {fn}({ty}, {ty})")
        pair, r, bad = f.tmp("ov"), f.tmp("v"), f.tmp("ovf")
        f.emit(f"{pair} = call {{ {ty}, i1 }} {fn}({ty} {x}, {ty} {y})")
        f.emit(f"{r} = extractvalue {{ {ty}, i1 }} {pair}, 0")
        f.emit(f"{bad} = extractvalue {{ {ty}, i1 }} {pair}, 1")
    ok, report, done = f.tmp("nov"), f.label("overflow"), f.label("no_overflow")
    f.emit(f"{ok} = xor i1 {bad}, true")
    f.emit(f"br i1 {ok}, label %{done}, label %{report}, !prof !1")
    f.gen.need_branch_weights()
    f.start_block(report)
    text = f"{what} overflow detected in {overflow_traceback(*s.attrs['overflow'])}\n"
    f.gen.emit_print(f, f.gen.module.string(text.replace("%", "%%")), [])
    f.emit(f"br label %{done}")
    f.start_block(done)
    return r


def overflow_traceback(file: str, line: int, col: int, end_line: int, end_col: int, func: str) -> str:
    """Taichi's text for the place of an overflow: file, line and function, the source line, carets under the
    expression."""
    src = linecache.getline(file, line).rstrip("\n")
    head = f'File "{file}", line {line}, in {func}:\n'
    if not src:
        return head
    end = end_col if end_line == line else len(src)
    return f"{head}{src}\n{' ' * col}{'^' * max(1, end - col)}\n"


def _power_of_two(v) -> bool:
    return isinstance(v, int) and v > 0 and v & (v - 1) == 0


def _int_div(f, s, t: dt.DataType, x: str, y: str) -> str:
    """Integer // and % (Python's: FLOORDIV, MOD) and C's (RAW_DIV, RAW_MOD), never trapping."""
    a, b = s.operands
    op, ty, r = s.op, t.llvm, f.tmp("v")
    if op in (Op.RAW_DIV, Op.RAW_MOD) and _nonnegative_digit(a) and b.op is Op.CONST and b.attrs["value"] > 0:
        # a digit of a flat loop index (never negative): unsigned division is the same and a shift/mask
        f.emit(f"{r} = {'udiv' if op is Op.RAW_DIV else 'urem'} {ty} {x}, {y}")
        return r
    if not t.is_signed:
        d = _safe_divisor(f, y, ty)
        f.emit(f"{r} = {'udiv' if op in (Op.FLOORDIV, Op.RAW_DIV) else 'urem'} {ty} {x}, {d}")
        return r
    if op in (Op.FLOORDIV, Op.MOD) and b.op is Op.CONST and _power_of_two(b.attrs["value"]):
        # Python's floor semantics on two's complement: x // 2**k is x >> k, x % 2**k is x & (2**k - 1)
        k = int(b.attrs["value"]).bit_length() - 1
        f.emit(f"{r} = ashr {ty} {x}, {k}" if op is Op.FLOORDIV else f"{r} = and {ty} {x}, {(1 << k) - 1}")
        return r
    d, minus_one = _safe_signed_divisor(f, y, ty)
    if op is Op.RAW_DIV:
        f.emit(f"{r} = sdiv {ty} {x}, {d}")
        return _negate_if(f, r, minus_one, ty)
    if op is Op.RAW_MOD:
        f.emit(f"{r} = srem {ty} {x}, {d}")
        return r
    # Python semantics: the remainder takes the divisor's sign; the quotient rounds toward -inf
    q, m = f.tmp("q"), f.tmp("m")
    f.emit(f"{q} = sdiv {ty} {x}, {d}")
    f.emit(f"{m} = srem {ty} {x}, {d}")
    nz, sx, sd, diff, fix = f.tmp(), f.tmp(), f.tmp(), f.tmp(), f.tmp()
    f.emit(f"{nz} = icmp ne {ty} {m}, 0")
    f.emit(f"{sx} = icmp slt {ty} {m}, 0")
    f.emit(f"{sd} = icmp slt {ty} {d}, 0")
    f.emit(f"{diff} = xor i1 {sx}, {sd}")
    f.emit(f"{fix} = and i1 {nz}, {diff}")
    if op is Op.FLOORDIV:
        adj = f.tmp()
        f.emit(f"{adj} = sext i1 {fix} to {ty}")
        f.emit(f"{r} = add {ty} {q}, {adj}")
        return _negate_if(f, r, minus_one, ty)
    add = f.tmp()
    f.emit(f"{add} = select i1 {fix}, {ty} {d}, {ty} 0")
    f.emit(f"{r} = add {ty} {m}, {add}")
    return r


def _neg(f, s, t: dt.DataType, x: str) -> str:
    r = f.tmp("u")
    f.emit(f"{r} = fneg {f.gen.fm}{t.llvm} {x}" if t.is_float else f"{r} = sub {t.llvm} 0, {x}")
    return r


def _bit_not(f, s, t: dt.DataType, x: str) -> str:
    r = f.tmp("u")
    f.emit(f"{r} = xor {t.llvm} {x}, -1")
    return r


def _logical_not(f, s, t: dt.DataType, x: str) -> str:
    c, r = f.tmp("c"), f.tmp("u")
    f.emit(f"{c} = fcmp oeq {t.llvm} {x}, 0.0" if t.is_float else f"{c} = icmp eq {t.llvm} {x}, 0")
    f.emit(f"{r} = zext i1 {c} to i32")
    return r


def _int_abs(f, s, t: dt.DataType, x: str) -> str:
    if not t.is_signed:
        return x  # |u| = u; llvm.abs reads its operand as signed
    ty, r = t.llvm, f.tmp("u")
    f.gen.module.declare(f"declare {ty} @llvm.abs.{ty}({ty}, i1)")
    f.emit(f"{r} = call {ty} @llvm.abs.{ty}({ty} {x}, i1 false)")
    return r


def _rsqrt(f, s, t: dt.DataType, x: str) -> str:
    sq, r = _intrinsic(f, "sqrt", t, [x]), f.tmp("u")
    f.emit(f"{r} = fdiv {f.gen.fm}{t.llvm} 1.0, {sq}")
    return r


# the emitters that opdefs.Special names
SPECIAL: dict[str, Callable[..., str]] = {
    "shift": _shift, "int_div": _int_div, "neg": _neg, "bit_not": _bit_not, "logical_not": _logical_not,
    "int_abs": _int_abs, "rsqrt": _rsqrt,
}


def _conv(f, x: str, src: dt.DataType, dst: dt.DataType) -> str:
    if src is dst:
        return x
    if dt.f16 in (src, dst) and dt.f32 not in (src, dst):
        return _conv_f16(f, x, src, dst)
    r = f.tmp("cv")
    if src.is_float and dst is dt.u1:
        f.emit(f"{r} = fcmp une {src.llvm} {x}, 0.0")  # truthiness, as an integer's icmp ne 0
    elif src.is_float and dst.is_float:
        f.emit(f"{r} = {'fpext' if dst.bits > src.bits else 'fptrunc'} {src.llvm} {x} to {dst.llvm}")
    elif src.is_float:
        f.emit(f"{r} = {'fptosi' if dst.is_signed else 'fptoui'} {src.llvm} {x} to {dst.llvm}")
    elif dst.is_float:
        f.emit(f"{r} = {'sitofp' if src.is_signed else 'uitofp'} {src.llvm} {x} to {dst.llvm}")
    elif dst is dt.u1:
        f.emit(f"{r} = icmp ne {src.llvm} {x}, 0")
    elif dst.bits == src.bits:
        return x
    elif dst.bits < src.bits:
        f.emit(f"{r} = trunc {src.llvm} {x} to {dst.llvm}")
    else:
        f.emit(f"{r} = {'sext' if src.is_signed else 'zext'} {src.llvm} {x} to {dst.llvm}")
    return r


def _conv_f16(f, x: str, src: dt.DataType, dst: dt.DataType) -> str:
    """Every f16 conversion goes through f32, the only one x86 has instructions for (F16C): LLVM would
    otherwise call compiler-rt's __truncdfhf2 & co., which the JIT cannot resolve (the process aborts).
    Integers <-> f16 through f32 round once (an integer that f32 rounds is beyond f16's range anyway);
    f64 -> f16 rounds to odd at f32 first, so the second rounding is exact (matches numpy)."""
    if src is dt.f16:
        return _conv(f, _conv(f, x, dt.f16, dt.f32), dt.f32, dst)
    if src is dt.f64:
        return _conv(f, _f64_to_f32_odd(f, x), dt.f32, dt.f16)
    return _conv(f, _conv(f, x, src, dt.f32), dt.f32, dt.f16)


def _f64_to_f32_odd(f, x: str) -> str:
    """f64 -> f32 rounded to odd: truncate toward zero and set the last bit when inexact. With 24 >= 11 + 2
    significand bits, rounding that to f16 equals rounding the f64 directly (no double rounding)."""
    t, back, ax, ab, inexact, up, b, dec, b2, odd, b3, r = (f.tmp("ro") for _ in range(12))
    f.gen.module.declare("declare double @llvm.fabs.f64(double)")
    f.emit(f"{t} = fptrunc double {x} to float")
    f.emit(f"{back} = fpext float {t} to double")
    f.emit(f"{inexact} = fcmp one double {back}, {x}")  # false for NaN and exact values
    f.emit(f"{ax} = call double @llvm.fabs.f64(double {x})")
    f.emit(f"{ab} = call double @llvm.fabs.f64(double {back})")
    f.emit(f"{up} = fcmp ogt double {ab}, {ax}")  # rounded away from zero: step back one ulp
    f.emit(f"{b} = bitcast float {t} to i32")
    f.emit(f"{dec} = zext i1 {up} to i32")
    f.emit(f"{b2} = sub i32 {b}, {dec}")
    f.emit(f"{odd} = zext i1 {inexact} to i32")
    f.emit(f"{b3} = or i32 {b2}, {odd}")
    f.emit(f"{r} = bitcast i32 {b3} to float")
    return r


def lower_cast(f, v, dst: dt.DataType) -> str:
    return _conv(f, f.v(v), v.type, dst)


def random_value(f, t: dt.DataType) -> str:
    def u32() -> str:
        r = f.tmp("rnd")
        f.emit(f"{r} = call i32 @sg_rand_u32(ptr %ctx, i32 {f.tid})")
        return r

    if t is dt.f64:
        hi, lo = u32(), u32()
        a, b, c, d, e, g = (f.tmp() for _ in range(6))
        f.emit(f"{a} = zext i32 {hi} to i64")
        f.emit(f"{b} = shl i64 {a}, 21")
        f.emit(f"{c} = lshr i32 {lo}, 11")
        f.emit(f"{d} = zext i32 {c} to i64")
        f.emit(f"{e} = or i64 {b}, {d}")
        f.emit(f"{g} = uitofp i64 {e} to double")
        r = f.tmp("rf")
        f.emit(f"{r} = fmul double {g}, 0x3CA0000000000000")  # 2**-53
        return r
    if t.is_float:
        x = u32()
        a, b = f.tmp(), f.tmp()
        f.emit(f"{a} = lshr i32 {x}, 8")
        f.emit(f"{b} = uitofp i32 {a} to float")
        r = f.tmp("rf")
        f.emit(f"{r} = fmul float {b}, 0x3E70000000000000")  # 2**-24
        return _conv(f, r, dt.f32, t) if t is not dt.f32 else r
    if t.bits == 64:
        hi, lo = u32(), u32()
        a, b, c = f.tmp(), f.tmp(), f.tmp()
        f.emit(f"{a} = zext i32 {hi} to i64")
        f.emit(f"{b} = shl i64 {a}, 32")
        f.emit(f"{c} = zext i32 {lo} to i64")
        r = f.tmp("ri")
        f.emit(f"{r} = or i64 {b}, {c}")
        return r
    x = u32()
    return _conv(f, x, dt.u32, t) if t.bits != 32 else x
