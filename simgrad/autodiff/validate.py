"""The global data access rules of differentiable kernels (DiffTaichi): once a field element has been
read, it must not be overwritten, or the adjoint (which replays the forward reads) sees a different
value and silently returns a wrong gradient.

Two checks. At compile time, when a kernel's adjoint is built, a store to exactly the element the same
kernel read (same field, same index values in the IR) is an error. At run time, under
`Tape(validation=True)` or `ti.init(debug=True)`, the Tape fingerprints every field a kernel reads when the
kernel runs forward and checks the fingerprints again right before the kernel's adjoint runs; a change
names the field, the kernel and the source line of the read.
"""

from __future__ import annotations

import hashlib

from simgrad.errors import GradientError, Loc
from simgrad.ir.nodes import Kernel, walk
from simgrad.ir.ops import Op
from simgrad.lang.field import ScalarField


def _differentiable(target) -> bool:
    return isinstance(target, ScalarField) and target.dtype.is_float and target.grad is not None \
        and target.grad.snode is not None


def _user_name(target) -> str:
    return target.name.split("[")[0]


def check_access_rules(kernel: Kernel) -> None:
    """Raise a located GradientError where the IR proves a read-then-overwrite of the same element."""
    read: dict[tuple, Loc | None] = {}
    for s in walk(kernel.body):
        if s.op not in (Op.GLOBAL_LOAD, Op.GLOBAL_STORE):
            continue
        ptr = s.operands[0]
        target = ptr.attrs["target"]
        if not _differentiable(target):
            continue
        key = (id(target), tuple(id(o) for o in ptr.operands))
        if s.op is Op.GLOBAL_LOAD:
            read.setdefault(key, s.loc)
        elif key in read:
            where = read[key]
            name = kernel.name.removesuffix("_grad")
            raise GradientError(
                f"kernel {name} overwrites an element of field '{_user_name(target)}' that it read "
                f"(at line {where.line if where else '?'}); its adjoint would replay the read with the new "
                "value and give a wrong gradient. Write the result to another field or time step "
                "(e.g. x[t + 1] = f(x[t])).", s.loc)


def check_and_adjoint(kernel: Kernel) -> bool:
    """The pipeline step for .grad kernels: the compile-time rule check, then the adjoint transform."""
    from simgrad.autodiff.reverse import make_adjoint

    check_access_rules(kernel)
    return make_adjoint(kernel)


def reads_of(kernel_ir: Kernel) -> dict:
    """{field component: location of its first read} for the fields a forward kernel reads."""
    out: dict = {}
    for s in walk(kernel_ir.body):
        if s.op is Op.GLOBAL_LOAD:
            target = s.operands[0].attrs["target"]
            if _differentiable(target):
                out.setdefault(target, s.loc)
    return out


def fingerprint(fields) -> dict:
    out = {}
    for f in fields:
        data = f.to_numpy()
        out[f] = hashlib.blake2b(data.tobytes(), digest_size=16).digest()
    return out


class Snapshot:
    """Fingerprints of what one forward launch read, checked before its adjoint launch."""

    def __init__(self, kernel, args):
        inst = kernel.instance(args)
        self.kernel = kernel
        self.reads = reads_of(inst.ir)
        self.prints = fingerprint(self.reads)

    def check(self) -> None:
        now = fingerprint(self.reads)
        for f, digest in self.prints.items():
            if now[f] != digest:
                loc = self.reads[f]
                raise GradientError(
                    f"global data access rule violated: field '{_user_name(f)}' was modified after kernel "
                    f"{self.kernel.name} read it, so its gradient would be computed from different values. "
                    "Keep every state a differentiated kernel reads unchanged until backward (e.g. store "
                    "each time step separately).", loc)
