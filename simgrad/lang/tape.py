"""ti.ad.Tape and friends: record kernel launches, then run their adjoints in reverse order.

Kernels decorated with @ti.ad.no_grad run forward and are skipped backward. A function decorated with
@ti.ad.grad_replaced is recorded as one unit; backward runs the function registered for it with
@ti.ad.grad_for (custom gradients, e.g. recomputation for checkpointing).
"""

from __future__ import annotations

import enum
import functools
import hashlib
from typing import Any

import numpy as np

from simgrad import dtypes as dt
from simgrad.autodiff.validate import differentiable, user_name, written_targets
from simgrad.errors import AccessRuleError, GradientError, SimgradError, SimgradRuntimeError, caller_loc
from simgrad.ir.nodes import Kernel, indices_of, walk
from simgrad.ir.ops import Op
from simgrad.lang import ad_hooks
from simgrad.lang.field import Field, ScalarField
from simgrad.runtime.launch import Sequence, same_replay_key


class Tape:
    """`with ti.ad.Tape(loss=loss): forward()` computes d loss / d (every field with a gradient)."""

    def __init__(self, loss=None, clear_gradients: bool = True, validation: bool = False, grad_check=None):
        if loss is not None and not isinstance(loss, Field):
            _check_array_loss(loss)
        elif loss is not None:
            if not isinstance(loss, ScalarField) or loss.shape != ():
                raise SimgradError(f"the loss must be a 0-d scalar field (ti.field(dtype, shape=())), got "
                                   f"shape {loss.shape}")
            if loss.grad is None or loss.grad.snode is None:
                raise SimgradError(f"the loss field {loss.name} has no gradient: create it with "
                                   "needs_grad=True (or place it before ti.root.lazy_grad())")
        if grad_check is not None and (not isinstance(grad_check, (list, tuple)) or
                                       not all(isinstance(f, Field) for f in grad_check)):
            raise SimgradError("Tape(grad_check=...) takes a list of fields whose gradients to check")
        if grad_check and (not isinstance(loss, Field) or loss.dtype is not dt.f64):
            raise SimgradError("Tape(grad_check=...) needs an f64 loss (finite differences in f32 are too coarse "
                               "to check against), as in Taichi")
        self.loss = loss
        self.clear_gradients = clear_gradients
        self.validation = validation
        self.grad_check: list[Any] = list(grad_check or [])
        self._before: list | None = None
        self.entries: list = []
        self.snapshots: dict = {}
        self.rollback: dict = {}  # entry -> [(field, values before the launch)] of in-place kernels
        self.gradient_evaluated = False
        self._outer = None

    def __enter__(self):
        if self.grad_check:
            self._before = _save_memory()  # what the checks replay the recorded kernels from
        if self.loss is not None:
            _fill(self.loss, 0.0)
        if self.clear_gradients:
            clear_all_gradients()
        self._outer = ad_hooks.recorder
        ad_hooks.recorder = self._record
        return self

    def _record(self, kernel, args) -> None:
        if not getattr(kernel, "_no_grad", False):
            self.entries.append((kernel, args))
            fields = _in_place_fields(kernel, args)
            if fields:  # the kernel reads what it overwrites: its adjoint must see the values from before it
                self.rollback[len(self.entries) - 1] = [(f, f.to_numpy()) for f in fields]
            if fields or self._validating():
                # an in-place launch's other inputs are always watched: a later launch overwriting one (a
                # temporary recomputed every step) would make its adjoint wrong, so that is an error
                self.snapshots[len(self.entries) - 1] = Snapshot(kernel, args)

    def _validating(self) -> bool:
        from simgrad.lang.program import get_program

        return self.validation or get_program().config.debug

    def __exit__(self, exc_type, exc, tb):
        ad_hooks.recorder = self._outer
        if exc_type is not None:
            return False
        if self.loss is not None:
            if self.loss.grad is None:  # a tensor's gradient appears once a kernel that needs it ran
                import torch

                self.loss.grad = torch.ones_like(self.loss)
            _fill(self.loss.grad, 1.0)
            self.grad()
        if self.grad_check:
            self._check_gradients()
        return False

    def _check_gradients(self) -> None:
        """Tape(grad_check=[x, ...]): compare each x.grad with central differences of the loss along random
        directions (replaying the recorded kernels from the state before the Tape), at decreasing steps;
        one step within 1% passes, as Taichi's check. Every field is put back as it was after backward."""
        assert self._before is not None and self.loss is not None
        after = _save_memory()
        before = self._before
        rng = np.random.default_rng(0)
        try:
            for x in self.grad_check:
                if x is self.loss:
                    continue
                if x.grad is None or x.grad.snode is None:
                    raise SimgradError(f"grad_check: field {x.name} has no gradient")
                grad = x.grad.to_numpy().astype(np.float64)
                x0 = x.to_numpy().astype(np.float64)
                errors = []
                for eps in 2.0 ** np.arange(-3, -30, -2):
                    t = rng.random(x0.shape)
                    pos, neg = (self._replayed_loss(before, x, x0 + s * eps * t) for s in (1, -1))
                    numeric = (pos - neg) * 0.5 / eps
                    autodiff = float(np.sum(grad * t))
                    err = abs(autodiff - numeric)
                    errors.append(err / (abs(autodiff) + 1e-20))
                    if err * 100 <= abs(autodiff) or err == 0:
                        break
                else:
                    raise GradientError(f"grad check failed for field {x.name}: relative error "
                                        f"{min(errors):.3g} against central differences (expected <= 0.01)")
        finally:
            _restore_memory(after)

    def _replayed_loss(self, before: list, x: Any, value: np.ndarray) -> float:
        _restore_memory(before)
        x.from_numpy(value.astype(x.to_numpy().dtype))
        outer, ad_hooks.recorder = ad_hooks.recorder, None
        try:
            for fn, args in self.entries:
                fn(*args)
        finally:
            ad_hooks.recorder = outer
        assert self.loss is not None
        return float(self.loss.to_numpy())

    def insert(self, fn, args) -> None:
        self.entries.append((fn, args))

    def grad(self) -> None:
        """Run the recorded adjoints in reverse order."""
        if self.gradient_evaluated:
            raise SimgradError("this Tape's gradients were already computed")
        # In-place kernels (reading what they overwrite) are rolled back before their adjoint, which then runs
        # on the values from before them; backward proceeds in reverse, so every earlier adjoint sees the state
        # it had too. The final values come back at the end.
        if not self.rollback and not self.snapshots:
            sequence = _backward_sequence(self.entries)
            if sequence is not None:
                sequence.run()
                self.gradient_evaluated = True
                return
        final = {id(f): (f, f.to_numpy()) for saved in self.rollback.values() for f, _ in saved}
        for k in range(len(self.entries) - 1, -1, -1):
            fn, args = self.entries[k]
            saved = self.rollback.get(k)
            if saved is not None:
                for f, values in saved:
                    f.from_numpy(values)
            snap = self.snapshots.get(k)
            if snap is not None:
                try:
                    snap.check()
                except AccessRuleError as e:
                    if saved is None:
                        raise
                    raise AccessRuleError(f"{e.args[0]}\n(an in-place kernel on a Tape: its other inputs must "
                                          "stay as it read them; put the steps in ti.ad.checkpoint(step, n, "
                                          "state=[...]), which recomputes what later launches overwrite)") \
                        from None
            in_place = getattr(fn.grad, "in_place", None) if saved is not None else None
            (in_place or fn.grad)(*args)
        for f, values in final.values():
            f.from_numpy(values)
        self.gradient_evaluated = True


