"""The IR's operations, and one entry per elementwise primitive holding everything known about it.

An `OpDef` says how many operands the op takes, which types it accepts, the type of its result, its exact
value (through ir/numeric.py, bit for bit what the compiled code computes), its reverse (VJP) rule, and
how codegen lowers it, as data. The rest of the compiler derives its tables from `OPS`: the op sets of
ir/ops.py, the builder's helpers (`b.atan2`), constant folding (passes/simplify.py), the derivative
tables (autodiff/rules.py), codegen's elementwise lowering (codegen/arith.py) and the math functions of
`ti.*` / `ti.math` (lang/operators.py). Adding a math function is one entry here (and its enum name), plus its
row in tests/ir/test_opdefs.py.

Reverse rules get the IR builder `b`, the adjoint of the result `g` and the operand values, and return
one contribution (or None) per operand, emitted with the builder: `lambda b, g, x: (b.mul(g, b.cos(x)),)`;
Python numbers stand for constants of the other operand's type.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum, auto
from typing import Any

import numpy as np

from simgrad import dtypes as dt
from simgrad.dtypes import DataType
from simgrad.ir import numeric as N


class Op(Enum):
    __hash__ = object.__hash__  # members are singletons: identity hashing, at C speed (hot in every pass)

    # memory
    CONST = auto()
    ARG = auto()  # a scalar kernel argument (attrs: slot)
    ALLOCA = auto()  # a mutable local
    LOCAL_LOAD = auto()
    LOCAL_STORE = auto()
    GLOBAL_PTR = auto()  # address of a field/ndarray element (attrs: target; operands: indices, and once
    #                      passes/lower_access.py has run (attrs: lowered) the element's byte offset last)
    CHECK_INDEX = auto()  # debug mode: an index (u64) checked against its extent; 0 when out of bounds
    GLOBAL_LOAD = auto()
    GLOBAL_STORE = auto()
    ATOMIC = auto()  # atomic read-modify-write, returns the old value (attrs: kind)
    ARRAY_SHAPE = auto()  # runtime extent of an ndarray argument (attrs: arg, dim)
    # sparse SNodes: SNODE_OP is what kernels say (attrs: op = is_active | activate | deactivate | length |
    # append_slot, snode: SNodeRef; operands: the node's indices; i32 result); passes/lower_access.py turns
    # it and every GLOBAL_PTR into a sparse field into the walk below, level by level
    SNODE_OP = auto()
    TREE_ROOT = auto()  # u64 address of an SNode tree's buffer (attrs: tree)
    SPARSE_CELL = auto()  # u64 address of a cell of a sparse level (operands: container address, cell
    #                       number; attrs: level, mode = read | write)
    SPARSE_ACTION = auto()  # SNODE_OP's effect on the last level (operands: container, cell; attrs: level, op)
    RET_STORE = auto()  # kernel return value (attrs: slot)
    # arithmetic
    ADD = auto()
    SUB = auto()
    MUL = auto()
    DIV = auto()  # float division
    FLOORDIV = auto()  # Python's // on integers
    MOD = auto()  # Python's % (sign of the divisor)
    RAW_DIV = auto()  # C division (truncation)
    RAW_MOD = auto()  # C remainder
    NEG = auto()
    POW = auto()
    MIN = auto()
    MAX = auto()
    BIT_AND = auto()
    BIT_OR = auto()
    BIT_XOR = auto()
    BIT_NOT = auto()
    SHL = auto()
    SHR = auto()  # arithmetic shift on signed, logical on unsigned
    LOGICAL_NOT = auto()
    CAST = auto()  # value conversion
    BITCAST = auto()
    SELECT = auto()
    # math
    SQRT = auto()
    RSQRT = auto()
    SIN = auto()
    COS = auto()
    TAN = auto()
    ASIN = auto()
    ACOS = auto()
    ATAN2 = auto()
    EXP = auto()
    LOG = auto()
    TANH = auto()
    LOG1P = auto()
    EXPM1 = auto()
    CBRT = auto()
    HYPOT = auto()
    FLOOR = auto()
    CEIL = auto()
    ROUND = auto()
    ABS = auto()
    # comparison (result i32: 1 or 0, as in Taichi)
    LT = auto()
    LE = auto()
    GT = auto()
    GE = auto()
    EQ = auto()
    NE = auto()
    # control
    IF = auto()  # blocks: then, else
    RANGE_FOR = auto()  # operands: begin, end; blocks: body; its own value is the loop index
    WHILE = auto()  # blocks: body (loops until BREAK)
    BREAK = auto()
    CONTINUE = auto()
    # runtime services
    PRINT = auto()
    ASSERT = auto()
    RANDOM = auto()
    THREAD_INDEX = auto()  # the thread running this iteration (ti.global_thread_idx)
    # autodiff: the per-thread tape (adstack) of values the adjoint needs, in LIFO order
    TAPE_RESET = auto()
    TAPE_PUSH = auto()
    TAPE_POP = auto()
    # real functions (a recursive ti.real_func, ir/nodes.py Function): PARAM is a parameter's value inside the
    # function (attrs: index); CALL calls one (attrs: func; operands: the arguments; no value); CALL_RESULT is
    # one of its results (operand: the CALL; attrs: index); FUNC_RETURN ends the function's body (operands: the
    # results, one per entry of Function.returns)
    PARAM = auto()
    CALL = auto()
    CALL_RESULT = auto()
    FUNC_RETURN = auto()


# -- lowering, as data (codegen/arith.py interprets these) -----------------------------------------------
@dataclass(frozen=True)
class Instr:
    """One LLVM instruction `name ty x, y` (floats carry the fast-math flags; integers nuw/nsw where the
    statement is marked nowrap)."""
    name: str


@dataclass(frozen=True)
class Intrinsic:
    """A call of `@llvm.<name>.<type>`; `unsigned` names the intrinsic for unsigned integers."""
    name: str
    unsigned: str | None = None


@dataclass(frozen=True)
class Libm:
    """A C math library call: `name` for f64, `name`f for f32, f16 through f32."""
    name: str


@dataclass(frozen=True)
class Compare:
    """icmp (signed / unsigned predicate) or fcmp, widened to an i32 0 or 1."""
    signed: str
    unsigned: str
    fcmp: str


@dataclass(frozen=True)
class Special:
    """A named emitter of codegen/arith.py (`SPECIAL`): Python's // and %, masked shifts, ..."""
    name: str


