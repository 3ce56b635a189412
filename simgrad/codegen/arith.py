"""Arithmetic, math, comparison and conversion instructions, with Python's semantics for // and %."""

from __future__ import annotations

from simgrad import dtypes as dt
from simgrad.ir.ops import Op

_INT_BIN = {Op.ADD: "add", Op.SUB: "sub", Op.MUL: "mul", Op.BIT_AND: "and", Op.BIT_OR: "or",
            Op.BIT_XOR: "xor"}
_FLT_BIN = {Op.ADD: "fadd", Op.SUB: "fsub", Op.MUL: "fmul", Op.DIV: "fdiv"}
_ICMP = {Op.LT: "slt", Op.LE: "sle", Op.GT: "sgt", Op.GE: "sge", Op.EQ: "eq", Op.NE: "ne"}
_UCMP = {Op.LT: "ult", Op.LE: "ule", Op.GT: "ugt", Op.GE: "uge", Op.EQ: "eq", Op.NE: "ne"}
_FCMP = {Op.LT: "olt", Op.LE: "ole", Op.GT: "ogt", Op.GE: "oge", Op.EQ: "oeq", Op.NE: "une"}
_FLOAT_INTRINSIC = {Op.SQRT: "sqrt", Op.SIN: "sin", Op.COS: "cos", Op.EXP: "exp", Op.LOG: "log",
                    Op.FLOOR: "floor", Op.CEIL: "ceil", Op.ROUND: "round", Op.ABS: "fabs"}
_LIBM = {Op.TAN: "tan", Op.ASIN: "asin", Op.ACOS: "acos", Op.TANH: "tanh", Op.ATAN2: "atan2"}


def _sfx(t: dt.DataType) -> str:
    return {"float": "f32", "double": "f64", "half": "f16"}.get(t.llvm, t.llvm)


def _intrinsic(f, name: str, t: dt.DataType, args: list[str]) -> str:
    ty = t.llvm
    fn = f"@llvm.{name}.{_sfx(t)}"
    f.gen.module.declare(f"declare {ty} {fn}({', '.join([ty] * len(args))})")
    r = f.tmp(name.split(".")[0])
    f.emit(f"{r} = call {ty} {fn}({', '.join(f'{ty} {a}' for a in args)})")
    return r


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


def lower_binary(f, s) -> str:
    a, b = s.operands
    t = a.type
    ty = t.llvm
    x, y = f.v(a), f.v(b)
    op = s.op
    r = f.tmp("v")
    if op in _ICMP:
        c = f.tmp("cmp")
        if t.is_float:
            f.emit(f"{c} = fcmp {_FCMP[op]} {ty} {x}, {y}")
        else:
            f.emit(f"{c} = icmp {(_ICMP if t.is_signed else _UCMP)[op]} {ty} {x}, {y}")
        f.emit(f"{r} = zext i1 {c} to i32")
        return r
    if t.is_float:
        if op in _FLT_BIN:
            f.emit(f"{r} = {_FLT_BIN[op]} {f.gen.fm}{ty} {x}, {y}")
            return r
        if op is Op.POW:
            return _intrinsic(f, "pow", t, [x, y])
        if op in (Op.MIN, Op.MAX):
            return _intrinsic(f, "minnum" if op is Op.MIN else "maxnum", t, [x, y])
        if op is Op.ATAN2:
            return _libm(f, "atan2", t, [x, y])
        raise NotImplementedError(op)
    if op in (Op.SHL, Op.SHR):
        # a shift by >= the width is poison in LLVM: take the amount modulo the width, as x86 does at
        # run time, so a constant shift and a run-time one agree
        amt = f.tmp("sh")
        f.emit(f"{amt} = and {ty} {y}, {t.bits - 1}")
        kind = "shl" if op is Op.SHL else "ashr" if t.is_signed else "lshr"
        f.emit(f"{r} = {kind} {ty} {x}, {amt}")
        return r
    if op in _INT_BIN:
        flags = " nuw nsw" if s.attrs.get("nowrap") else ""  # address arithmetic (passes/lower_access.py)
        f.emit(f"{r} = {_INT_BIN[op]}{flags} {ty} {x}, {y}")
        return r
    if op in (Op.MIN, Op.MAX):
        name = ("s" if t.is_signed else "u") + ("min" if op is Op.MIN else "max")
        return _intrinsic(f, name, t, [x, y])
    if op in (Op.RAW_DIV, Op.RAW_MOD) and _nonnegative_digit(a) and b.op is Op.CONST and b.attrs["value"] > 0:
        # a digit of a flat loop index (never negative): unsigned division is the same and a shift/mask
        f.emit(f"{r} = {'udiv' if op is Op.RAW_DIV else 'urem'} {ty} {x}, {y}")
        return r
    if not t.is_signed:
        d = _safe_divisor(f, y, ty)
        f.emit(f"{r} = {'udiv' if op in (Op.FLOORDIV, Op.RAW_DIV) else 'urem'} {ty} {x}, {d}")
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
    elif op is Op.MOD:
        add = f.tmp()
        f.emit(f"{add} = select i1 {fix}, {ty} {d}, {ty} 0")
        f.emit(f"{r} = add {ty} {m}, {add}")
    elif op is Op.POW:
        raise NotImplementedError("integer pow is lowered by the frontend")
    else:
        raise NotImplementedError(op)
    return r


def lower_unary(f, s) -> str:
    (a,) = s.operands
    t = a.type
    ty = t.llvm
    x = f.v(a)
    op = s.op
    r = f.tmp("u")
    if op is Op.NEG:
        f.emit(f"{r} = fneg {f.gen.fm}{ty} {x}" if t.is_float else f"{r} = sub {ty} 0, {x}")
        return r
    if op is Op.BIT_NOT:
        f.emit(f"{r} = xor {ty} {x}, -1")
        return r
    if op is Op.LOGICAL_NOT:
        c = f.tmp("c")
        f.emit(f"{c} = fcmp oeq {ty} {x}, 0.0" if t.is_float else f"{c} = icmp eq {ty} {x}, 0")
        f.emit(f"{r} = zext i1 {c} to i32")
        return r
    if op is Op.ABS and not t.is_float:
        if not t.is_signed:
            return x  # |u| = u; llvm.abs reads its operand as signed
        f.gen.module.declare(f"declare {ty} @llvm.abs.{ty}({ty}, i1)")
        f.emit(f"{r} = call {ty} @llvm.abs.{ty}({ty} {x}, i1 false)")
        return r
    if op is Op.RSQRT:
        sq = _intrinsic(f, "sqrt", t, [x])
        f.emit(f"{r} = fdiv {f.gen.fm}{ty} 1.0, {sq}")
        return r
    if op in _FLOAT_INTRINSIC:
        return _intrinsic(f, _FLOAT_INTRINSIC[op], t, [x])
    return _libm(f, _LIBM[op], t, [x])


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