# the last captured backward pass: (program generation, the recorded launches, their Sequence or None)
_backward: tuple | None = None


def _same_launches(entries: list, recorded: list) -> bool:
    """Whether `entries` launch what `recorded` launched: the same kernels with arguments of equal replay keys
    (runtime/launch.py same_replay_key). Compared in place: building a key per backward pass allocated two tuples
    per launch, and for mass_spring's 3406 launches the garbage collector's pauses cost more than the replay
    saved."""
    if len(entries) != len(recorded):
        return False
    for (fn, args), (rfn, rargs) in zip(entries, recorded):
        if fn is not rfn or len(args) != len(rargs):
            return False
        if not all(map(same_replay_key, args, rargs)):
            return False
    return True


def _backward_sequence(entries: list):
    """The adjoints of `entries` in reverse as one native Sequence (runtime/launch.py), reused while a Tape
    records the same launches with the same arguments (a training loop); None where a step needs Python (a
    custom gradient, a launcher with Python after its call), under the forward mode or the profiler, or on
    arch=cuda."""
    global _backward
    from simgrad.lang.program import get_program

    prog = get_program()
    if ad_hooks.forward_mode is not None or prog.config.kernel_profiler or \
            prog.on_gpu:
        return None
    if _backward is not None and _backward[0] == prog.generation and _same_launches(entries, _backward[1]):
        return _backward[2]  # None too: these launches were found not capturable, don't try again
    steps = []
    for fn, args in reversed(entries):
        make = getattr(getattr(fn, "grad", None), "launcher", None)
        launcher = make(args) if make is not None else None
        if launcher is None or launcher.pack is None:  # a custom gradient, or Python after the launch
            break
        steps.append((launcher, args))
    sequence = Sequence.packed(steps) if len(steps) == len(entries) else None
    _backward = (prog.generation, list(entries), sequence)  # the entries keep their arguments' identities valid
    return sequence


