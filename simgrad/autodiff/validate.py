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

import numpy as np

from simgrad.errors import GradientError, Loc
from simgrad.ir.fieldref import FieldRef
from simgrad.ir.nodes import Kernel, walk
from simgrad.ir.ops import Op


def _differentiable(target) -> bool:
    return isinstance(target, FieldRef) and target.dtype.is_float and target.grad is not None


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
    """{field component: (location of its first read, leading indices)} for the fields a forward kernel
    reads. The leading indices are IR expressions of the kernel's scalar arguments (`x[t - 1, i]`), or None
    when some read's first index depends on anything else: then the whole field is watched."""
    out: dict = {}
    for s in walk(kernel_ir.body):
        if s.op is Op.GLOBAL_LOAD:
            ptr = s.operands[0]
            target = ptr.attrs["target"]
            if not _differentiable(target):
                continue
            loc, leads = out.get(target, (s.loc, []))
            lead = ptr.operands[0] if ptr.operands and _evaluable(ptr.operands[0]) else None
            out[target] = (loc, None if leads is None or lead is None else leads + [lead])
    return out


_ARITH = {Op.ADD: lambda a, b: a + b, Op.SUB: lambda a, b: a - b, Op.MUL: lambda a, b: a * b}


def _evaluable(s) -> bool:
    if s.op in (Op.CONST, Op.ARG):
        return True
    return s.op in _ARITH and all(_evaluable(o) for o in s.operands)


def _evaluate(s, args: dict) -> int:
    if s.op is Op.CONST:
        return int(s.attrs["value"])
    if s.op is Op.ARG:
        return int(args[s.attrs["slot"]])
    a, b = (_evaluate(o, args) for o in s.operands)
    return _ARITH[s.op](a, b)


def _watched(f, leads, args: dict) -> bytes:
    """The bytes of what a launch read of `f`: the slices its leading indices name, or the whole field."""
    field = f.owner  # the lang-level field behind the IR's record
    data = field.view if field.view is not None else field.to_numpy()
    try:
        picked = None if leads is None else sorted({_evaluate(e, args) for e in leads})
    except KeyError:  # an index from a matrix argument's entry: watch everything
        picked = None
    if picked is None:
        return hashlib.blake2b(np.ascontiguousarray(data).tobytes(), digest_size=16).digest()
    h = hashlib.blake2b(digest_size=16)
    for i in picked:
        if 0 <= i < data.shape[0]:
            h.update(np.ascontiguousarray(data[i]).tobytes())
    return h.digest()


class Snapshot:
    """Fingerprints of what one forward launch read, checked before its adjoint launch: the slices of the
    leading axis the launch read when its arguments pick them (x[t - 1, i]: writing x[t] later is fine),
    else whole fields."""

    def __init__(self, kernel, args):
        inst = kernel.instance(args)
        self.kernel = kernel
        self.args = {p.slot: a for p, a in zip(inst.launcher.params, args) if p.kind == "scalar"}
        self.reads = reads_of(inst.ir)
        self.prints = self._fingerprint()

    def _fingerprint(self) -> dict:
        return {f: _watched(f, leads, self.args) for f, (_, leads) in self.reads.items()}

    def check(self) -> None:
        now = self._fingerprint()
        for f, digest in self.prints.items():
            if now[f] != digest:
                loc = self.reads[f][0]
                raise GradientError(
                    f"global data access rule violated: field '{_user_name(f)}' was modified after kernel "
                    f"{self.kernel.name} read it, so its gradient would be computed from different values. "
                    "Keep every state a differentiated kernel reads unchanged until backward (e.g. store "
                    "each time step separately).", loc)