Lowering = Instr | Intrinsic | Libm | Compare | Special

ANY, FLOAT, INT = "any", "float", "int"  # operand domains
SAME, I32 = "same", "i32"  # result types: the operands' type, or i32 (0 or 1)


@dataclass(frozen=True)
class OpDef:
    """Everything about one elementwise primitive; the compiler's per-op tables are read off these."""
    op: Op
    arity: int
    domain: str  # ANY, FLOAT or INT
    exact: Callable[..., Any]  # (operand type, *values) -> the machine's result, or None where undefined
    lower_float: Lowering | None = None
    lower_int: Lowering | None = None
    result: str = SAME
    vjp: Callable[..., tuple] | None = None
    linear: bool = False  # the VJP needs no operand values
    zero_gradient: bool = False  # piecewise constant: derivative zero almost everywhere
    export: tuple[str, ...] = ()  # a math function in these namespaces: "ti" (ti.<name>), "math" (ti.math)
    python: Callable[..., Any] | None = None  # its value in Python scope
    sample: tuple[tuple[float, float], ...] = ()  # per operand, a range where it is smooth (fuzzing)

    @property
    def name(self) -> str:
        """The builder helper's and the math function's name."""
        return self.op.name.lower()

    def accepts(self, t: DataType) -> bool:
        return self.domain == ANY or (self.domain == FLOAT) == t.is_float

    def result_type(self, t: DataType) -> DataType:
        return dt.i32 if self.result == I32 else t

    def fold(self, t: DataType, *values):
        """The value this op computes on constant operands of type `t` (None: not folded)."""
        return self.exact(t, *values) if self.accepts(t) else None


