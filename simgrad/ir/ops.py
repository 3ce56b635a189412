"""The IR's operations (`Op`, defined with the elementwise registry in ir/opdefs.py) and the sets of them
that passes test membership in, derived from the registry where they concern elementwise ops."""

from __future__ import annotations

from simgrad.ir.opdefs import FLOAT, I32, INT, OPS, Op

__all__ = ["Op", "OPS", "BINARY_ARITH", "COMPARE", "UNARY_MATH", "FLOAT_ONLY", "INT_ONLY", "SIDE_EFFECTS",
           "PURE", "ELEMENTWISE"]

ELEMENTWISE = set(OPS)
COMPARE = {op for op, d in OPS.items() if d.arity == 2 and d.result == I32}
BINARY_ARITH = {op for op, d in OPS.items() if d.arity == 2} - COMPARE
UNARY_MATH = {op for op, d in OPS.items() if d.arity == 1}
FLOAT_ONLY = {op for op, d in OPS.items() if d.domain == FLOAT}
INT_ONLY = {op for op, d in OPS.items() if d.domain == INT}
# Statements with an effect beyond their value: never removed by dead-code elimination.
SIDE_EFFECTS = {
    Op.LOCAL_STORE, Op.GLOBAL_STORE, Op.ATOMIC, Op.RET_STORE, Op.IF, Op.RANGE_FOR, Op.WHILE, Op.BREAK,
    Op.CONTINUE, Op.PRINT, Op.ASSERT, Op.RANDOM, Op.TAPE_RESET, Op.TAPE_PUSH, Op.TAPE_POP, Op.CHECK_INDEX,
    Op.SNODE_OP, Op.SPARSE_CELL, Op.SPARSE_ACTION, Op.CALL, Op.FUNC_RETURN,
}
# Pure value computations: candidates for common-subexpression elimination and folding.
PURE = ELEMENTWISE | {Op.CONST, Op.CAST, Op.BITCAST, Op.SELECT, Op.ARG, Op.ARRAY_SHAPE, Op.GLOBAL_PTR, Op.TREE_ROOT}