def _in_place_fields(kernel, args) -> list:
    """For a kernel instance that updates fields in place, every lang-level field it writes (computed once
    per instance); [] for the others."""
    instance = getattr(kernel, "instance", None)
    if instance is None:  # a @ti.ad.grad_replaced unit: its own gradient function
        return []
    simple = getattr(kernel, "_simple_instance", None)  # kernels of scalar arguments have one instance
    inst = simple if simple is not None else instance(args)
    if not inst.in_place:
        return []
    fields = getattr(inst, "_in_place_fields", None)
    if fields is None:
        # everything it writes, not only what it updates in place: an earlier launch may have read those
        fields = inst._in_place_fields = [t.owner for t in written_targets(inst.ir) if t.owner is not None]
    return fields


def _check_array_loss(loss) -> None:
    """A Tape's loss may also be a one-element ti.ndarray with needs_grad=True or a torch tensor that
    requires grad (as in Taichi, whose RuntimeError texts these are); gradients of ndarrays are not cleared on
    entry."""
    if hasattr(loss, "_ndarray_data"):
        if loss._ndarray.size != 1:
            raise SimgradRuntimeError(f"The loss of `Tape` must be an ndarray with only one element, got shape "
                                      f"{loss.shape}", caller_loc())
        if loss.grad is None:
            raise SimgradRuntimeError("Gradients of loss are not allocated, please set needs_grad=True for all "
                                      "ndarrays that are required by autodiff. (The loss ndarray has no gradient: "
                                      "create it with ti.ndarray(..., needs_grad=True).)", caller_loc())
    elif hasattr(loss, "requires_grad") and hasattr(loss, "numel"):
        if loss.numel() != 1:
            raise SimgradRuntimeError(f"The loss of `Tape` must be a tensor only contains one element, got shape "
                                      f"{tuple(loss.shape)}", caller_loc())
        if not loss.requires_grad:
            raise SimgradRuntimeError("Gradients of loss are not allocated, please set requires_grad=True for all "
                                      "tensors that are required by autodiff. (The loss tensor has no gradient: "
                                      "create it with requires_grad=True.)", caller_loc())
    else:
        raise SimgradError(f"Tape(loss=...) expects a scalar field, a one-element ndarray or a tensor, got "
                           f"{type(loss).__name__}", caller_loc())


def _fill(x, value: float) -> None:
    if hasattr(x, "fill_"):  # a torch tensor (a leaf that requires grad is filled without recording)
        import torch

        with torch.no_grad():
            x.fill_(value)
    else:
        x.fill(value)


def _save_memory() -> list:
    """Copies of every SNode tree's buffer (what a grad check restores between replays)."""
    from simgrad.lang.program import get_program

    prog = get_program()
    prog.materialize_all()
    return [(t, t.buffer.copy()) for t in prog.trees if t.buffer is not None]


def _restore_memory(saved: list) -> None:
    for tree, copy in saved:
        tree.buffer[...] = copy  # through the accessor: after the kernels still running on the device


class SNodeGradType(enum.Enum):
    """What a placed field is to autodiff (Taichi's names)."""

    PRIMAL = 0
    ADJOINT = 1
    DUAL = 2
    ADJOINT_CHECKBIT = 3


def clear_all_gradients(gradient_type=SNodeGradType.ADJOINT) -> None:
    """Zero every placed gradient field of the program (gradient_type=SNodeGradType.DUAL: every dual)."""
    from simgrad.lang.program import get_program

    if gradient_type is None:
        gradient_type = SNodeGradType.ADJOINT
    if gradient_type not in (SNodeGradType.ADJOINT, SNodeGradType.DUAL):
        return  # primal values are not gradients; simgrad keeps no check bits
    duals = gradient_type is SNodeGradType.DUAL
    prog = get_program()
    prog.materialize_all()
    native: dict[int, list] = {}  # parent SNode -> the large gradients placed under it
    zero = ad_hooks.zero_fields
    for tree in prog.trees:
        for node in tree.root._walk():
            if node.kind != "place" or node.field.is_primal or node.field.is_dual != duals:
                continue
            f = node.field
            if zero is not None and int(np.prod(f.shape)) >= _NATIVE_ZEROING:
                native.setdefault(id(node._parent), []).append(f)
            elif f.view is not None:
                f.view[...] = 0
            else:
                f.fill(0)
    if native and zero is not None:
        zero(list(native.values()))


