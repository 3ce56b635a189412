"""The IR's operations and the facts about each, kept in tables keyed by `Op` rather than if-chains."""

from __future__ import annotations

from enum import Enum, auto


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


BINARY_ARITH = {
    Op.ADD, Op.SUB, Op.MUL, Op.DIV, Op.FLOORDIV, Op.MOD, Op.RAW_DIV, Op.RAW_MOD, Op.POW, Op.MIN, Op.MAX,
    Op.BIT_AND, Op.BIT_OR, Op.BIT_XOR, Op.SHL, Op.SHR, Op.ATAN2,
}
COMPARE = {Op.LT, Op.LE, Op.GT, Op.GE, Op.EQ, Op.NE}
UNARY_MATH = {
    Op.SQRT, Op.RSQRT, Op.SIN, Op.COS, Op.TAN, Op.ASIN, Op.ACOS, Op.EXP, Op.LOG, Op.TANH, Op.FLOOR,
    Op.CEIL, Op.ROUND, Op.ABS, Op.NEG, Op.BIT_NOT, Op.LOGICAL_NOT,
}
FLOAT_ONLY = {
    Op.DIV, Op.SQRT, Op.RSQRT, Op.SIN, Op.COS, Op.TAN, Op.ASIN, Op.ACOS, Op.ATAN2, Op.EXP, Op.LOG, Op.TANH,
}
INT_ONLY = {Op.FLOORDIV, Op.MOD, Op.RAW_MOD, Op.BIT_AND, Op.BIT_OR, Op.BIT_XOR, Op.BIT_NOT, Op.SHL, Op.SHR}
CONTROL = {Op.IF, Op.RANGE_FOR, Op.WHILE}
# Statements with an effect beyond their value: never removed by dead-code elimination.
SIDE_EFFECTS = {
    Op.LOCAL_STORE, Op.GLOBAL_STORE, Op.ATOMIC, Op.RET_STORE, Op.IF, Op.RANGE_FOR, Op.WHILE, Op.BREAK,
    Op.CONTINUE, Op.PRINT, Op.ASSERT, Op.RANDOM, Op.TAPE_RESET, Op.TAPE_PUSH, Op.TAPE_POP, Op.CHECK_INDEX,
    Op.SNODE_OP, Op.SPARSE_CELL, Op.SPARSE_ACTION,
}
# Pure value computations: candidates for common-subexpression elimination and folding.
PURE = BINARY_ARITH | COMPARE | UNARY_MATH | {Op.CONST, Op.CAST, Op.BITCAST, Op.SELECT, Op.ARG,
                                              Op.ARRAY_SHAPE, Op.GLOBAL_PTR, Op.TREE_ROOT}
ATOMIC_KINDS = ("add", "sub", "mul", "min", "max", "and", "or", "xor", "xchg")
