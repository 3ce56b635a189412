"""IR invariants: every operand is defined before its use in an enclosing scope; operand types agree."""

from __future__ import annotations

from simgrad.errors import SimgradError
from simgrad.ir import ops as O
from simgrad.ir.nodes import Block, Kernel
from simgrad.ir.ops import Op


class IRVerifyError(SimgradError):
    pass


def verify(kernel: Kernel) -> bool:
    _block(kernel.body, set())
    return False


def _block(block: Block, visible: set) -> None:
    local = set(visible)
    for s in block.stmts:
        for o in s.operands:
            if id(o) not in local and o.op is not Op.CONST:  # constants have no scope
                raise IRVerifyError(f"internal: {s!r} uses {o!r} outside its scope", s.loc)
        if s.op in O.BINARY_ARITH or s.op in O.COMPARE:
            a, b = s.operands
            if a.type is not b.type and s.op not in (Op.SHL, Op.SHR):
                raise IRVerifyError(f"internal: {s!r} mixes {a.type} and {b.type}", s.loc)
        for b in s.blocks:
            inner = local | {id(s)} if s.op is Op.RANGE_FOR else local
            _block(b, inner)
        local.add(id(s))
