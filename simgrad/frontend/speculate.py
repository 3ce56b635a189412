"""Which statements of a run-time choice's sides (`a and b`, `a or b`, `x if c else y`) may run before the
choice is known: then both sides are computed and a select picks one, with no branch around them. Pure
arithmetic may (integer division by zero does not trap: codegen divides by 1), and so may a load of a
dense field element whose indices are provably inside the field's shape, such as the element a
struct-for visits (`i < 3 and grid_v[i, j][0] < 0`): reading it cannot fault and nothing but the choice
sees its value. A call, a store, a print, a debug overflow report, an index check, an ndarray or sparse
element, or an index not known in bounds (`i < n and x[i] > 0` must not read x[n]) keeps the branch, as
in Taichi with short_circuit_operators."""

from __future__ import annotations

from simgrad.ir import ops as O
from simgrad.ir.bounds import in_bounds
from simgrad.ir.nodes import walk
from simgrad.ir.ops import Op

_ALWAYS = O.PURE | {Op.LOCAL_LOAD, Op.ALLOCA}


def speculatable(blocks) -> bool:
    """May every statement of these blocks (the sides of a choice) run whether or not its side is chosen?
    Locals the sides declare may be stored to (a ti.func's parameters), nothing else."""
    own = {x for b in blocks for x in walk(b) if x.op is Op.ALLOCA}
    for b in blocks:
        for x in walk(b):
            if x.op is Op.GLOBAL_LOAD:
                if not in_bounds(x.operands[0]):
                    return False
            elif x.op is Op.LOCAL_STORE:
                if x.operands[0] not in own:
                    return False
            elif x.op not in _ALWAYS or "overflow" in x.attrs:
                return False
    return True
