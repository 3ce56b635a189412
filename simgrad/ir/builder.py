"""Builds IR, checking types as it goes. The only way statements are created."""

from __future__ import annotations

from contextlib import contextmanager

from simgrad import dtypes as dt
from simgrad.dtypes import DataType
from simgrad.errors import Loc, SimgradTypeError
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
        s = Stmt(op, type, tuple(operands), attrs or {}, self.loc)
        if nblocks:
            s.blocks = tuple(Block(s) for _ in range(nblocks))
        s.block = self.block
        self.block.stmts.append(s)
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
        if type.is_float:
            value = float(value)
        elif type is dt.u1:
            value = int(bool(value))
        else:
            value = _wrap_int(int(value), type)
        return self.emit(Op.CONST, type, (), {"value": value})

    def cast(self, v: Stmt, type: DataType) -> Stmt:
        if v.type is type:
            return v
        if v.op is Op.CONST:
            return self.const(v.attrs["value"], type)
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

    def select(self, cond: Stmt, a: Stmt, b: Stmt) -> Stmt:
        if a.type is not b.type:
            raise SimgradTypeError(f"internal: select on {a.type} and {b.type}", self.loc)
        return self.emit(Op.SELECT, a.type, (cond, a, b))


def _wrap_int(v: int, t: DataType) -> int:
    """Two's-complement wrap-around of a Python int into `t`'s range."""
    mask = (1 << t.bits) - 1
    v &= mask
    if t.is_signed and v >> (t.bits - 1):
        v -= 1 << t.bits
    return v