# -- exact values -----------------------------------------------------------------------------------------
def _arith(ffn: Callable | None, ifn: Callable) -> Callable:
    """Floats through numpy's IEEE scalars of their width; integers in Python, wrapped to the type."""
    def exact(t: DataType, *v):
        if t.is_float:
            return None if ffn is None else N.ieee(ffn, t, *v)
        r = ifn(t, *v)
        return None if r is None else N.wrap_int(r, t)
    return exact


def _libm(name: str) -> Callable:
    return lambda t, *v: N.libm(name, t, *v)


def _divide(fn: Callable) -> Callable:
    """Integer division: undefined by zero (codegen divides by 1 rather than trap), so never folded."""
    return lambda t, a, b: None if b == 0 else fn(a, b)


def _compare(fn: Callable) -> Callable:
    return lambda t, a, b: int(fn(a, b))  # Python's float comparisons are fcmp's ordered ones, and != is une


def _minmax(pick: Callable) -> Callable:
    # llvm.minnum/maxnum: a NaN operand yields the other; the sign of an equal zero is unspecified
    return lambda t, a, b: N.minmax(pick, a, b) if t.is_float else pick(a, b)


def _bits(fn: Callable) -> Callable:
    return lambda t, a, b: N.wrap_int(fn(a, b), t)


def _shl(t: DataType, a: int, b: int) -> int:
    return N.wrap_int(a << N.shift_amount(b, t), t)


def _shr(t: DataType, a: int, b: int) -> int:
    return a >> N.shift_amount(b, t)  # Python's >> is arithmetic; an unsigned value is non-negative


def _neg(t: DataType, a):
    return -a if t.is_float else N.wrap_int(-a, t)


def _abs(t: DataType, a):
    if t.is_float:
        return math.fabs(a)
    return N.wrap_int(abs(a), t) if t.is_signed else a  # llvm.abs wraps INT_MIN


def _rsqrt(t: DataType, a: float) -> float:
    """1 / sqrt(a) as emitted: two instructions, each rounded to `t` (f16: each promoted and rounded back)."""
    return N.ieee(lambda one, s: one / s, t, 1.0, N.ieee(np.sqrt, t, a))


# -- reverse rules ---------------------------------------------------------------------------------------
def _div(b, g, x, y):
    return b.div(g, y), b.neg(b.div(b.mul(g, x), b.mul(y, y)))


def _pow(b, g, x, y):
    dx = b.mul(g, b.mul(y, b.pow(x, b.sub(y, 1.0))))
    positive = b.gt(x, 0.0)
    safe = b.select(positive, x, 1.0)
    dy = b.select(positive, b.mul(g, b.mul(b.pow(x, y), b.log(safe))), 0.0)
    return dx, dy


def _atan2(b, g, y, x):
    r = b.add(b.mul(x, x), b.mul(y, y))
    return b.div(b.mul(g, x), r), b.neg(b.div(b.mul(g, y), r))


def _min(b, g, x, y):
    first = b.le(x, y)  # ties go to the first operand
    return b.select(first, g, 0.0), b.select(first, 0.0, g)


def _max(b, g, x, y):
    first = b.ge(x, y)
    return b.select(first, g, 0.0), b.select(first, 0.0, g)


def _abs_vjp(b, g, x):
    return (b.select(b.gt(x, 0.0), g, b.select(b.lt(x, 0.0), b.neg(g), 0.0)),)


def _tan(b, g, x):
    t = b.tan(x)
    return (b.mul(g, b.add(b.mul(t, t), 1.0)),)


def _tanh(b, g, x):
    t = b.tanh(x)
    return (b.mul(g, b.sub(1.0, b.mul(t, t))),)


def _cbrt(b, g, x):
    c = b.cbrt(x)
    return (b.div(g, b.mul(b.mul(c, c), 3.0)),)


def _hypot(b, g, x, y):
    h = b.hypot(x, y)
    return b.div(b.mul(g, x), h), b.div(b.mul(g, y), h)


