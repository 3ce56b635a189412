"""Builds IR, checking types as it goes. The only way statements are created."""

from __future__ import annotations

from contextlib import contextmanager

from simgrad import dtypes as dt
from simgrad.dtypes import DataType
from simgrad.errors import Loc, SimgradTypeError
from simgrad.ir import numeric
from simgrad.ir import ops as O
from simgrad.ir.nodes import Block, Stmt
from simgrad.ir.ops import Op


class Builder:
    def __init__(self, block: Block):
        self.blocks = [block]
        self.loc: Loc | None = None

    @property
    def block(self) -> Block:
        return self.blocks[-1]

    def emit(self, op: Op, type: DataType | None, operands=(), attrs=None, nblocks: int = 0) -> Stmt:
        if op is Op.CONST:  # a constant is a value, placed in no block (it prints inline)
            return self.detached(op, type, operands, attrs, self.loc)
        s = self.detached(op, type, operands, attrs, self.loc, self.block, nblocks)
        self.block.stmts.append(s)
        return s

    @staticmethod
    def detached(op: Op, type: DataType | None, operands=(), attrs=None, loc: Loc | None = None,
                 block: Block | None = None, nblocks: int = 0) -> Stmt:
        """A statement that the caller places itself (a transform inserting at a position it computed):
        still made here, so every statement comes from the builder."""
        s = Stmt(op, type, tuple(operands), attrs or {}, loc)
        if nblocks:
            s.blocks = tuple(Block(s) for _ in range(nblocks))
        s.block = block
        return s

    @contextmanager
    def inside(self, block: Block):
        self.blocks.append(block)
        try:
            yield block
        finally:
            self.blocks.pop()

    # -- typed helpers ---------------------------------------------------------------------
    def const(self, value, type: DataType) -> Stmt:
        """A constant, its value wrapped or rounded to `type` (ir/numeric.py). Constants are values, as in
        LLVM: placed in no block, so any statement anywhere may use one (the verifier checks that)."""
        return self.constant(numeric.const_value(value, type), type)

    @staticmethod
    def constant(value, type: DataType, loc: Loc | None = None) -> Stmt:
        """A constant of an already exact value (a fold's result)."""
        return Stmt(Op.CONST, type, (), {"value": value}, loc)

    def cast(self, v: Stmt, type: DataType) -> Stmt:
        if v.type is type:
            return v
        if v.op is Op.CONST:
            folded = numeric.convert(v.attrs["value"], v.vtype, type)
            if folded is not None:
                return self.constant(folded, type, self.loc)
        return self.emit(Op.CAST, type, (v,))

    def binary(self, op: Op, a: Stmt, b: Stmt) -> Stmt:
        if a.type is not b.type:
            raise SimgradTypeError(f"internal: {op.name} on {a.type} and {b.type}", self.loc)
        if op in O.FLOAT_ONLY and not a.vtype.is_float:
            raise SimgradTypeError(f"{op.name.lower()} needs floating-point operands, got {a.type}", self.loc)
        if op in O.INT_ONLY and a.vtype.is_float:
            raise SimgradTypeError(f"{op.name.lower()} needs integer operands, got {a.type}", self.loc)
        result = dt.i32 if op in O.COMPARE else a.type
        return self.emit(op, result, (a, b))

    def unary(self, op: Op, a: Stmt) -> Stmt:
        if op in O.FLOAT_ONLY and not a.vtype.is_float:
            raise SimgradTypeError(f"{op.name.lower()} needs a floating-point operand, got {a.type}", self.loc)
        if op in O.INT_ONLY and a.vtype.is_float:
            raise SimgradTypeError(f"{op.name.lower()} needs an integer operand, got {a.type}", self.loc)
        result = dt.i32 if op is Op.LOGICAL_NOT else a.type
        return self.emit(op, result, (a,))

    def select(self, cond: Stmt, a, b) -> Stmt:
        a, b = self._pair(a, b)
        if a.type is not b.type:
            raise SimgradTypeError(f"internal: select on {a.type} and {b.type}", self.loc)
        return self.emit(Op.SELECT, a.type, (cond, a, b))

    # -- arithmetic on values and Python numbers (what derivative rules are written with) ---------------
    def _pair(self, a, b) -> tuple[Stmt, Stmt]:
        """Both as statements: a Python number takes the other operand's type."""
        if not isinstance(a, Stmt):
            a = self.const(a, b.vtype)
        if not isinstance(b, Stmt):
            b = self.const(b, a.vtype)
        return a, b

    def _arith(self, op: Op, a, b) -> Stmt:
        a, b = self._pair(a, b)
        return self.binary(op, a, b)

    def add(self, a, b) -> Stmt:
        return self._arith(Op.ADD, a, b)

    def sub(self, a, b) -> Stmt:
        return self._arith(Op.SUB, a, b)

    def mul(self, a, b) -> Stmt:
        return self._arith(Op.MUL, a, b)

    def div(self, a, b) -> Stmt:
        return self._arith(Op.DIV, a, b)

    def pow(self, a, b) -> Stmt:
        return self._arith(Op.POW, a, b)

    def lt(self, a, b) -> Stmt:
        return self._arith(Op.LT, a, b)

    def le(self, a, b) -> Stmt:
        return self._arith(Op.LE, a, b)

    def gt(self, a, b) -> Stmt:
        return self._arith(Op.GT, a, b)

    def ge(self, a, b) -> Stmt:
        return self._arith(Op.GE, a, b)

    def eq(self, a, b) -> Stmt:
        return self._arith(Op.EQ, a, b)

    def neg(self, a: Stmt) -> Stmt:
        return self.unary(Op.NEG, a)

    def sqrt(self, a: Stmt) -> Stmt:
        return self.unary(Op.SQRT, a)

    def rsqrt(self, a: Stmt) -> Stmt:
        return self.unary(Op.RSQRT, a)

    def sin(self, a: Stmt) -> Stmt:
        return self.unary(Op.SIN, a)

    def cos(self, a: Stmt) -> Stmt:
        return self.unary(Op.COS, a)

    def tan(self, a: Stmt) -> Stmt:
        return self.unary(Op.TAN, a)

    def exp(self, a: Stmt) -> Stmt:
        return self.unary(Op.EXP, a)

    def log(self, a: Stmt) -> Stmt:
        return self.unary(Op.LOG, a)

    def tanh(self, a: Stmt) -> Stmt:
        return self.unary(Op.TANH, a)