# gradients of at least this many elements are zeroed by a compiled kernel, one pass over their cells
_NATIVE_ZEROING = 1 << 16


def no_grad(kernel):
    """The kernel runs in forward; a Tape skips it in backward. A plain Python function (Taichi's use: it
    calls kernels) is recorded on the Tape as one unit whose gradient, `fn.grad`, does nothing."""
    if not hasattr(kernel, "grad"):  # not a kernel: a Python function
        replaced = _Replaced(kernel)
        replaced.grad = _no_gradient
        return replaced
    kernel._no_grad = True
    return kernel


def _no_gradient(*args, **kwargs) -> None:
    return None


class _Replaced:
    """A Python function recorded as one unit on the Tape; its gradient is the grad_for function."""

    def __init__(self, fn):
        self.fn = fn
        self.grad = None
        functools.update_wrapper(self, fn)

    def __call__(self, *args, **kwargs):
        outer = ad_hooks.recorder
        tape = getattr(outer, "__self__", None)
        if tape is not None:
            tape.insert(self, args)
        ad_hooks.recorder = None  # the kernels inside are not recorded one by one
        try:
            return self.fn(*args, **kwargs)
        finally:
            ad_hooks.recorder = outer

    def __get__(self, obj, owner=None):
        """`obj.f(x)` for a method of a (@ti.data_oriented) class: the primal and its grad_for method both
        bound to the object, so the Tape records and replays them with `self`."""
        if obj is None:
            return self
        bound = _Replaced(functools.partial(self.fn, obj))
        if self.grad is not None:
            bound.grad = functools.partial(self.grad, obj)
        return bound


def grad_replaced(fn):
    return _Replaced(fn)


def grad_for(primal):
    def register(fn):
        if not isinstance(primal, _Replaced):  # RuntimeErrors, as Taichi raises them
            if hasattr(primal, "grad"):
                raise SimgradRuntimeError("ti.ad.grad_for: the primal function must be a **python** function "
                                          f"instead of a taichi kernel ({primal.__name__}): wrap the kernel in a "
                                          "@ti.ad.grad_replaced decorated python function", caller_loc())
            raise SimgradRuntimeError(f"Primal function `{getattr(primal, '__name__', primal)}` must be "
                                      "decorated by ti.ad.grad_replaced", caller_loc())
        primal.grad = fn
        return fn

    return register


# -- run-time access checks (Tape(validation=True), debug mode) ---------------------------------------
def reads_of(kernel_ir: Kernel) -> dict:
    """{field component: (location of its first read, leading indices)} for the fields a forward kernel
    reads. The leading indices are IR expressions of the kernel's scalar arguments (`x[t - 1, i]`), or None
    when some read's first index depends on anything else: then the whole field is watched."""
    out: dict = {}
    for s in walk(kernel_ir.body):
        if s.op is Op.GLOBAL_LOAD:
            ptr = s.operands[0]
            target = ptr.attrs["target"]
            if not differentiable(target):
                continue
            loc, leads = out.get(target, (s.loc, []))
            indices = indices_of(ptr)
            lead = indices[0] if indices and _evaluable(indices[0]) else None
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
    except KeyError:  # an index from a slot with no value here (a matrix argument's entry): watch everything
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
        # ARG slot -> value of the scalar words the arguments fill (each parameter's packing says which)
        self.args = {slot: v for p, a in zip(inst.launcher.params, args) for slot, v in p.slot_values(a).items()}
        self.reads = reads_of(inst.ir)
        self.prints = self._fingerprint()

    def _fingerprint(self) -> dict:
        return {f: _watched(f, leads, self.args) for f, (_, leads) in self.reads.items()}

    def check(self) -> None:
        now = self._fingerprint()
        for f, digest in self.prints.items():
            if now[f] != digest:
                loc = self.reads[f][0]
                raise AccessRuleError(
                    f"global data access rule violated: field '{user_name(f)}' was modified after kernel "
                    f"{self.kernel.name} read it, so its gradient would be computed from different values. "
                    "Keep every state a differentiated kernel reads unchanged until backward (e.g. store "
                    "each time step separately).", loc)
