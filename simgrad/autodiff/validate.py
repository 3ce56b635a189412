"""The global data access rules of differentiable kernels (DiffTaichi): once a field element has been
read, it must not be overwritten, or the adjoint (which replays the forward reads) sees a different
value and silently returns a wrong gradient.

At compile time, when a kernel's adjoint is built, a store to exactly the element the same kernel read
(same field, same index values in the IR) is an error. The run-time check (what the Tape fingerprints)
is lang-level: lang/tape.py.
"""

from __future__ import annotations

from simgrad.errors import GradientError, Loc
from simgrad.ir.fieldref import ArrayRef, FieldRef
from simgrad.ir.nodes import Kernel, walk
from simgrad.ir.ops import Op


def differentiable(target) -> bool:
    """A field with a placed gradient (what the Tape's run-time checks watch)."""
    return isinstance(target, FieldRef) and target.dtype.is_float and target.grad is not None


def _has_adjoint(target) -> bool:
    return isinstance(target, (FieldRef, ArrayRef)) and target.dtype.is_float and target.grad is not None


def user_name(target) -> str:
    return target.name.split("[")[0]


def check_access_rules(kernel: Kernel) -> None:
    """Raise a located GradientError where the IR proves a read-then-overwrite of the same element."""
    read: dict[tuple, Loc | None] = {}
    for s in walk(kernel.body):
        if s.op not in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE):
            continue
        ptr = s.operands[0]
        target = ptr.attrs["target"]
        if isinstance(target, ArrayRef) and target.shape_slot >= 0:
            raise GradientError(f"Cannot automatically differentiate through a grad tensor: kernel "
                                f"{kernel.name.removesuffix('_grad')} accesses '{target.name}'", s.loc)
        if not _has_adjoint(target):
            continue
        key = (id(target), tuple(id(o) for o in ptr.operands))
        if s.op is Op.GLOBAL_LOAD:
            read.setdefault(key, s.loc)
        elif key in read:
            where = read[key]
            name = kernel.name.removesuffix("_grad")
            raise GradientError(
                f"kernel {name} overwrites an element of {_kind(target)} '{user_name(target)}' that it read "
                f"(at line {where.line if where else '?'}); its adjoint would replay the read with the new "
                "value and give a wrong gradient. Write the result to another field or time step "
                "(e.g. x[t + 1] = f(x[t])).", s.loc)


def _kind(target) -> str:
    return "field" if isinstance(target, FieldRef) else "ndarray"


def check_and_adjoint(kernel: Kernel) -> bool:
    """The pipeline step for .grad kernels: the compile-time rule check, then the adjoint transform."""
    from simgrad.autodiff.reverse import make_adjoint

    check_access_rules(kernel)
    return make_adjoint(kernel)
