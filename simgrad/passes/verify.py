"""IR invariants: every operand is defined before its use in an enclosing scope; operand types agree.

Constants are values placed in no block (ir/builder.py): one found in a block, or used as an operand while
it sits in a block, is an error, so a constant can never be out of scope."""

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
    """`visible` holds the values in scope; what this block defines is taken out again when it ends (one
    set for the whole walk, so a kernel of many nested branches costs linear time)."""
    added = []
    try:
        for s in block.stmts:
            _stmt(s, visible)
            for b in s.blocks:
                if s.op is Op.RANGE_FOR:  # the loop index is visible only inside the body
                    visible.add(id(s))
                    try:
                        _block(b, visible)
                    finally:
                        visible.discard(id(s))
                else:
                    _block(b, visible)
            visible.add(id(s))
            added.append(id(s))
    finally:
        visible.difference_update(added)


def _stmt(s, visible: set) -> None:
    if s.op is Op.CONST:
        raise IRVerifyError(f"internal: constant {s!r} placed in a block", s.loc)
    for o in s.operands:
        if o.op is Op.CONST:
            if o.block is not None:
                raise IRVerifyError(f"internal: {s!r} uses constant {o!r} placed in a block", s.loc)
        elif id(o) not in visible:
            raise IRVerifyError(f"internal: {s!r} uses {o!r} outside its scope", s.loc)
    if s.op in (Op.LOCAL_LOAD, Op.LOCAL_STORE):  # a lane local (passes/lanes.py) takes its lane's index last
        var = s.operands[0]
        laned = var.op is Op.ALLOCA and bool(var.attrs.get("lanes"))
        if len(s.operands) != (1 if s.op is Op.LOCAL_LOAD else 2) + laned:
            raise IRVerifyError(f"internal: {s!r} on {var!r} {'needs' if laned else 'takes no'} lane index", s.loc)
        if laned and not s.operands[-1].vtype.is_int:
            raise IRVerifyError(f"internal: {s!r} has a lane index of type {s.operands[-1].type}", s.loc)
    elif s.op is Op.ATOMIC and s.operands[0].op is Op.ALLOCA and s.operands[0].attrs.get("lanes"):
        raise IRVerifyError(f"internal: {s!r} updates lane local {s.operands[0]!r} (passes/lanes.py rewrites those)",
                            s.loc)
    if s.op in O.BINARY_ARITH or s.op in O.COMPARE:
        a, b = s.operands
        if a.type is not b.type and s.op not in (Op.SHL, Op.SHR):
            raise IRVerifyError(f"internal: {s!r} mixes {a.type} and {b.type}", s.loc)