def _python_rsqrt(x):
    return 1.0 / math.sqrt(x)


_WIDE = ((-4.0, 4.0),)
_TI_MATH = ("ti", "math")


def _math(op: Op, lowering: Lowering, python: Callable, vjp: Callable | None, sample=_WIDE,
          export: tuple[str, ...] = _TI_MATH, exact: Callable | None = None) -> OpDef:
    """A float math function of ti.* / ti.math (an int operand is cast to default_fp by lang/operators.py)."""
    name = op.name.lower()
    return OpDef(op, len(sample), FLOAT, exact or _libm(name), lower_float=lowering, vjp=vjp, export=export,
                 python=python, sample=sample)


def _cmp(op: Op, fn: Callable, signed: str, unsigned: str, fcmp: str) -> OpDef:
    low = Compare(signed, unsigned, fcmp)
    return OpDef(op, 2, ANY, _compare(fn), low, low, result=I32, zero_gradient=True)


_INT_DIV = Special("int_div")
_DEFS = [
    OpDef(Op.ADD, 2, ANY, _arith(lambda a, b: a + b, lambda t, a, b: a + b), Instr("fadd"), Instr("add"),
          vjp=lambda b, g, x, y: (g, g), linear=True),
    OpDef(Op.SUB, 2, ANY, _arith(lambda a, b: a - b, lambda t, a, b: a - b), Instr("fsub"), Instr("sub"),
          vjp=lambda b, g, x, y: (g, b.neg(g)), linear=True),
    OpDef(Op.MUL, 2, ANY, _arith(lambda a, b: a * b, lambda t, a, b: a * b), Instr("fmul"), Instr("mul"),
          vjp=lambda b, g, x, y: (b.mul(g, y), b.mul(g, x))),
    OpDef(Op.DIV, 2, FLOAT, _arith(lambda a, b: a / b, lambda t, a, b: None), Instr("fdiv"), vjp=_div),
    OpDef(Op.FLOORDIV, 2, INT, _arith(None, _divide(lambda a, b: a // b)), lower_int=_INT_DIV),  # Python's //
    OpDef(Op.MOD, 2, INT, _arith(None, _divide(lambda a, b: a % b)), lower_int=_INT_DIV),  # Python's %
    OpDef(Op.RAW_DIV, 2, INT, _arith(None, _divide(N.c_div)), lower_int=_INT_DIV),  # C's /
    OpDef(Op.RAW_MOD, 2, INT, _arith(None, _divide(lambda a, b: a - b * N.c_div(a, b))), lower_int=_INT_DIV),
    OpDef(Op.POW, 2, FLOAT, _libm("pow"), Intrinsic("pow"), vjp=_pow),  # integer powers: lang/operators.py
    OpDef(Op.MIN, 2, ANY, _minmax(min), Intrinsic("minnum"), Intrinsic("smin", "umin"), vjp=_min),
    OpDef(Op.MAX, 2, ANY, _minmax(max), Intrinsic("maxnum"), Intrinsic("smax", "umax"), vjp=_max),
    OpDef(Op.BIT_AND, 2, INT, _bits(lambda a, b: a & b), lower_int=Instr("and")),
    OpDef(Op.BIT_OR, 2, INT, _bits(lambda a, b: a | b), lower_int=Instr("or")),
    OpDef(Op.BIT_XOR, 2, INT, _bits(lambda a, b: a ^ b), lower_int=Instr("xor")),
    OpDef(Op.SHL, 2, INT, _shl, lower_int=Special("shift")),
    OpDef(Op.SHR, 2, INT, _shr, lower_int=Special("shift")),  # arithmetic on signed, logical on unsigned
    OpDef(Op.NEG, 1, ANY, _neg, Special("neg"), Special("neg"), vjp=lambda b, g, x: (b.neg(g),), linear=True),
    OpDef(Op.BIT_NOT, 1, INT, lambda t, a: N.wrap_int(~a, t), lower_int=Special("bit_not")),
    OpDef(Op.LOGICAL_NOT, 1, ANY, lambda t, a: int(a == 0), Special("logical_not"), Special("logical_not"),
          result=I32, zero_gradient=True),
    OpDef(Op.ABS, 1, ANY, _abs, Intrinsic("fabs"), Special("int_abs"), vjp=_abs_vjp),
    OpDef(Op.FLOOR, 1, FLOAT, _libm("floor"), Intrinsic("floor"), zero_gradient=True),
    OpDef(Op.CEIL, 1, FLOAT, _libm("ceil"), Intrinsic("ceil"), zero_gradient=True),
    OpDef(Op.ROUND, 1, FLOAT, _libm("round"), Intrinsic("round"), zero_gradient=True),  # half away from zero
    _cmp(Op.LT, lambda a, b: a < b, "slt", "ult", "olt"),
    _cmp(Op.LE, lambda a, b: a <= b, "sle", "ule", "ole"),
    _cmp(Op.GT, lambda a, b: a > b, "sgt", "ugt", "ogt"),
    _cmp(Op.GE, lambda a, b: a >= b, "sge", "uge", "oge"),
    _cmp(Op.EQ, lambda a, b: a == b, "eq", "eq", "oeq"),
    _cmp(Op.NE, lambda a, b: a != b, "ne", "ne", "une"),
    # math functions (float operands)
    _math(Op.SQRT, Intrinsic("sqrt"), math.sqrt, lambda b, g, x: (b.div(b.mul(g, 0.5), b.sqrt(x)),),
          ((0.1, 9.0),), exact=lambda t, a: N.ieee(np.sqrt, t, a)),
    _math(Op.RSQRT, Special("rsqrt"), _python_rsqrt,
          lambda b, g, x: (b.mul(b.mul(g, -0.5), b.div(b.rsqrt(x), x)),), ((0.1, 9.0),), ("ti",), _rsqrt),
    _math(Op.SIN, Intrinsic("sin"), math.sin, lambda b, g, x: (b.mul(g, b.cos(x)),)),
    _math(Op.COS, Intrinsic("cos"), math.cos, lambda b, g, x: (b.neg(b.mul(g, b.sin(x))),)),
    _math(Op.TAN, Libm("tan"), math.tan, _tan, ((-1.3, 1.3),)),
    _math(Op.ASIN, Libm("asin"), math.asin,
          lambda b, g, x: (b.div(g, b.sqrt(b.sub(1.0, b.mul(x, x)))),), ((-0.9, 0.9),)),
    _math(Op.ACOS, Libm("acos"), math.acos,
          lambda b, g, x: (b.neg(b.div(g, b.sqrt(b.sub(1.0, b.mul(x, x))))),), ((-0.9, 0.9),)),
    _math(Op.ATAN2, Libm("atan2"), math.atan2, _atan2, ((-3.0, 3.0), (0.2, 3.0))),
    _math(Op.EXP, Intrinsic("exp"), math.exp, lambda b, g, x: (b.mul(g, b.exp(x)),)),
    _math(Op.LOG, Intrinsic("log"), math.log, lambda b, g, x: (b.div(g, x),), ((0.1, 9.0),)),
    _math(Op.TANH, Libm("tanh"), math.tanh, _tanh),
    _math(Op.LOG1P, Libm("log1p"), math.log1p, lambda b, g, x: (b.div(g, b.add(x, 1.0)),), ((-0.9, 4.0),),
          ("math",)),  # not in Taichi 1.7.4
    _math(Op.EXPM1, Libm("expm1"), math.expm1, lambda b, g, x: (b.mul(g, b.exp(x)),), export=("math",)),
    _math(Op.CBRT, Libm("cbrt"), math.cbrt, _cbrt, ((0.1, 8.0),), ("math",)),  # not differentiable at 0
    _math(Op.HYPOT, Libm("hypot"), math.hypot, _hypot, ((-3.0, 3.0), (0.2, 3.0)), ("math",)),  # kink at (0, 0)
]

OPS: dict[Op, OpDef] = {d.op: d for d in _DEFS}
