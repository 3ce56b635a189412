"""Builds IR, checking types as it goes. The only way statements are created."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import contextmanager
from typing import TYPE_CHECKING

from simgrad.dtypes import DataType
from simgrad.errors import Loc, SimgradTypeError
from simgrad.ir import numeric
from simgrad.ir.nodes import Block, Stmt
from simgrad.ir.opdefs import FLOAT, OPS, Op, OpDef

# Python's operator for the binary ops a type error names as Python does ("unsupported operand type(s) for '&'")
_SYMBOLS = {"bit_and": "&", "bit_or": "|", "bit_xor": "^", "shl": "<<", "shr": ">>"}


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
        """A constant of an already exact value (a fold's result; flushed if subnormal in flush-to-zero mode)."""
        if type.is_float:
            value = numeric.flush(value, type)
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
        return self.emit(op, self._checked(OPS[op], a.vtype), (a, b))

    def unary(self, op: Op, a: Stmt) -> Stmt:
        return self.emit(op, self._checked(OPS[op], a.vtype), (a,))

    def _checked(self, d: OpDef, t: DataType) -> DataType:
        """The result type of `d` on operands of type `t` (a located error where it does not take them)."""
        if not d.accepts(t):
            kind = "floating-point" if d.domain == FLOAT else "integer"
            if d.arity == 1:  # Taichi's words
                inputs = "real" if d.domain == FLOAT else "integral"
                raise SimgradTypeError(f"'{d.name}' takes {inputs} inputs only, got {t}", self.loc)
            symbol = _SYMBOLS.get(d.name)
            taichi = f"unsupported operand type(s) for '{symbol}': " if symbol else ""
            raise SimgradTypeError(f"{taichi}{d.name} needs {kind} operands, got {t}", self.loc)
        return d.result_type(t)

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

    if TYPE_CHECKING:
        def __getattr__(self, name: str) -> Callable[..., Stmt]:
            """The helpers below, one per registry op: `b.add(x, 1.0)`, `b.atan2(y, x)`, `b.sin(x)`."""


def _helper(d: OpDef) -> Callable[..., Stmt]:
    """`b.<op>(...)`: a binary op takes statements or Python numbers (typed like the other operand)."""
    op = d.op
    fn: Callable[..., Stmt]
    if d.arity == 2:
        def binary(self: Builder, a, b) -> Stmt:
            return self._arith(op, a, b)
        fn = binary
    else:
        def unary(self: Builder, a: Stmt) -> Stmt:
            return self.unary(op, a)
        fn = unary
    fn.__name__ = fn.__qualname__ = d.name
    return fn


for _d in OPS.values():
    assert not hasattr(Builder, _d.name), _d.name  # a registry op must not shadow a builder method
    setattr(Builder, _d.name, _helper(_d))


def clone(s: Stmt, mapping: dict, block: Block | None) -> Stmt:
    """A copy of `s` and everything nested in it; operands defined inside are the copies' (`mapping`: id of
    an original -> its copy, or what to use instead of it)."""
    new = Builder.detached(s.op, s.type, tuple(mapping.get(id(o), o) for o in s.operands), dict(s.attrs), s.loc,
                           block, len(s.blocks))
    mapping[id(s)] = new
    for old_b, new_b in zip(s.blocks, new.blocks):
        new_b.stmts = [clone(x, mapping, new_b) for x in old_b.stmts]
    return new
